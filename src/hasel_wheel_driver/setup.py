"""The HASEL wheel's Teensy over USB serial: the link core, its command line and the driver node."""
from glob import glob

from setuptools import find_packages, setup

package_name = "hasel_wheel_driver"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", glob("config/*.yaml")),
        ("share/" + package_name + "/launch", glob("launch/*.launch.py")),
    ],
    # lower bounds only, so that Ubuntu 24.04 / ROS 2 Jazzy system packages satisfy them
    install_requires=["setuptools", "numpy>=1.24", "PyYAML>=5.4", "pyserial>=3.4", "hasel_wheel_common"],
    extras_require={"test": ["pytest"]},          # colcon test runs pytest (not unittest)          # colcon test runs pytest (not unittest)
    zip_safe=False,
    maintainer="HASEL wheel developers",
    maintainer_email="dev@hasel-wheel.invalid",
    description="The HASEL wheel's Teensy over USB serial: link core, command line and driver node.",
    license="Apache-2.0",
    entry_points={"console_scripts": [
        "hasel_wheel_link = hasel_wheel_driver.link_cli:main",
        "driver_node = hasel_wheel_driver.driver_node:main",
    ]},
)
