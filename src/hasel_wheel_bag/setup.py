"""MCAP bags in rosbag2's layout without ROS: writer, readers, recovery, info and export for the HASEL wheel."""
from glob import glob

from setuptools import find_packages, setup

package_name = "hasel_wheel_bag"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    package_data={package_name: ["msg_defs/std/*.msg", "msg_defs/hasel_wheel_msgs/*.msg"]},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
    ],
    # lower bounds only, so that Ubuntu 24.04 / ROS 2 Jazzy system packages satisfy them
    install_requires=['setuptools', 'numpy>=1.24', 'PyYAML>=5.4', 'mcap>=1.1', 'mcap-ros2-support>=0.5', 'tqdm>=4.60', 'hasel_wheel_common'],
    extras_require={'parquet': ['pyarrow>=15'], 'test': ['pytest']},
    zip_safe=False,
    maintainer="HASEL wheel developers",
    maintainer_email="dev@hasel-wheel.invalid",
    description="MCAP bags in rosbag2's layout without ROS: writer, readers, recovery, info and export for the HASEL wheel.",
    license="Apache-2.0",
)
