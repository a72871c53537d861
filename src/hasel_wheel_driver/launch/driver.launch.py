"""Launch the real wheel's driver: ros2 launch hasel_wheel_driver driver.launch.py port:=/dev/serial/by-id/..."""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, Shutdown
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
from launch_ros.substitutions import FindPackageShare


def generate_launch_description():
    share = FindPackageShare("hasel_wheel_driver")
    return LaunchDescription([
        DeclareLaunchArgument("namespace", default_value="wheel0",
                              description="namespace of the wheel's topics"),
        DeclareLaunchArgument("port", default_value="/dev/ttyACM0",
                              description="serial device (a /dev/serial/by-id/... name is stable)"),
        DeclareLaunchArgument("params_file",
                              default_value=PathJoinSubstitution([share, "config", "driver_node.yaml"]),
                              description="ROS parameter file of driver_node"),
        DeclareLaunchArgument("telemetry_subscribers", default_value="0",
                              description="open the serial link once this many subscriptions "
                                          "listen to telemetry (0 = at once)"),
        Node(package="hasel_wheel_driver", executable="driver_node", name="driver",
             namespace=LaunchConfiguration("namespace"), output="screen",
             on_exit=Shutdown(reason="the driver exited"),   # no controller left without it
             parameters=[LaunchConfiguration("params_file"),
                         {"port": LaunchConfiguration("port"),
                          "telemetry_subscribers": ParameterValue(
                              LaunchConfiguration("telemetry_subscribers"), value_type=int)}]),
    ])
