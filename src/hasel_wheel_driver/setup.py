"""Serial link to the wheel's Teensy, topic table, message definitions and bag I/O."""
from glob import glob

from setuptools import find_packages, setup

package_name = "hasel_wheel_driver"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    package_data={package_name: ["msg_defs/std/*.msg", "msg_defs/hasel_wheel_msgs/*.msg"]},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", glob("config/*.yaml")),
        ("share/" + package_name + "/launch", glob("launch/*.launch.py")),
    ],
    # lower bounds only, so that Ubuntu 24.04 / ROS 2 Jazzy system packages satisfy them
    install_requires=["setuptools", "numpy>=1.24", "PyYAML>=5.4", "mcap>=1.1", "mcap-ros2-support>=0.5", "pyserial>=3.4", "cobs>=1.1",
                      "tqdm>=4.60"],
    extras_require={"parquet": ["pyarrow>=15"],   # bag export --format parquet
                    "test": ["pytest"]},          # colcon test runs pytest (not unittest)
    zip_safe=False,
    maintainer="HASEL wheel developers",
    maintainer_email="dev@hasel-wheel.invalid",
    description="Serial link to the HASEL wheel's Teensy, topic table, message definitions and bag I/O.",
    license="Apache-2.0",
    entry_points={"console_scripts": [
        "hasel_wheel_link = hasel_wheel_driver.link_cli:main",
        "driver_node = hasel_wheel_driver.driver_node:main",
    ]},
)
