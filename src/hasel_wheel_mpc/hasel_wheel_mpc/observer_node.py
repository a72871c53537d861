"""observer_node: the hybrid-state observer (six-state EKF) as a ROS 2 node.

Subscribes to ``telemetry`` (one :meth:`hasel_wheel_mpc.observer.Observer.step` per sample)
and ``command`` (which (phi_a, phi_d) each command sequence number stands for).  Publishes
``state_estimate`` at the telemetry rate (300 Hz), stamped as its sample, and
``/diagnostics``.  The disturbance estimator runs where the predictions are made, in
``mpc_node`` (:class:`hasel_wheel_mpc.core.ControlCore`): nothing flows back from the MPC.
"""
from __future__ import annotations

import time

from diagnostic_msgs.msg import DiagnosticStatus
from hasel_wheel_msgs.msg import ActuationCommand, HybridStateEstimate, WheelTelemetry
from rclpy.node import Node

from hasel_wheel_common import samples, topics
from hasel_wheel_common.nodes.ros_common import (create_publishers, fill, float_param,
                                                 publish_status, qos_profile, run_node,
                                                 text_param)
from hasel_wheel_sim.params import WheelParams

from hasel_wheel_mpc.core import START_ANGLES
from hasel_wheel_mpc.node_model import declare_controller_model
from hasel_wheel_mpc.observer import Observer, ObserverConfig


def _warm_up(params: WheelParams) -> None:
    """Load (or compile) the observer's model flow now, not at the first telemetry sample."""
    obs = Observer(params)
    for k in range(2):
        obs.step(samples.TelemetrySample(k / 300.0, 0, k, 0, 0.0, 0, 0, 0, 0, 0.0, 0.0, 0))


class ObserverNode(Node):

    def __init__(self) -> None:
        super().__init__("observer_node")
        params, ext, model_text = declare_controller_model(self)
        defaults = ObserverConfig()
        accel_noise = self.declare_parameter(
            "accel_noise", defaults.accel_noise,
            float_param("std of the white unmodelled acceleration [rad/s^2]", 1e-4, 10.0,
                        True)).value
        encoder_noise = self.declare_parameter(
            "encoder_noise", defaults.encoder_noise,
            float_param("encoder noise std beyond quantisation [rad]", 0.0, 0.1, True)).value
        gate_sigma = self.declare_parameter(
            "gate_sigma", defaults.gate_sigma,
            float_param("innovation gate: beyond this many sigma a sample is a glitch [1]",
                        1.0, 100.0, True)).value
        disturbance_rate = self.declare_parameter(
            "disturbance_rate", defaults.disturbance_rate,
            float_param("random-walk intensity of the acceleration disturbance (c, a, b) "
                        "[rad/s^2 per sqrt(s)]; 0 = no disturbance state", 0.0, 10.0, True)).value
        pivot_rate = self.declare_parameter(
            "pivot_rate", defaults.pivot_rate,
            float_param("random-walk intensity of the once-per-pivot-lap disturbance (e, f) "
                        "[rad/s^2 per sqrt(s)]; 0 = none", 0.0, 10.0, True)).value
        learn_speed = self.declare_parameter(
            "learn_speed", defaults.learn_speed,
            float_param("the disturbance is not learnt while the wheel is surely slower than "
                        "this (starting, stalled) [rad/s]", 0.0, 5.0, True)).value
        self.declare_parameter("frame_id", "wheel", text_param("frame_id of estimate headers"))
        period = self.declare_parameter(
            "diagnostics_period", 1.0, float_param("period of /diagnostics [s]", 0.1, 60.0,
                                                   True)).value
        self.frame_id = self.get_parameter("frame_id").value
        self.obs = Observer(params, ext, config=ObserverConfig(
            accel_noise=accel_noise, encoder_noise=encoder_noise, gate_sigma=gate_sigma,
            disturbance_rate=disturbance_rate, pivot_rate=pivot_rate, learn_speed=learn_speed))
        _warm_up(params)
        self.obs.command_sent(0, *START_ANGLES)
        # diagnostics
        self.last_seq: int | None = None
        self.missing = 0
        self.received = 0
        self.window_count = 0
        self.window_t0 = time.monotonic()
        self.last: HybridStateEstimate | None = None

        pubs = create_publishers(self, (topics.STATE_ESTIMATE, topics.DIAGNOSTICS))
        self.pub_est, self.pub_diag = pubs.values()
        self.create_subscription(WheelTelemetry, topics.TELEMETRY.name, self._on_telemetry,
                                 qos_profile(topics.TELEMETRY.qos))
        self.create_subscription(ActuationCommand, topics.COMMAND.name, self._on_command,
                                 qos_profile(topics.COMMAND.qos))
        self.create_timer(period, self._on_diagnostics)
        self.get_logger().info(
            f"ready: observer on {topics.TELEMETRY.name} -> {topics.STATE_ESTIMATE.name}; "
            + model_text)

    # -- inputs -------------------------------------------------------------------------------
    def _on_command(self, msg: ActuationCommand) -> None:
        self.obs.command_sent(int(msg.sequence), float(msg.phi_a), float(msg.phi_d),
                              bool(msg.now))

    def _on_telemetry(self, msg: WheelTelemetry) -> None:
        s = samples.telemetry_from_msg(msg)
        self.received += 1
        self.window_count += 1
        if self.last_seq is not None and s.sequence > self.last_seq + 1:
            self.missing += s.sequence - self.last_seq - 1
        self.last_seq = s.sequence
        e = self.obs.step(s)
        out = fill(HybridStateEstimate(), samples.state_msg(
            e.t, e.xi1, e.xi2, e.q, e.act_counter, e.deact_counter, e.eta_unwrapped,
            e.xi2_std, e.quality, e.accel_disturbance, e.accel_coefficients))
        out.header.stamp = msg.header.stamp          # the estimate is for this sample
        out.header.frame_id = self.frame_id
        self.pub_est.publish(out)
        self.last = out

    # -- diagnostics --------------------------------------------------------------------------
    def _on_diagnostics(self) -> None:
        now = time.monotonic()
        rate = self.window_count / max(now - self.window_t0, 1e-9)
        self.window_count, self.window_t0 = 0, now
        e = self.last
        quality = e.quality if e else 0.0
        values = {
            "sample_rate_hz": f"{rate:.1f}", "samples": str(self.received),
            "missing_samples": str(self.missing), "glitches_rejected": str(self.obs.rejected),
            "reacquisitions": str(self.obs.reacquisitions),
            "updates": str(self.obs.updates), "quality": f"{quality:.3f}",
            "xi2_rad_s": f"{e.xi2:.4f}" if e else "-",
            "xi2_stddev_rad_s": f"{e.xi2_stddev:.4f}" if e else "-",
            "accel_disturbance_rad_s2": f"{e.accel_disturbance:.4f}" if e else "-"}
        if e is None or rate < 1.0:
            level, text = DiagnosticStatus.STALE[0], "no telemetry"
        elif quality < 0.5 or rate < 250.0:
            level, text = DiagnosticStatus.WARN[0], "degraded (quality or sample rate low)"
        else:
            level, text = DiagnosticStatus.OK[0], "estimating"
        publish_status(self, self.pub_diag, "observer", "hasel_wheel_mpc", level,
                       text, values)


def main(args=None):
    run_node(ObserverNode, "observer_node", args)


if __name__ == '__main__':
    main()
