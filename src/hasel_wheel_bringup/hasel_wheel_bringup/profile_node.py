"""profile_node: plays a reference profile on ``reference_speed`` by the wheel's clock.

Each ``telemetry`` sample's device time drives
:class:`hasel_wheel_bringup.reference_profile.ProfilePlayer`; a due reference goes out on
``reference_speed`` (which mpc_node follows), and the node exits ``duration`` seconds after
the first sample.  The default is the demo's profile, so the graph runs what ``./dev demo``
runs::

    ros2 run hasel_wheel_bringup profile_node --ros-args -r __ns:=/wheel0
    ros2 run hasel_wheel_bringup profile_node --ros-args -r __ns:=/wheel0 \\
        -p profile:="0:1.0, 20:2.0" -p duration:=40.0
"""
from __future__ import annotations

from hasel_wheel_msgs.msg import WheelTelemetry
from rclpy.node import Node
from rclpy.task import Future
from std_msgs.msg import Float64

from hasel_wheel_common import topics
from hasel_wheel_common.nodes.ros_common import (create_publishers, float_param, qos_profile,
                                                 run_node, text_param)
from hasel_wheel_mpc.closed_loop import FIG11_DURATION, FIG11_PROFILE

from hasel_wheel_bringup.reference_profile import ProfilePlayer, parse_profile, profile_text


class ProfileNode(Node):

    def __init__(self) -> None:
        super().__init__("profile_node")
        text = self.declare_parameter(
            "profile", profile_text(FIG11_PROFILE),
            text_param("start [s]:reference [rad/s], comma-separated, by the device clock "
                       "from the first telemetry sample")).value
        duration = self.declare_parameter(
            "duration", FIG11_DURATION,
            float_param("exit this long after the first telemetry sample [s]", 0.1, 1e6,
                        True)).value
        self.player = ProfilePlayer(parse_profile(text), duration)
        self.finished = Future()
        (self.pub_ref,) = create_publishers(self, (topics.REFERENCE,)).values()
        self.create_subscription(WheelTelemetry, topics.TELEMETRY.name, self._on_telemetry,
                                 qos_profile(topics.TELEMETRY.qos))
        self.get_logger().info(f"ready: profile {text} for {duration:g} s")

    def _on_telemetry(self, msg: WheelTelemetry) -> None:
        if self.finished.done():
            return
        ref = self.player.step(msg.device_time_us * 1e-6)
        if ref is not None:
            self.pub_ref.publish(Float64(data=ref))
            self.get_logger().info(f"reference {ref:g} rad/s")
        if self.player.done:
            self.finished.set_result(True)


def main(args=None):
    run_node(ProfileNode, "profile_node", args)


if __name__ == '__main__':
    main()
