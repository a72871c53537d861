"""Helpers for this package's launch files (imports launch, never rclpy; not part of the core).
"""
from __future__ import annotations

import shutil

from launch.actions import (DeclareLaunchArgument, IncludeLaunchDescription, RegisterEventHandler,
                            Shutdown)
from launch.event_handlers import OnProcessIO
from launch.launch_description_sources import PythonLaunchDescriptionSource
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
from launch_ros.substitutions import FindPackageShare

#: What a node logs once it can take samples (its model is loaded or compiled).
READY = b"ready:"


def when_all_ready(nodes, actions) -> list:
    """Event handlers that return ``actions`` once every node in ``nodes`` has logged READY
    on stdout or stderr."""
    waiting = set(range(len(nodes)))

    def handler(i):
        def on_output(event):
            if i in waiting and READY in event.text:
                waiting.discard(i)
                if not waiting:
                    return actions
            return None
        return on_output

    return [RegisterEventHandler(OnProcessIO(target_action=n, on_stdout=handler(i),
                                             on_stderr=handler(i)))
            for i, n in enumerate(nodes)]


def stops_with_launch(cmd: list[str]) -> list[str]:
    """``cmd`` run so that it gets SIGINT when the launch process dies (``setpriv
    --pdeathsig``, util-linux).  Jazzy's ``ros2 launch`` dies at once on SIGTERM and leaves
    its processes running; our nodes notice that themselves
    (:mod:`hasel_wheel_common.stop_request`), ``ros2 bag record``/``play`` would not, and an
    orphaned recorder never closes its bag.  Without setpriv the command is returned as is."""
    return ["setpriv", "--pdeathsig", "INT", "--", *cmd] if shutil.which("setpriv") else cmd


def recording_arguments() -> list:
    """The ``record`` and ``bag_dir`` launch arguments (record.launch.py's)."""
    return [DeclareLaunchArgument("record", default_value="true",
                                  description="record every topic to an MCAP bag (true/false)"),
            DeclareLaunchArgument("bag_dir", default_value="",
                                  description="output directory of the bag ('' = rosbag2's "
                                              "rosbag2_<date>_<time>)")]


def include_recording(config_files: list[str], namespaces: list) -> IncludeLaunchDescription:
    """record.launch.py with this launch's ``record`` and ``bag_dir``, keeping the files named
    by the launch arguments ``config_files`` in the bag (an empty one is left out), with the
    recorder's QoS for the wheels in ``namespaces`` (strings or substitutions)."""
    files: list = []                  # "a,b,c" as substitutions
    for name in config_files:
        files += [LaunchConfiguration(name), ","]
    names: list = []                  # "wheel0,wheel1" as substitutions
    for i, ns in enumerate(namespaces):
        names += [","] * bool(i) + [ns]
    share = FindPackageShare("hasel_wheel_bringup")
    return IncludeLaunchDescription(
        PythonLaunchDescriptionSource(PathJoinSubstitution([share, "launch", "record.launch.py"])),
        launch_arguments={"record": LaunchConfiguration("record"),
                          "bag_dir": LaunchConfiguration("bag_dir"),
                          "config_files": files, "namespaces": names}.items())


def share_file_argument(name: str, package: str, filename: str,
                        description: str) -> DeclareLaunchArgument:
    """Launch argument ``name`` whose default is ``<package's share>/config/<filename>``."""
    return DeclareLaunchArgument(
        name, description=description,
        default_value=PathJoinSubstitution([FindPackageShare(package), "config", filename]))


def sim_arguments(prefix: str = "") -> list:
    """The simulator's launch arguments ``plant_file`` (the realistic plant by default),
    ``sim_params_file`` and ``time_scale``; ``prefix`` starts each description (e.g.
    'plant:=sim: ')."""
    return [share_file_argument("plant_file", "hasel_wheel_sim", "plant_realistic.yaml",
                                prefix + "plant YAML of the simulator (seed, switching, effects)"),
            share_file_argument("sim_params_file", "hasel_wheel_sim", "sim_node.yaml",
                                prefix + "ROS parameter file of the simulator (initial speed, "
                                         "start_timeout)"),
            DeclareLaunchArgument("time_scale", default_value="1.0",
                                  description=prefix + "simulated seconds per wall second")]


def controller_parameter_arguments() -> list:
    """The ``observer_params_file`` and ``mpc_params_file`` launch arguments."""
    return [share_file_argument(f"{name}_params_file", "hasel_wheel_mpc", f"{name}.yaml",
                                f"ROS parameter file of {name}_node")
            for name in ("observer", "mpc")]


def controller_nodes(namespace) -> tuple:
    """(observer_node, mpc_node) under ``namespace``, each with its parameter file (launch
    arguments ``observer_params_file``, ``mpc_params_file``) and the model file of the
    launch argument ``controller_model_file``; either one exiting shuts the launch down."""
    model = {"model_file": ParameterValue(LaunchConfiguration("controller_model_file"),
                                          value_type=str)}
    return tuple(
        Node(package="hasel_wheel_mpc", executable=f"{name}_node", name=f"{name}_node",
             namespace=namespace, output="screen",
             on_exit=Shutdown(reason=f"the {name} node exited"),
             parameters=[LaunchConfiguration(f"{name}_params_file"), model])
        for name in ("observer", "mpc"))


def controller_model_argument() -> DeclareLaunchArgument:
    """The ``controller_model_file`` launch argument."""
    return DeclareLaunchArgument("controller_model_file", default_value="",
                                 description="model file for the observer and the MPC, e.g. "
                                             "hasel_wheel identify's model.yaml ('' = paper "
                                             "model)")
