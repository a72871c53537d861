"""launch_testing: hardware_closed_loop.launch.py (driver_node, observer, MPC) against the
virtual Teensy on a pseudo-terminal running the C++ firmware core: HV enabled and a reference
set as a user does, the loop holds it through the firmware's own switching, and every process
exits cleanly (0) on the SIGINT that ends the launch.

Runs where ROS 2 Jazzy is installed, a C++ compiler and CMake are present, and only inside a
loopback-only network namespace (``hasel_wheel_common.ros_sandbox``); anywhere else,
including the project's default test command, it skips and says why.  The C++ core's own
tests run everywhere (``docs/device.md``).
"""
import os
import signal
import subprocess
import sys
import tempfile
import time
import unittest
from pathlib import Path

import pytest

from hasel_wheel_common import topics
from hasel_wheel_common.ros_sandbox import ros_graph_unavailable
from hasel_wheel_sim.device_cpp import compiler_missing

FIRMWARE = Path(__file__).resolve().parents[3] / "firmware"
REASON = ros_graph_unavailable() or (f"needs {compiler_missing()}" if compiler_missing() else None)
NAMESPACE = "/hw"
LINK = Path(tempfile.gettempdir()) / f"hasel-launch-test-{os.getpid()}" / "usb-Teensyduino-if00"
TARGET = 1.5            # reference [rad/s]
W0 = 3.0                # the virtual wheel's speed when it is plugged in [rad/s]
SETTLE = 25.0           # seconds allowed to get there [s]
WINDOW = 5.0            # steady speed = mean estimated speed over the last WINDOW seconds [s]

if REASON is not None:
    def test_needs_ros_2_a_compiler_and_a_loopback_only_namespace():
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
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient
    from std_msgs.msg import Float64

    from hasel_wheel_common.nodes.ros_common import message_class, qos_profile

    @pytest.mark.launch_test
    def generate_test_description():
        LINK.parent.mkdir(parents=True, exist_ok=True)
        path = PathJoinSubstitution([FindPackageShare("hasel_wheel_bringup"), "launch",
                                     "hardware_closed_loop.launch.py"])
        return LaunchDescription([
            IncludeLaunchDescription(PythonLaunchDescriptionSource(path),
                                     launch_arguments={"namespace": NAMESPACE.strip("/"),
                                                       "port": str(LINK),
                                                       "record": "false"}.items()),
            launch_testing.actions.ReadyToTest()])

    class TestHardwareLaunchWithCppCore(unittest.TestCase):

        @classmethod
        def setUpClass(cls):
            rclpy.init()
            cls.node = rclpy.create_node("hardware_launch_test")
            cls.device = None

        @classmethod
        def tearDownClass(cls):
            cls.node.destroy_node()
            rclpy.shutdown()

        def _spin_until(self, done, timeout: float, what) -> None:
            end = time.monotonic() + timeout
            while not done():
                if time.monotonic() > end:
                    self.fail(f"after {timeout:g} s: {what()}")
                rclpy.spin_once(self.node, timeout_sec=0.1)

        def _set(self, node: str, name: str, value) -> None:
            client = AsyncParameterClient(self.node, f"{NAMESPACE}/{node}")
            self.assertTrue(client.wait_for_services(timeout_sec=60.0), f"{node}: no services")
            future = client.set_parameters([Parameter(name, value=value)])
            rclpy.spin_until_future_complete(self.node, future, timeout_sec=30.0)
            self.assertTrue(future.result().results[0].successful, f"{node}.{name} := {value}")

        def test_1_the_loop_holds_a_reference_through_the_cpp_core(self):
            ns = NAMESPACE
            speed = []          # (stamp [s], xi2 [rad/s])
            self.node.create_subscription(
                message_class(topics.STATE_ESTIMATE.type), f"{ns}/{topics.STATE_ESTIMATE.name}",
                lambda m: speed.append((m.header.stamp.sec + m.header.stamp.nanosec * 1e-9,
                                        m.xi2)), qos_profile(topics.STATE_ESTIMATE.qos))
            pub = self.node.create_publisher(Float64, f"{ns}/{topics.REFERENCE.name}",
                                             qos_profile(topics.REFERENCE.qos))
            # the graph is up (the driver waits for its port), then the device is plugged in
            self._set("mpc_node", "reference_speed", TARGET)
            env = dict(os.environ, HASEL_FIRMWARE_DIR=str(FIRMWARE))
            type(self).device = subprocess.Popen(
                [sys.executable, "-m", "hasel_wheel_bringup.cli", "virtual-teensy", str(LINK),
                 "--device-core", "cpp", "--initial-speed", str(W0)],
                env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
            # HV is asked for once the device is there (on a reconnect the driver sends HV off)
            self._spin_until(lambda: speed, 120.0, lambda: "no state estimate")
            self._set("driver", "hv_enabled", True)
            pub.publish(Float64(data=TARGET))
            t0 = speed[-1][0]
            self._spin_until(lambda: speed[-1][0] >= t0 + SETTLE + WINDOW,
                             2.0 * (SETTLE + WINDOW), lambda: "state estimates stopped")
            last = [v for t, v in speed if t >= speed[-1][0] - WINDOW]
            mean = sum(last) / len(last)
            self.assertAlmostEqual(mean, TARGET, delta=0.02 * TARGET)

        def test_2_hv_goes_off_and_the_device_stops_cleanly(self):
            hv = []             # hv_monitor of each telemetry sample [V]
            self.node.create_subscription(
                message_class(topics.TELEMETRY.type), f"{NAMESPACE}/{topics.TELEMETRY.name}",
                lambda m: hv.append(m.hv_monitor), qos_profile(topics.TELEMETRY.qos))
            self._set("driver", "hv_enabled", False)
            self._spin_until(lambda: hv and hv[-1] == 0.0, 30.0,
                             lambda: f"HV still on: {hv[-1] if hv else None} V")
            device = type(self).device
            self.assertIsNotNone(device)
            device.send_signal(signal.SIGINT)
            out, _ = device.communicate(timeout=30)
            self.assertEqual(device.returncode, 0, out)
            self.assertFalse(LINK.exists())                 # unplugged on the way out

    @launch_testing.post_shutdown_test()
    class TestCleanShutdown(unittest.TestCase):

        def test_every_process_exits_cleanly_on_sigint(self, proc_info):
            launch_testing.asserts.assertExitCodes(proc_info)
