"""Record every topic of the graph to an MCAP bag; the other launch files include this one.

    ros2 launch hasel_wheel_bringup record.launch.py bag_dir:=bags/run1
    ros2 launch hasel_wheel_bringup sim_closed_loop.launch.py record:=false
    ros2 launch hasel_wheel_bringup sim_closed_loop.launch.py bag_dir:=bags/sim_run1

``ros2 bag record --all-topics --storage mcap`` with the run's configuration in the bag's
custom data (metadata.yaml): the git revision and every file listed in ``config_files``
(comma-separated: parameter files, plant file with its seed, model file).  ``bag_dir`` ''
lets rosbag2 name the bag (rosbag2_<date>_<time> in the working directory).

The recorder subscribes to the topics of the wheels in ``namespaces`` with the profiles of
:func:`hasel_wheel_common.topics.recorder_profiles` (``--qos-profile-overrides-path``):
volatile, so a reference sent by ``ros2 topic pub`` is recorded beside the MPC node's latched
one, and a second of history on the 300 Hz streams, so a briefly starved recorder loses no
sample.
"""
import contextlib
import os
import tempfile

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, ExecuteProcess, OpaqueFunction, RegisterEventHandler
from launch.event_handlers import OnShutdown
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration

from hasel_wheel_bringup.launch_support import recording_arguments, stops_with_launch
from hasel_wheel_common.topics import recorder_overrides_yaml
from hasel_wheel_mpc.recorder import launch_custom_data


def _overrides_file(namespaces: list[str]) -> str:
    """A temporary YAML file of the recorder's QoS overrides for these namespaces."""
    fd, path = tempfile.mkstemp(prefix="hasel_wheel_qos_", suffix=".yaml")
    with os.fdopen(fd, "w") as fh:
        fh.write(recorder_overrides_yaml(namespaces))
    return path


def _remove(path: str) -> None:
    """Delete ``path`` if it is still there (every shutdown event calls this)."""
    with contextlib.suppress(FileNotFoundError):
        os.unlink(path)


def _recorder(context):
    if not IfCondition(LaunchConfiguration("record")).evaluate(context):
        return []
    files = [f for f in LaunchConfiguration("config_files").perform(context).split(",") if f]
    custom = launch_custom_data(files)
    namespaces = LaunchConfiguration("namespaces").perform(context).split(",")
    overrides = _overrides_file([ns.strip().strip("/") for ns in namespaces])
    cmd = ["ros2", "bag", "record", "--all-topics", "--storage", "mcap",
           "--qos-profile-overrides-path", overrides,
           "--custom-data", *[f"{k}={v}" for k, v in custom.items()]]
    out = LaunchConfiguration("bag_dir").perform(context)
    if out:
        cmd += ["--output", out]
    return [ExecuteProcess(cmd=stops_with_launch(cmd), output="screen", name="bag_record"),
            RegisterEventHandler(OnShutdown(on_shutdown=lambda *_: _remove(overrides)))]


def generate_launch_description():
    return LaunchDescription([
        *recording_arguments(),
        DeclareLaunchArgument("config_files", default_value="",
                              description="comma-separated files to keep in the bag's "
                                          "custom data"),
        DeclareLaunchArgument("namespaces", default_value="wheel0",
                              description="comma-separated namespaces of the wheels whose "
                                          "topics get the recorder's QoS ('' = root)"),
        OpaqueFunction(function=_recorder),
    ])
