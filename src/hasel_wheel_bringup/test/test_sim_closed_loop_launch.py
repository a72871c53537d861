"""launch_testing: sim_closed_loop.launch.py brings up every documented topic with its type,
tracks a reference published on ``reference_speed``, and every process exits cleanly (0) on
the SIGINT that ends the launch.

Runs where ROS 2 Jazzy is installed (``colcon test``, or ``launch_test`` on this file) and
only inside a loopback-only network namespace (``hasel_wheel_common.ros_sandbox``); anywhere
else, including the project's default test command, it skips and says why.
"""
import time
import unittest

import pytest

from hasel_wheel_common import topics
from hasel_wheel_common.ros_sandbox import ros_graph_unavailable

REASON = ros_graph_unavailable()
NAMESPACE = "/lt"
TARGET = 1.5            # reference published on reference_speed [rad/s]
SETTLE = 25.0           # simulated (= wall, time_scale 1) seconds allowed to get there [s]
WINDOW = 5.0            # steady speed = mean estimated speed over the last WINDOW seconds [s]

if REASON is not None:
    def test_needs_ros_2_in_a_loopback_only_namespace():
        pytest.skip(REASON)
else:
    import launch_testing.actions
    import launch_testing.asserts
    import rclpy
    from launch import LaunchDescription
    from launch.actions import IncludeLaunchDescription
    from launch.launch_description_sources import PythonLaunchDescriptionSource
    from launch.substitutions import PathJoinSubstitution
    from launch_ros.substitutions import FindPackageShare
    from std_msgs.msg import Float64

    from hasel_wheel_common.nodes.ros_common import message_class, qos_profile

    @pytest.mark.launch_test
    def generate_test_description():
        path = PathJoinSubstitution([FindPackageShare("hasel_wheel_bringup"), "launch",
                                     "sim_closed_loop.launch.py"])
        return LaunchDescription([
            IncludeLaunchDescription(PythonLaunchDescriptionSource(path),
                                     launch_arguments={"namespace": NAMESPACE.strip("/"),
                                                       "record": "false"}.items()),
            launch_testing.actions.ReadyToTest()])

    class TestSimClosedLoop(unittest.TestCase):

        @classmethod
        def setUpClass(cls):
            rclpy.init()
            cls.node = rclpy.create_node("sim_closed_loop_test")

        @classmethod
        def tearDownClass(cls):
            cls.node.destroy_node()
            rclpy.shutdown()

        def test_1_every_documented_topic_appears_with_its_type(self):
            want = {topics.qualified(t, NAMESPACE): t.type for t in topics.ALL}
            end = time.monotonic() + 300.0       # a first run compiles the models (numba)
            while time.monotonic() < end:
                have = dict(self.node.get_topic_names_and_types())
                if all(name in have for name in want):
                    break
                time.sleep(0.5)
            for name, datatype in want.items():
                self.assertEqual(have.get(name), [datatype], name)

        def test_2_tracks_a_reference_published_on_the_topic(self):
            ns = NAMESPACE
            speed = []                        # (t [s] from the estimate's stamp, xi2 [rad/s])
            references = []
            est_cls = message_class(topics.STATE_ESTIMATE.type)
            status_cls = message_class(topics.MPC_STATUS.type)
            self.node.create_subscription(
                est_cls, f"{ns}/{topics.STATE_ESTIMATE.name}",
                lambda m: speed.append((m.header.stamp.sec + m.header.stamp.nanosec * 1e-9,
                                        m.xi2)),
                qos_profile(topics.STATE_ESTIMATE.qos))
            self.node.create_subscription(status_cls, f"{ns}/{topics.MPC_STATUS.name}",
                                          lambda m: references.append(m.reference_speed),
                                          qos_profile(topics.MPC_STATUS.qos))
            pub = self.node.create_publisher(Float64, f"{ns}/{topics.REFERENCE.name}",
                                             qos_profile(topics.REFERENCE.qos))
            # publish until a decision uses it (discovery may drop the first ones)
            end = time.monotonic() + 60.0
            next_pub = 0.0
            while time.monotonic() < end and TARGET not in references:
                if time.monotonic() >= next_pub:
                    pub.publish(Float64(data=TARGET))
                    next_pub = time.monotonic() + 1.0
                rclpy.spin_once(self.node, timeout_sec=0.1)
            self.assertIn(TARGET, references, "no MPC decision used the published reference")
            while not speed and time.monotonic() < end:
                rclpy.spin_once(self.node, timeout_sec=0.1)
            t_ref = speed[-1][0]
            while not speed or speed[-1][0] < t_ref + SETTLE + WINDOW:
                rclpy.spin_once(self.node, timeout_sec=0.1)
                self.assertLess(time.monotonic(), end, "state estimates stopped")
            last = [v for t, v in speed if t >= speed[-1][0] - WINDOW]
            mean = sum(last) / len(last)
            self.assertGreater(len(last), 0.8 * 300 * WINDOW)    # ~300 Hz estimates
            self.assertAlmostEqual(mean, TARGET, delta=0.05 * TARGET)
            self.assertEqual(references[-1], TARGET)

    @launch_testing.post_shutdown_test()
    class TestCleanShutdown(unittest.TestCase):

        def test_every_process_exits_cleanly_on_sigint(self, proc_info):
            launch_testing.asserts.assertExitCodes(proc_info)
