"""Every node class builds against the installed rclpy, declares each parameter with a
description and (numbers) a range, and uses each topic with the table's type and QoS.

Runs only where ROS 2 is installed, inside a loopback-only network namespace (see
``hasel_wheel_common.ros_sandbox``); elsewhere it skips and says why.
"""
import importlib

import pytest

from hasel_wheel_common import topics
from hasel_wheel_common.ros_sandbox import ros_graph_unavailable

REASON = ros_graph_unavailable()
#: one worker runs every test here (./dev test runs pytest-xdist): one ROS graph at a time
pytestmark = [pytest.mark.skipif(REASON is not None, reason=str(REASON)),
              pytest.mark.xdist_group("ros_graph")]

NODES = [("hasel_wheel_driver.driver_node", "DriverNode"),
         ("hasel_wheel_sim.sim_node", "SimNode"),
         ("hasel_wheel_mpc.observer_node", "ObserverNode"),
         ("hasel_wheel_mpc.mpc_node", "MpcNode"),
         ("hasel_wheel_bringup.trial_node", "TrialNode"),
         ("hasel_wheel_bringup.profile_node", "ProfileNode")]
#: Topics every rclpy node has, not ours.
BUILT_IN = {"/rosout", "/parameter_events"}


@pytest.fixture(scope="module")
def ros():
    import rclpy
    rclpy.init()
    yield rclpy
    rclpy.shutdown()


@pytest.mark.parametrize("module, name", NODES, ids=[n for _, n in NODES])
def test_node_builds_with_described_parameters_and_table_topics(ros, module, name):
    from rcl_interfaces.msg import ParameterType

    from hasel_wheel_common.nodes.ros_common import message_class, qos_profile

    node = getattr(importlib.import_module(module), name)()
    try:
        params = node.get_parameters_by_prefix("")
        assert len(params) > 2
        for pname in params:
            if pname == "use_sim_time":                 # rclpy's own
                continue
            d = node.describe_parameter(pname)
            assert d.description, f"{name}: parameter {pname} has no description"
            if d.type == ParameterType.PARAMETER_DOUBLE:
                assert d.floating_point_range, f"{name}: {pname} has no range"
            if d.type == ParameterType.PARAMETER_INTEGER:
                assert d.integer_range, f"{name}: {pname} has no range"
        table = {topics.qualified(t): t for t in topics.ALL}
        used = [*node.publishers, *node.subscriptions]
        ours = [e for e in used if e.topic_name not in BUILT_IN]
        assert ours, f"{name} uses none of the table's topics"
        for e in ours:
            assert e.topic_name in table, f"{name}: {e.topic_name} is not in topics.ALL"
            t = table[e.topic_name]
            assert e.msg_type is message_class(t.type), (name, t.name)
            if t is topics.REFERENCE and not hasattr(e, "publish"):
                continue            # subscribed reliable + volatile, to match `ros2 topic pub`
            want = qos_profile(t.qos)
            assert (e.qos_profile.reliability, e.qos_profile.durability) == \
                (want.reliability, want.durability), (name, t.name)
    finally:
        node.destroy_node()


def test_a_parameter_out_of_range_is_refused_with_the_range(ros):
    from rclpy.parameter import Parameter

    from hasel_wheel_mpc.mpc_node import MpcNode

    node = MpcNode()
    try:
        bad = node.set_parameters([Parameter("reference_speed", Parameter.Type.DOUBLE, 9.0)])[0]
        assert not bad.successful
        assert bad.reason == "Parameter reference_speed out of range Min: 0.0, Max: 5.0, value: 9.0"
        good = node.set_parameters([Parameter("reference_speed", Parameter.Type.DOUBLE, 1.5)])[0]
        assert good.successful and node.reference == 1.5
        worse = node.set_parameters([Parameter("max_horizon", Parameter.Type.DOUBLE, 0.01)])[0]
        assert not worse.successful and node.mpc.config.max_horizon == 6.0
        assert node.mpc.config.horizon_pads == 2
        three = node.set_parameters([Parameter("horizon_pads", Parameter.Type.INTEGER, 3)])[0]
        assert not three.successful and node.mpc.config.horizon_pads == 2
        one = node.set_parameters([Parameter("horizon_pads", Parameter.Type.INTEGER, 1)])[0]
        assert one.successful and node.mpc.config.horizon_pads == 1
    finally:
        node.destroy_node()
