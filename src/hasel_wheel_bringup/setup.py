"""The hasel_wheel command line, the closed-loop demo, open-loop trials, bag analysis and plots, launch files and configurations."""
from glob import glob

from setuptools import find_packages, setup

package_name = "hasel_wheel_bringup"

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
    install_requires=['setuptools', 'numpy>=1.24', 'scipy>=1.10', 'PyYAML>=5.4', 'matplotlib>=3.6', 'hasel_wheel_common', 'hasel_wheel_bag', 'hasel_wheel_driver', 'hasel_wheel_sim', 'hasel_wheel_mpc', 'hasel_wheel_ident'],
    extras_require={'test': ['pytest']},
    zip_safe=False,
    maintainer="HASEL wheel developers",
    maintainer_email="dev@hasel-wheel.invalid",
    description="The hasel_wheel command line, the closed-loop demo, open-loop trials, bag analysis and plots, launch files and configurations.",
    license="Apache-2.0",
    entry_points={"console_scripts": [
        "hasel_wheel = hasel_wheel_bringup.cli:main",
        "hasel_wheel_bag = hasel_wheel_bringup.bag_cli:main",
        "trial_node = hasel_wheel_bringup.trial_node:main",
        "profile_node = hasel_wheel_bringup.profile_node:main",
    ]},
)
