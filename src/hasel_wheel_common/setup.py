"""Samples, the topic table, the serial protocol codec, message conversion and shared ROS helpers of the HASEL wheel."""
from glob import glob

from setuptools import find_packages, setup

package_name = "hasel_wheel_common"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
    ],
    # lower bounds only, so that Ubuntu 24.04 / ROS 2 Jazzy system packages satisfy them
    install_requires=['setuptools', 'numpy>=1.24', 'PyYAML>=5.4', 'cobs>=1.1'],
    extras_require={'test': ['pytest']},
    zip_safe=False,
    maintainer="HASEL wheel developers",
    maintainer_email="dev@hasel-wheel.invalid",
    description="Samples, the topic table, the serial protocol codec, message conversion and shared ROS helpers of the HASEL wheel.",
    license="Apache-2.0",
)
