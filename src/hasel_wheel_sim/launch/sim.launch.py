"""Launch the simulated wheel alone: ros2 launch hasel_wheel_sim sim.launch.py [namespace:=wheel0]."""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, Shutdown
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue
from launch_ros.substitutions import FindPackageShare


def generate_launch_description():
    share = FindPackageShare("hasel_wheel_sim")
    return LaunchDescription([
        DeclareLaunchArgument("namespace", default_value="wheel0",
                              description="namespace of the wheel's topics"),
        DeclareLaunchArgument("params_file",
                              default_value=PathJoinSubstitution([share, "config", "sim_node.yaml"]),
                              description="ROS parameter file of sim_node"),
        DeclareLaunchArgument("plant_file",
                              default_value=PathJoinSubstitution([share, "config", "plant.yaml"]),
                              description="plant YAML (seed, switching, effects)"),
        DeclareLaunchArgument("time_scale", default_value="1.0",
                              description="simulated seconds per wall second"),
        DeclareLaunchArgument("seed_offset", default_value="0",
                              description="added to plant_file's seed (gives wheels of one "
                                          "launch their own noise)"),
        DeclareLaunchArgument("model_file", default_value="",
                              description="model file (e.g. hasel_wheel identify's model.yaml) "
                                          "as the plant's dynamics; then plant_file may hold "
                                          "sensor/link effects only ('' = not used)"),
        DeclareLaunchArgument("telemetry_subscribers", default_value="0",
                              description="hold the wheel until this many subscriptions "
                                          "match telemetry (and its controller is connected)"),
        Node(package="hasel_wheel_sim", executable="sim_node", name="sim",
             namespace=LaunchConfiguration("namespace"), output="screen",
             on_exit=Shutdown(reason="the simulated wheel exited"),
             parameters=[LaunchConfiguration("params_file"),
                         {"plant_file": LaunchConfiguration("plant_file"),
                          "time_scale": ParameterValue(LaunchConfiguration("time_scale"),
                                                       value_type=float),   # time_scale:=2 too
                          "seed_offset": ParameterValue(LaunchConfiguration("seed_offset"),
                                                        value_type=int),
                          "model_file": ParameterValue(LaunchConfiguration("model_file"),
                                                       value_type=str),
                          "telemetry_subscribers": ParameterValue(
                              LaunchConfiguration("telemetry_subscribers"), value_type=int)}]),
    ])
