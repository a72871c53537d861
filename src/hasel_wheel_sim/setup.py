"""Hybrid model of the HASEL rolling soft wheel and a plant simulator with real-world effects."""
from glob import glob

from setuptools import find_packages, setup

package_name = "hasel_wheel_sim"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    package_data={package_name: ["config/*.yaml"]},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", glob("config/*.yaml")),
        ("share/" + package_name + "/launch", glob("launch/*.launch.py")),
    ],
    # lower bounds only, so that Ubuntu 24.04 / ROS 2 Jazzy system packages satisfy them
    install_requires=["setuptools", "numpy>=1.24", "PyYAML>=5.4", "hasel_wheel_common"],
    extras_require={"fast": ["numba>=0.58"],   # compiled model core (falls back to Python)
                    "test": ["pytest"]},       # colcon test runs pytest (not unittest)
    zip_safe=False,
    maintainer="HASEL wheel developers",
    maintainer_email="dev@hasel-wheel.invalid",
    description="Hybrid model of the HASEL rolling soft wheel and a plant simulator with real-world effects.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "sim_node = hasel_wheel_sim.sim_node:main",
        ],
    },
)
