"""An open-loop characterisation run (Table II style): trial_node drives the wheel, recorded.

    ros2 launch hasel_wheel_bringup open_loop_trial.launch.py                     # simulated wheel
    ros2 launch hasel_wheel_bringup open_loop_trial.launch.py plant:=hardware \\
        port:=/dev/serial/by-id/usb-Teensyduino_USB_Serial_12345-if00 bag_dir:=bags/table2
    ros2 param set /wheel0/driver hv_enabled true          # hardware: HV stays off until you ask
    ros2 launch hasel_wheel_bringup open_loop_trial.launch.py trial_params_file:=my_steps.yaml

trial_node (parameters: config/open_loop_trial.yaml) holds each (phi_a, phi_d) step for
step_duration seconds from the first telemetry sample with HV on, logs each step's steady
speed, and exits after the last step; that ends the launch, which stops the plant (the driver
switches HV off) and the recording.  The plant is the simulator (plant:=sim, plant_file:=...,
time_scale:=...) or the real wheel through the driver (plant:=hardware, port:=...); either
starts once trial_node has logged "ready:".  The bag's custom data keeps the trial's parameter
file and the plant's (plant_file for the sim, the driver's parameter file for hardware).
"""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, IncludeLaunchDescription, OpaqueFunction, Shutdown
from launch.conditions import IfCondition
from launch.launch_description_sources import PythonLaunchDescriptionSource
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.substitutions import FindPackageShare

from hasel_wheel_bringup.launch_support import (include_recording, recording_arguments,
                                           share_file_argument, sim_arguments,
                                           when_all_ready)

PLANTS = ("sim", "hardware")


def _plant_and_trial(context):
    """trial_node, then the chosen plant once it is ready, and the recording of both."""
    plant = LaunchConfiguration("plant").perform(context)      # one of PLANTS (choices)
    namespace = LaunchConfiguration("namespace")
    trial = Node(package="hasel_wheel_bringup", executable="trial_node", name="trial_node",
                 namespace=namespace, output="screen",
                 on_exit=Shutdown(reason="the open-loop trial ended"),
                 parameters=[LaunchConfiguration("trial_params_file")])
    if plant == "sim":
        source = PathJoinSubstitution([FindPackageShare("hasel_wheel_sim"), "launch",
                                       "sim.launch.py"])
        arguments = {"namespace": namespace, "plant_file": LaunchConfiguration("plant_file"),
                     "params_file": LaunchConfiguration("sim_params_file"),
                     "time_scale": LaunchConfiguration("time_scale")}
        kept = ["trial_params_file", "sim_params_file", "plant_file"]
    else:
        source = PathJoinSubstitution([FindPackageShare("hasel_wheel_driver"), "launch",
                                       "driver.launch.py"])
        listeners = 1 + IfCondition(LaunchConfiguration("record")).evaluate(context)
        arguments = {"namespace": namespace, "port": LaunchConfiguration("port"),
                     "params_file": LaunchConfiguration("driver_params_file"),
                     "telemetry_subscribers": str(listeners)}     # trial node, recorder
        kept = ["trial_params_file", "driver_params_file"]
    wheel = IncludeLaunchDescription(PythonLaunchDescriptionSource(source),
                                     launch_arguments=arguments.items())
    return [include_recording(kept, [namespace]), *when_all_ready([trial], [wheel]), trial]


def generate_launch_description():
    return LaunchDescription([
        *recording_arguments(),
        DeclareLaunchArgument("plant", default_value="sim", choices=list(PLANTS),
                              description="the wheel: the simulator or the real one (driver)"),
        DeclareLaunchArgument("namespace", default_value="wheel0",
                              description="namespace of the wheel's topics and nodes"),
        share_file_argument("trial_params_file", "hasel_wheel_bringup", "open_loop_trial.yaml",
                            "ROS parameter file of trial_node (the steps)"),
        *sim_arguments("plant:=sim: "),
        DeclareLaunchArgument("port", default_value="/dev/ttyACM0",
                              description="plant:=hardware: the Teensy's serial device"),
        share_file_argument("driver_params_file", "hasel_wheel_driver", "driver_node.yaml",
                            "plant:=hardware: ROS parameter file of the driver"),
        OpaqueFunction(function=_plant_and_trial),
    ])
