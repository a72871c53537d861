"""Record every topic of the graph to an MCAP bag; the other launch files include this one.

    ros2 launch hasel_wheel_bringup record.launch.py bag_dir:=bags/run1
    ros2 launch hasel_wheel_bringup sim_closed_loop.launch.py record:=false
    ros2 launch hasel_wheel_bringup sim_closed_loop.launch.py bag_dir:=bags/sim_run1

``ros2 bag record --all-topics --storage mcap`` with the run's configuration in the bag's
custom data (metadata.yaml): the git revision and every file listed in ``config_files``
(comma-separated: parameter files, plant file with its seed, model file).  ``bag_dir`` ''
lets rosbag2 name the bag (rosbag2_<date>_<time> in the working directory).
"""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, ExecuteProcess, OpaqueFunction
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration

from hasel_wheel_bringup.launch_support import recording_arguments
from hasel_wheel_mpc.recorder import launch_custom_data


def _recorder(context):
    if not IfCondition(LaunchConfiguration("record")).evaluate(context):
        return []
    files = [f for f in LaunchConfiguration("config_files").perform(context).split(",") if f]
    custom = launch_custom_data(files)
    cmd = ["ros2", "bag", "record", "--all-topics", "--storage", "mcap",
           "--custom-data", *[f"{k}={v}" for k, v in custom.items()]]
    out = LaunchConfiguration("bag_dir").perform(context)
    if out:
        cmd += ["--output", out]
    return [ExecuteProcess(cmd=cmd, output="screen", name="bag_record")]


def generate_launch_description():
    return LaunchDescription([
        *recording_arguments(),
        DeclareLaunchArgument("config_files", default_value="",
                              description="comma-separated files to keep in the bag's "
                                          "custom data"),
        OpaqueFunction(function=_recorder),
    ])
