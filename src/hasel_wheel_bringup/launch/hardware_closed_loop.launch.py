"""The closed speed loop on the real wheel: driver -> observer -> MPC -> driver, recorded.

    ros2 launch hasel_wheel_bringup hardware_closed_loop.launch.py \\
        port:=/dev/serial/by-id/usb-Teensyduino_USB_Serial_12345-if00 bag_dir:=bags/run1
    ros2 param set /wheel0/driver hv_enabled true          # HV stays off until you ask
    ros2 topic pub --once /wheel0/reference_speed std_msgs/msg/Float64 "{data: 1.5}"
    ros2 launch hasel_wheel_bringup hardware_closed_loop.launch.py \\
        ports:=/dev/serial/by-id/usb-...-A-if00,/dev/serial/by-id/usb-...-B-if00   # /wheel0, /wheel1

The observer and the MPC start first; the driver (hasel_wheel_driver's driver.launch.py)
starts once both have logged "ready:" (per wheel, with ports:=...), so the first telemetry
finds them loaded.  The driver keeps high voltage off until ``hv_enabled`` is set true, and
switches it off again when the link goes quiet, a command is rejected or the launch stops.
Every topic is recorded to an MCAP bag (record.launch.py) with the driver's, observer's and
MPC's parameter files in the bag's custom data; record:=false turns recording off.
"""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, IncludeLaunchDescription, OpaqueFunction
from launch.conditions import IfCondition
from launch.launch_description_sources import PythonLaunchDescriptionSource
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.substitutions import FindPackageShare

from hasel_wheel_bringup.launch_support import (controller_model_argument, controller_nodes,
                                           controller_parameter_arguments, include_recording,
                                           recording_arguments, share_file_argument,
                                           when_all_ready)


def _wheels(context):
    """Each wheel's driver, observer and MPC: one wheel on ``port`` under ``namespace``, or
    one per entry of ``ports`` (comma-separated) under wheel0, wheel1, ...; each driver
    opens its link once the observer, the MPC and (when recording) the recorder listen."""
    ports = [p.strip() for p in LaunchConfiguration("ports").perform(context).split(",")
             if p.strip()]
    if len(set(ports)) != len(ports):
        raise ValueError(f"ports:={','.join(ports)}: a serial device is named twice")
    wheels = ([(LaunchConfiguration("namespace").perform(context),
                LaunchConfiguration("port").perform(context))] if not ports else
              [(f"wheel{i}", port) for i, port in enumerate(ports)])
    driver_launch = PathJoinSubstitution([FindPackageShare("hasel_wheel_driver"), "launch",
                                          "driver.launch.py"])
    listeners = str(2 + IfCondition(LaunchConfiguration("record")).evaluate(context))
    actions = []
    for ns, port in wheels:
        observer, mpc = controller_nodes(ns)
        driver = IncludeLaunchDescription(
            PythonLaunchDescriptionSource(driver_launch),
            launch_arguments={"namespace": ns, "port": port,
                              "params_file": LaunchConfiguration("driver_params_file"),
                              "telemetry_subscribers": listeners}.items())
        actions += [*when_all_ready([observer, mpc], [driver]), observer, mpc]
    return [include_recording(["driver_params_file", "observer_params_file", "mpc_params_file",
                               "controller_model_file"], [ns for ns, _ in wheels]), *actions]


def generate_launch_description():
    return LaunchDescription([
        *recording_arguments(),
        DeclareLaunchArgument("namespace", default_value="wheel0",
                              description="namespace of the wheel's topics and nodes"),
        DeclareLaunchArgument("port", default_value="/dev/ttyACM0",
                              description="the Teensy's serial device (a /dev/serial/by-id/... "
                                          "name survives replugging)"),
        DeclareLaunchArgument("ports", default_value="",
                              description="several wheels: their serial devices, comma-separated; "
                                          "wheel i under /wheel<i> (then port and namespace are "
                                          "not used)"),
        share_file_argument("driver_params_file", "hasel_wheel_driver", "driver_node.yaml",
                            "ROS parameter file of the driver"),
        controller_model_argument(),
        *controller_parameter_arguments(),
        OpaqueFunction(function=_wheels),
    ])
