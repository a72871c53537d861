"""A recorded bag drives the observer and the MPC live: ros2 bag play into the nodes.

    ros2 launch hasel_wheel_bringup replay.launch.py bag:=out/demo/bag namespace:=wheel0
    ros2 launch hasel_wheel_bringup replay.launch.py bag:=out/demo/bag rate:=2.0 bag_dir:=bags/replay1

``<namespace>/telemetry``, ``reference_speed``, ``command`` and ``mpc_status`` are played: the
observer must know the angles of the commands the wheel really ran (the telemetry names them
by sequence number), and the recorded decisions land in the new bag beside the replay's.  The
observer computes a new ``state_estimate``; the MPC's new commands and decisions go to
``<namespace>/replay/command`` and ``<namespace>/replay/mpc_status`` (remapped, so they neither
reach the observer nor mix with the recorded ones: the replay MPC numbers its commands from 0
as the recorded one did, and its angles would overwrite the recorded ones).  Everything is
recorded to a new bag (record.launch.py; record:=false turns it off).  Nothing drives a
wheel: no driver or simulator runs, and the recorded motion is the one the original
controller caused (an open-loop replay).  Playback starts once both nodes have logged
"ready:"; the launch ends when the bag has been played.

The nodes see the samples in real time, with the MPC's wall-clock deadline, so their output
is close to but not bit-identical with the recording; the exact re-computation is offline:
``hasel_wheel bag replay <bag>``.
"""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, ExecuteProcess, OpaqueFunction, Shutdown
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from hasel_wheel_bringup.launch_support import (controller_parameter_arguments, include_recording,
                                           recording_arguments, stops_with_launch,
                                           when_all_ready)

def _play(context):
    """``ros2 bag play`` of the wheel's telemetry, reference, commands and decisions (the topic names
    built here, so that a root namespace '' gives /telemetry, not //telemetry)."""
    ns = LaunchConfiguration("namespace").perform(context).strip("/")
    prefix = f"/{ns}" if ns else ""
    cmd = ["ros2", "bag", "play", LaunchConfiguration("bag").perform(context), "--rate",
           LaunchConfiguration("rate").perform(context), "--disable-keyboard-controls",
           "--topics", *(f"{prefix}/{name}" for name in ("telemetry", "reference_speed",
                                                         "command", "mpc_status"))]
    return [ExecuteProcess(cmd=stops_with_launch(cmd), output="screen", name="bag_play",
                           on_exit=Shutdown(reason="the bag has been played"))]


def generate_launch_description():
    ns = LaunchConfiguration("namespace")
    observer = Node(package="hasel_wheel_mpc", executable="observer_node", name="observer_node",
                    namespace=ns, output="screen",
                    parameters=[LaunchConfiguration("observer_params_file")])
    mpc = Node(package="hasel_wheel_mpc", executable="mpc_node", name="mpc_node",
               namespace=ns, output="screen", parameters=[LaunchConfiguration("mpc_params_file")],
               remappings=[("command", "replay/command"), ("mpc_status", "replay/mpc_status")])
    play = OpaqueFunction(function=_play)
    record = include_recording(["observer_params_file", "mpc_params_file"], [ns])
    return LaunchDescription([
        DeclareLaunchArgument("bag", description="bag to play (directory or .mcap file)"),
        DeclareLaunchArgument("namespace", default_value="wheel0",
                              description="the wheel's namespace in the bag ('' = root)"),
        DeclareLaunchArgument("rate", default_value="1.0", description="playback rate [1]"),
        *recording_arguments(),
        *controller_parameter_arguments(),
        *when_all_ready([observer, mpc], [play]),
        record,
        observer,
        mpc,
    ])
