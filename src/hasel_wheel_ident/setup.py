"""Identification of the HASEL wheel's hybrid model from recorded trials: fits, residual analysis, the effect search and its report."""
from glob import glob

from setuptools import find_packages, setup

package_name = "hasel_wheel_ident"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
    ],
    # lower bounds only, so that Ubuntu 24.04 / ROS 2 Jazzy system packages satisfy them
    install_requires=['setuptools', 'numpy>=1.24', 'scipy>=1.10', 'PyYAML>=5.4', 'matplotlib>=3.6', 'hasel_wheel_common', 'hasel_wheel_bag', 'hasel_wheel_sim', 'hasel_wheel_mpc'],
    extras_require={'threads': ['threadpoolctl>=3.1'], 'test': ['pytest']},
    zip_safe=False,
    maintainer="HASEL wheel developers",
    maintainer_email="dev@hasel-wheel.invalid",
    description="Identification of the HASEL wheel's hybrid model from recorded trials: fits, residual analysis, the effect search and its report.",
    license="Apache-2.0",
)
