"""The closed speed loop on the simulated wheel: sim -> observer -> MPC -> sim.

    ros2 launch hasel_wheel_bringup sim_closed_loop.launch.py [namespace:=wheel0] [time_scale:=1.0]
    ros2 launch hasel_wheel_bringup sim_closed_loop.launch.py controller_model_file:=out/identify/model.yaml
    ros2 launch hasel_wheel_bringup sim_closed_loop.launch.py bag_dir:=bags/run1   # or record:=false
    ros2 launch hasel_wheel_bringup sim_closed_loop.launch.py wheels:=4 time_scale:=0.5   # /wheel0..3
    ros2 topic pub --once /wheel0/reference_speed std_msgs/msg/Float64 "{data: 1.5}"
    ros2 param set /wheel0/mpc_node reference_speed 2.0

The observer and the MPC start first; the simulator (hasel_wheel_sim's sim.launch.py, on the
plant with realistic effects unless plant_file:=... says otherwise) starts once both have
logged "ready:", and holds its wheel at t = 0 until its controller is connected (the MPC
node, which publishes command and subscribes to telemetry).  The simulated wheel starts at
1 rad/s and coasts to a stop within seconds without commands, and a stopped wheel cannot be
started; loading (or on the first run, compiling) the model can take the nodes longer than
that.

Every topic is recorded to an MCAP bag (record.launch.py) with the parameter files, the plant
file (its seed) and the controller's model file in the bag's custom data.
"""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, IncludeLaunchDescription, OpaqueFunction
from launch.launch_description_sources import PythonLaunchDescriptionSource
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.substitutions import FindPackageShare

from hasel_wheel_bringup.launch_support import (controller_model_argument, controller_nodes,
                                           controller_parameter_arguments, include_recording,
                                           recording_arguments, sim_arguments, when_all_ready)


def _wheels(context):
    """Each wheel's sim, observer and MPC: one wheel under ``namespace``, or ``wheels`` > 1
    of them under wheel0, wheel1, ... (wheel i on plant_file's seed + i)."""
    text = LaunchConfiguration("wheels").perform(context)
    if not text.isdigit() or int(text) < 1:
        raise ValueError(f"wheels:={text!r}: expected a whole number >= 1")
    n = int(text)
    names = ([LaunchConfiguration("namespace").perform(context)] if n == 1 else
             [f"wheel{i}" for i in range(n)])
    sim_share = FindPackageShare("hasel_wheel_sim")
    # the observer, the MPC and (when recording) the recorder: the bag gets the first sample
    listeners = str(2 + IfCondition(LaunchConfiguration("record")).evaluate(context))
    actions = []
    for i, ns in enumerate(names):
        observer, mpc = controller_nodes(ns)
        sim = IncludeLaunchDescription(
            PythonLaunchDescriptionSource(PathJoinSubstitution([sim_share, "launch",
                                                                "sim.launch.py"])),
            launch_arguments={"namespace": ns,
                              "params_file": LaunchConfiguration("sim_params_file"),
                              "plant_file": LaunchConfiguration("plant_file"),
                              "time_scale": LaunchConfiguration("time_scale"),
                              "seed_offset": str(i),
                              "model_file": LaunchConfiguration("plant_model_file"),
                              "telemetry_subscribers": listeners}.items())
        actions += [*when_all_ready([observer, mpc], [sim]), observer, mpc]
    return [include_recording(["observer_params_file", "mpc_params_file", "sim_params_file",
                               "plant_file", "controller_model_file"], names), *actions]


def generate_launch_description():
    return LaunchDescription([
        *recording_arguments(),
        DeclareLaunchArgument("namespace", default_value="wheel0",
                              description="namespace of the wheel's topics and nodes ('' = "
                                          "root); with wheels > 1: wheel0, wheel1, ..."),
        DeclareLaunchArgument("wheels", default_value="1",
                              description="independent closed loops, each in its own namespace "
                                          "and on its own plant seed, all in one bag"),
        *sim_arguments(),
        controller_model_argument(),
        DeclareLaunchArgument("plant_model_file", default_value="",
                              description="model file as the simulated plant's dynamics (then "
                                          "pass plant_file:=.../plant.yaml: sensor/link "
                                          "effects only); '' = plant_file's effects"),
        *controller_parameter_arguments(),
        OpaqueFunction(function=_wheels),
    ])
