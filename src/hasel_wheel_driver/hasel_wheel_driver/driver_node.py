"""driver_node: the wheel's Teensy (USB serial, protocol v1.1) as ROS 2 topics.

Publishes ``telemetry``, ``joint_states`` and ``/diagnostics``; forwards ``command`` after
validating it, as a START when its ``now`` is true.  Serial I/O runs in the driver core's own
thread, so the executor never waits on the port.  HV: off until ``hv_enabled`` is set true;
off again on shutdown (SIGINT/SIGTERM), on a stale or lost link, whenever the device's
watchdog trips, and on ``hv_request`` false (the MPC gave up a stalled wheel).  The serial link opens
once ``telemetry_subscribers`` subscriptions match ``telemetry`` (or after
``subscriber_timeout``), so the recorder gets the first sample too
(:mod:`hasel_wheel_driver.link_start`).
"""
from __future__ import annotations

import sys
import time

from diagnostic_msgs.msg import DiagnosticStatus
from hasel_wheel_msgs.msg import ActuationCommand, WheelTelemetry
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter
from sensor_msgs.msg import JointState
from std_msgs.msg import Bool

from hasel_wheel_common import samples
from hasel_wheel_common import topics
from hasel_wheel_common.published_count import PublishedCount
from hasel_wheel_driver.link import DriverCore, LinkConfig
from hasel_wheel_driver.link_start import link_may_start
from hasel_wheel_common.nodes.ros_common import (create_publishers, fill, float_param,
                                                 int_param, publish_status, qos_profile,
                                                 run_node, text_param)


#: How often the node checks whether its link may open [s].
LINK_START_POLL = 0.05


class DriverNode(Node):

    def __init__(self) -> None:
        super().__init__("hasel_wheel_driver")
        port = self.declare_parameter(
            "port", "/dev/ttyACM0",
            text_param("serial device; prefer the stable /dev/serial/by-id/usb-... name")).value
        hb = self.declare_parameter(
            "heartbeat_period", 0.02,
            float_param("heartbeat period [s] (device watchdog: 100 ms)", 0.005, 0.05, True)).value
        timeout = self.declare_parameter(
            "link_timeout", 0.25,
            float_param("no telemetry this long = stale link: ESTOP + HV off [s]", 0.05, 5.0, True)).value
        hv_at_start = self.declare_parameter(
            "hv_enabled", False,
            text_param("request HV on (true) or off (false); always off at start-up",
                       read_only=False)).value
        if hv_at_start is not False:       # from a parameter file or --ros-args: not at start-up
            self.set_parameters([Parameter("hv_enabled", Parameter.Type.BOOL, False)])
            self.get_logger().warn(f"hv_enabled = {hv_at_start!r} at start-up ignored: HV stays "
                                   f"off until 'ros2 param set <node> hv_enabled true'")
        self.declare_parameter("frame_id", "wheel", text_param("frame_id of telemetry headers"))
        period = self.declare_parameter(
            "diagnostics_period", 1.0, float_param("period of /diagnostics [s]", 0.1, 60.0, True)).value
        self.frame_id = self.get_parameter("frame_id").value
        self.telemetry_subscribers = self.declare_parameter(
            "telemetry_subscribers", 0,
            int_param("open the serial link once this many subscriptions listen to telemetry "
                      "(the launch files count the observer, the MPC and the recorder) [count]; "
                      "0 = at once", 0, 64, True)).value
        self.subscriber_timeout = self.declare_parameter(
            "subscriber_timeout", 5.0,
            float_param("open the link after this long even without them [s]", 0.0, 60.0,
                        True)).value
        self.commands_refused = 0
        self.published = PublishedCount()     # telemetry samples published (diagnostics)

        pubs = create_publishers(self, (topics.TELEMETRY, topics.JOINT_STATES, topics.DIAGNOSTICS))
        self.pub_tlm, self.pub_js, self.pub_diag = pubs.values()
        self.create_subscription(ActuationCommand, topics.COMMAND.name, self._on_command,
                                 qos_profile(topics.COMMAND.qos))
        self.create_subscription(Bool, topics.HV_REQUEST.name, self._on_hv_request,
                                 qos_profile(topics.HV_REQUEST.qos))
        self.core = DriverCore(LinkConfig(port, heartbeat_period=hb, link_timeout=timeout),
                               on_sample=self._on_sample, on_event=self._on_event)
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.add_post_set_parameters_callback(self._after_set_parameters)
        self.create_timer(period, self._on_diagnostics)
        self.created = time.monotonic()
        self.link_timer = self.create_timer(LINK_START_POLL, self._start_link)
        self.get_logger().info(f"serial link on {port} once {self.telemetry_subscribers} "
                               f"subscribers listen to telemetry; HV stays off until "
                               f"hv_enabled is true")

    def _start_link(self) -> None:
        """Open the serial link once the telemetry has its listeners (or on timeout)."""
        matched = self.pub_tlm.get_subscription_count()
        waited = time.monotonic() - self.created
        if not link_may_start(matched, self.telemetry_subscribers, waited,
                              self.subscriber_timeout):
            return
        self.destroy_timer(self.link_timer)
        if matched < self.telemetry_subscribers:
            self.get_logger().warn(f"opening the serial link with {matched} of "
                                   f"{self.telemetry_subscribers} telemetry subscribers after "
                                   f"{waited:.1f} s (subscriber_timeout): the others miss the "
                                   f"first samples")
        self.core.start()

    def _on_set_parameters(self, params) -> SetParametersResult:
        for p in params:
            if p.name == "hv_enabled":
                if not isinstance(p.value, bool):
                    return SetParametersResult(successful=False, reason="hv_enabled must be true or false")
        return SetParametersResult(successful=True)

    def _after_set_parameters(self, params) -> None:
        for p in params:
            if p.name == "hv_enabled":
                if p.value:
                    self.core.clear_estop()
                self.core.set_hv(p.value)

    def _on_sample(self, s: samples.TelemetrySample) -> None:
        # runs in the link thread; stamp with the ROS time of arrival
        if not self.context.ok():      # shutting down (SIGINT/SIGTERM): nothing to publish to
            return
        host = s._replace(t=self.get_clock().now().nanoseconds * 1e-9)
        self.pub_tlm.publish(fill(WheelTelemetry(), samples.telemetry_msg(host, self.frame_id)))
        self.published.count(s.sequence)
        self.pub_js.publish(fill(JointState(), samples.joint_state_msg(host)))

    def _on_event(self, event: str) -> None:
        if any(w in event for w in ("lost", "stale", "v1.0")):
            self.get_logger().warn(f"link: {event}")
        else:
            self.get_logger().info(f"link: {event}")

    def _on_hv_request(self, msg: Bool) -> None:
        """``hv_request`` false (the MPC gave up a stalled wheel): HV off, as ``hv_enabled``
        false does.  True is ignored: HV comes on only by ``hv_enabled``."""
        if msg.data or not self.get_parameter("hv_enabled").value:
            return
        self.get_logger().error("hv_request false (the controller gave up a stalled wheel): "
                                "HV off; set hv_enabled true to try again")
        self.set_parameters([Parameter("hv_enabled", Parameter.Type.BOOL, False)])

    def _on_command(self, msg: ActuationCommand) -> None:
        why = self.core.send_command(samples.Command(int(msg.n_a), float(msg.phi_a),
                                                     float(msg.phi_d), int(msg.sequence),
                                                     now=bool(msg.now)))
        if why:
            self.commands_refused += 1
            self.get_logger().warn(f"command {msg.sequence} not sent, HV stays off for it: {why}")

    def _on_diagnostics(self) -> None:
        d = self.core.diagnostics()
        d["commands_refused"] = str(self.commands_refused)
        d.update(self.published.diagnostics())
        ok = self.core.connected and not self.core.stale
        level = DiagnosticStatus.OK[0] if ok else DiagnosticStatus.ERROR[0]
        publish_status(self, self.pub_diag, "serial link", self.core.config.port, level,
                       "link up" if ok else "link down or stale: HV off", d)

    def destroy_node(self) -> None:
        confirmed = self.core.shutdown()          # ESTOP, then HV(0) as the last frame
        note = f"HV off {'confirmed' if confirmed else 'sent, NOT confirmed'}"
        if self.context.ok():
            self.get_logger().info(note)
        else:                                     # after SIGINT/SIGTERM rosout is gone
            print(f"[{self.get_fully_qualified_name()}] {note}", file=sys.stderr, flush=True)
        super().destroy_node()


def main(args=None):
    run_node(DriverNode, "hasel_wheel_driver", args)


if __name__ == '__main__':
    main()
