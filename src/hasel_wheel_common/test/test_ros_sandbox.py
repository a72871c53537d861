"""Tests that start ROS 2 nodes run only in a loopback-only network namespace."""
import importlib.util

from hasel_wheel_common.ros_sandbox import ros_graph_unavailable

LOCAL = {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}


def test_another_interface_keeps_ros_tests_off():
    reason = ros_graph_unavailable(["lo", "eth0", "docker0"], LOCAL)
    assert "besides lo (docker0, eth0)" in reason and "unshare --net" in reason
    assert "besides lo ()" in ros_graph_unavailable([], LOCAL)      # not even lo: no


def test_discovery_must_be_localhost():
    assert ros_graph_unavailable(["lo"], {"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"}) == \
        "ROS_AUTOMATIC_DISCOVERY_RANGE is 'SUBNET'; expected 'LOCALHOST'"
    assert ros_graph_unavailable(["lo"], {}) == \
        "ROS_AUTOMATIC_DISCOVERY_RANGE is None; expected 'LOCALHOST'"


def test_loopback_only_and_localhost_leaves_only_the_ros_install():
    reason = ros_graph_unavailable(["lo"], LOCAL)
    if importlib.util.find_spec("rclpy") and importlib.util.find_spec("launch_testing"):
        assert reason is None
    else:
        assert "is not importable (source a ROS 2 Jazzy setup.bash" in reason
