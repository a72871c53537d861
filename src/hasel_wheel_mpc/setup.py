"""Observer, disturbance estimator, MPC, the control core and its nodes, and the embedded runner for the HASEL wheel."""
from glob import glob

from setuptools import find_packages, setup

package_name = "hasel_wheel_mpc"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    package_data={package_name: ["config/*.yaml"]},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", glob("config/*.yaml")),
    ],
    # lower bounds only, so that Ubuntu 24.04 / ROS 2 Jazzy system packages satisfy them
    install_requires=["setuptools", "numpy>=1.24", "PyYAML>=5.4", "hasel_wheel_common", "hasel_wheel_bag", "hasel_wheel_sim"],
    extras_require={"test": ["pytest"]},      # colcon test runs pytest (not unittest)
    zip_safe=False,
    maintainer="HASEL wheel developers",
    maintainer_email="dev@hasel-wheel.invalid",
    description="Observer, disturbance estimator, MPC, the control core and its nodes, and the embedded runner for the HASEL wheel.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "observer_node = hasel_wheel_mpc.observer_node:main",
            "mpc_node = hasel_wheel_mpc.mpc_node:main",
        ],
    },
)
