"""observer_node: the hybrid-state observer and the disturbance estimator as a ROS 2 node.

Subscribes to ``telemetry`` (one EKF step per sample, :class:`hasel_wheel_mpc.observer.Observer`),
``command`` (which (phi_a, phi_d) each command sequence number stands for) and ``mpc_status``
(the MPC's predicted cycle mean and reference, for the estimator).  Publishes
``state_estimate`` at the telemetry rate (300 Hz) and ``/diagnostics``.

Disturbance estimator (:class:`hasel_wheel_mpc.disturbance.IntegralEstimator`): one update at
each switch-off of the actuator of interest, from the mean estimated speed over the cycle that
just ended and the prediction the MPC made for it, as in ``closed_loop.run_closed_loop``.  Its
d [rad/s] goes out in ``HybridStateEstimate.disturbance``; ``estimator_gain`` 0 switches it off.
"""
from __future__ import annotations

import math
import time
from collections import deque

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from hasel_wheel_msgs.msg import (ActuationCommand, HybridStateEstimate, MpcStatus,
                                  WheelTelemetry)
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node

from hasel_wheel_common import samples
from hasel_wheel_common import topics
from hasel_wheel_common.nodes.ros_common import (create_publishers, fill, float_param,
                                                 publish_status, qos_profile, run_node,
                                                 text_param)
from hasel_wheel_sim.params import ParameterError, WheelParams

from hasel_wheel_mpc.disturbance import TRACKING_GAIN, IntegralEstimator
from hasel_wheel_mpc.node_model import declare_controller_model
from hasel_wheel_mpc.observer import Observer, ObserverConfig

ESTIMATOR_MODES = ("tracking", "paper")


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
        gain = self.declare_parameter(
            "estimator_gain", TRACKING_GAIN,
            float_param("gain K of the disturbance estimator (57)-(58) [1 per cycle]; "
                        "0 = estimator off", 0.0, 1.99)).value
        mode = self.declare_parameter(
            "estimator_mode", "tracking",
            text_param("estimator error: tracking (xi2_meas - xi2_r) or paper "
                       "(xi2_meas - xi2_prdt, eq. 58)", read_only=False,
                       choices=ESTIMATOR_MODES)).value
        gate = self.declare_parameter(
            "estimator_gate", 0.64,
            float_param("estimator runs only within this band around the reference [rad/s]",
                        0.01, 10.0)).value
        self.declare_parameter("frame_id", "wheel", text_param("frame_id of estimate headers"))
        period = self.declare_parameter(
            "diagnostics_period", 1.0, float_param("period of /diagnostics [s]", 0.1, 60.0,
                                                   True)).value
        self.frame_id = self.get_parameter("frame_id").value
        self.obs = Observer(params, ext, config=ObserverConfig(
            accel_noise=accel_noise, encoder_noise=encoder_noise, gate_sigma=gate_sigma,
            disturbance_rate=disturbance_rate, pivot_rate=pivot_rate))
        if mode not in ESTIMATOR_MODES:
            raise ParameterError(f"estimator_mode = {mode!r}: expected one of {ESTIMATOR_MODES}")
        self.est = IntegralEstimator(gain=gain, gate=gate, mode=mode) if gain > 0.0 else None
        _warm_up(params)
        self.est_mode, self.est_gate = mode, gate

        # estimator bookkeeping, as in closed_loop.run_closed_loop
        self.edges = samples.PadEdges()
        self.cycle_speeds: list[float] = []
        self.queued: deque = deque(maxlen=8)   # model-only predictions of the coming cycles
        self.window_pred: float | None = None
        self.off_since_status = True
        self.reference = math.nan               # of the MPC's latest decision [rad/s]
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
        self.create_subscription(MpcStatus, topics.MPC_STATUS.name, self._on_status,
                                 qos_profile(topics.MPC_STATUS.qos))
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.add_post_set_parameters_callback(self._after_set_parameters)
        self.create_timer(period, self._on_diagnostics)
        self.get_logger().info(
            f"ready: observer on {topics.TELEMETRY.name} -> {topics.STATE_ESTIMATE.name}; "
            "estimator " + (f"{mode}, K = {gain:g}" if self.est else "off") + "; " +
            model_text)

    # -- parameters ---------------------------------------------------------------------------
    def _estimator_settings(self, params) -> tuple[float, str, float]:
        new = {p.name: p.value for p in params}
        return (new.get("estimator_gain", self.est.gain if self.est else 0.0),
                new.get("estimator_mode", self.est_mode), new.get("estimator_gate", self.est_gate))

    def _on_set_parameters(self, params) -> SetParametersResult:
        gain, mode, gate = self._estimator_settings(params)
        if mode not in ESTIMATOR_MODES:
            return SetParametersResult(
                successful=False,
                reason=f"estimator_mode = {mode!r}: expected one of {', '.join(ESTIMATOR_MODES)}")
        if gain > 0.0:
            try:
                IntegralEstimator(gain=gain, gate=gate, mode=mode)
            except ValueError as exc:
                return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _after_set_parameters(self, params) -> None:
        gain, mode, gate = self._estimator_settings(params)
        self.est_mode, self.est_gate = mode, gate
        if gain <= 0.0:
            self.est = None
        elif self.est is None:
            self.est = IntegralEstimator(gain=gain, gate=gate, mode=mode)
        else:           # keep d: a new gain applies from the next update
            self.est.gain, self.est.gate, self.est.mode = gain, gate, mode

    # -- inputs -------------------------------------------------------------------------------
    def _on_command(self, msg: ActuationCommand) -> None:
        self.obs.command_sent(int(msg.sequence), float(msg.phi_a), float(msg.phi_d))

    def _on_status(self, msg: MpcStatus) -> None:
        # a new decision predicts the cycle that starts at the next switch-off; a second one
        # before that switch-off (the MPC re-decided on a new reference) replaces it
        self.obs.command_sent(int(msg.command.sequence), float(msg.command.phi_a),
                              float(msg.command.phi_d))
        d = self.est.d if self.est else 0.0
        prediction = None if msg.braking else msg.predicted_speed - d     # model-only mean
        if math.isfinite(self.reference) and msg.reference_speed != self.reference:
            # cycles predicted for the old reference say nothing about the model's error
            # against the new one (as controller.SpeedController)
            self.window_pred = None
            self.queued = deque([None] * len(self.queued), maxlen=self.queued.maxlen)
        if not self.off_since_status and self.queued:
            self.queued[-1] = prediction
        else:
            self.queued.append(prediction)
        self.off_since_status = False
        self.reference = msg.reference_speed

    def _on_telemetry(self, msg: WheelTelemetry) -> None:
        s = samples.telemetry_from_msg(msg)
        self.received += 1
        self.window_count += 1
        if self.last_seq is not None and s.sequence > self.last_seq + 1:
            self.missing += s.sequence - self.last_seq - 1
        self.last_seq = s.sequence
        e = self.obs.step(s)
        speed = e.xi2
        self.cycle_speeds.append(speed)
        _, switched_off = self.edges.step(s.q, s.eta_unwrapped)
        if switched_off:                       # the cycle some decision predicted has ended
            self.off_since_status = True
            if (self.est and self.window_pred is not None and len(self.cycle_speeds) > 1
                    and math.isfinite(self.reference)):
                self.est.step(float(np.mean(self.cycle_speeds[:-1])), self.window_pred,
                              self.reference)
            self.window_pred = self.queued.popleft() if self.queued else None
            self.cycle_speeds = [speed]
        out = fill(HybridStateEstimate(), samples.state_msg(
            e.t, e.xi1, e.xi2, e.q, e.act_counter, e.deact_counter, e.eta_unwrapped,
            self.est.d if self.est else 0.0, e.xi2_std, e.quality, e.accel_disturbance,
            e.accel_coefficients))
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
            "accel_disturbance_rad_s2": f"{e.accel_disturbance:.4f}" if e else "-",
            "estimator": f"{self.est.mode}, K = {self.est.gain:g}" if self.est else "off",
            "estimator_d_rad_s": f"{self.est.d:.4f}" if self.est else "0",
            "estimator_updates": str(self.est.updates) if self.est else "0",
            "reference_rad_s": f"{self.reference:.3f}"}
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
