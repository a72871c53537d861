"""mpc_node: the control core (disturbance estimator, decisions, start policy, MPC) as a ROS 2 node.

Subscribes to ``state_estimate`` (the observer's six states, one per telemetry sample),
``telemetry`` (the encoder angle and the latched command) and ``reference_speed``; publishes
``command``, ``mpc_status`` (one per decision), ``hv_request`` (false once the core gives up a
stalled wheel) and ``/diagnostics`` (the core's status: starting, restarting, dead pads,
"stalled at pad N").  Every estimate goes to
:meth:`hasel_wheel_mpc.core.ControlCore.step`, which the embedded runner calls the same way,
so the node decides as the embedded runner does (``test_nodes.py``, ``test_core.py``).

The reference [rad/s] is the parameter ``reference_speed``; a std_msgs/Float64 on the topic
``reference_speed`` sets that parameter (same validation), so ``ros2 topic pub`` and
``ros2 param set`` both drive it and ``ros2 param get`` shows the one in use.  The node
publishes the reference in use on that topic (latched) whenever it changes, and again to
each subscriber that joins later (the recorder subscribes volatile), so a bag has every
reference of the run.
"""
from __future__ import annotations

import dataclasses
import math
import time

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from hasel_wheel_msgs.msg import ActuationCommand, HybridStateEstimate, MpcStatus, WheelTelemetry
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_msgs.msg import Bool, Float64

from hasel_wheel_common import samples, topics
from hasel_wheel_common.nodes.ros_common import (create_publishers, fill, float_param, int_param,
                                                 publish_status, qos_profile, run_node,
                                                 text_param)
from hasel_wheel_sim.model import SECTOR

from hasel_wheel_mpc.config import ESTIMATOR_MODES, MPC_PARAMS, ControllerConfig
from hasel_wheel_mpc.start_policy import StartConfig
from hasel_wheel_mpc.core import IDLE_SAMPLES, REDECIDE_MIN_TIME, ControlCore
from hasel_wheel_mpc.disturbance import ESTIMATOR_GATE, TRACKING_GAIN
from hasel_wheel_mpc.mpc import MpcConfig, gc_paused
from hasel_wheel_mpc.node_model import declare_controller_model
from hasel_wheel_mpc.observer import estimate_from_msg

#: Parameters that are MpcConfig fields of the same name (changeable at run time).
CONFIG_PARAMS = MPC_PARAMS
#: Parameters of the disturbance estimator (changeable at run time; d is kept).
ESTIMATOR_PARAMS = ("estimator_gain", "estimator_mode", "estimator_gate")
#: How often the node looks for new subscribers of ``reference_speed`` [s].
REFERENCE_ANNOUNCE_PERIOD = 0.2


class MpcNode(Node):

    def __init__(self) -> None:
        super().__init__("mpc_node")
        cfg = MpcConfig()
        params, ext, model_text = declare_controller_model(self)
        self.reference = self.declare_parameter(
            "reference_speed", 1.0,
            float_param("speed reference xi2_r [rad/s]; also set by std_msgs/Float64 on the "
                        "topic reference_speed", 0.0, 5.0)).value
        self.declare_parameter(
            "brake_threshold", cfg.brake_threshold,
            float_param("braking mode when the estimated speed (+ d) exceeds the reference by "
                        "this much [rad/s]", 0.01, 2.0))
        self.declare_parameter(
            "brake_phi_a", cfg.brake_phi_a,
            float_param("braking activation angle phi_a of pad eta + 2 [rad] (the earliest the "
                        "pad can still switch on is used if that is later)", -SECTOR, 0.0))
        self.declare_parameter(
            "brake_phi_d", cfg.brake_phi_d,
            float_param("braking deactivation angle phi_d [rad], above brake_phi_a", -SECTOR, 0.0))
        self.declare_parameter(
            "terminal_weight", cfg.terminal_weight,
            float_param("weight w_T of the speed error at the end of the horizon in the cost "
                        "[1]; 0 = (59) alone", 0.0, 100.0))
        self.declare_parameter(
            "horizon_pads", cfg.horizon_pads,
            int_param("cycles predicted per candidate: 1 = the paper's next cycle, 2 = that "
                      "cycle and the next, with the candidate's angles repeated [cycles]", 1, 2))
        self.declare_parameter(
            "time_weighted", cfg.time_weighted,
            text_param("cost = mean over all the cycle's samples (true) or (59)'s mean of the "
                       "two segment means (false)", read_only=False))
        self.declare_parameter(
            "deadline_margin", cfg.deadline_margin,
            float_param("the decision must be ready this long before the current switch-off "
                        "(command latency) [s]", 0.0, 0.05))
        self.declare_parameter(
            "max_horizon", cfg.max_horizon,
            float_param("longest prediction [s]", 0.1, 10.0))
        self.declare_parameter(
            "phi_a_min", cfg.phi_a_min,
            float_param("actuation limit: smallest activation angle phi_a the MPC may choose "
                        "(a smaller phi_a pushes harder) [rad]", 0.0, SECTOR))
        self.declare_parameter(
            "phi_a_max", cfg.phi_a_max,
            float_param("actuation limit: largest activation angle phi_a the MPC may choose "
                        "[rad]", 0.0, SECTOR))
        self.declare_parameter(
            "idle_samples", IDLE_SAMPLES,
            int_param("decide on an idle wheel after this many samples with HV off [samples]",
                      10, 3000))
        self.declare_parameter(
            "redecide_min_time", REDECIDE_MIN_TIME,
            float_param("decide at once on a new reference only if the next switching (off, "
                        "or on between pads) is at least this far away [s]", 0.0, 0.2))
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
            "estimator_gate", ESTIMATOR_GATE,
            float_param("estimator runs only within this band around the reference [rad/s]",
                        0.01, 10.0)).value
        start = StartConfig()
        still = self.declare_parameter(
            "still_speed", start.still_speed,
            float_param("start/stall policy: a wheel slower than this stands [rad/s]", 0.001,
                        1.0, True)).value
        stall = self.declare_parameter(
            "stall_time", start.stall_time,
            float_param("start/stall policy: standing this long with a reference above 0 is a "
                        "stall, and the wheel is restarted [s]", 0.1, 60.0, True)).value
        restarts = self.declare_parameter(
            "max_restarts", start.max_restarts,
            int_param("start/stall policy: STARTs in a row that do not bring the wheel to half "
                      "its reference before HV goes off (hv_request false) [count]", 0, 100,
                      True)).value
        period = self.declare_parameter(
            "diagnostics_period", 1.0, float_param("period of /diagnostics [s]", 0.1, 60.0,
                                                   True)).value
        mpc_cfg = dataclasses.replace(cfg, **{k: self.get_parameter(k).value
                                              for k in CONFIG_PARAMS})
        self.core = ControlCore(ControllerConfig(params, ext, mpc=mpc_cfg,
                                                 estimator_gain=gain or None,
                                                 estimator_mode=mode, estimator_gate=gate,
                                                 start=StartConfig(still, stall, restarts)))
        self.core.idle_samples = self.get_parameter("idle_samples").value
        self.core.redecide_min_time = self.get_parameter("redecide_min_time").value
        self.mpc = self.core.mpc                        # loads the compiled predictor

        # diagnostics
        self.estimates = 0
        self.window_estimates = 0
        self.window_t0 = time.monotonic()
        self.compute: list[float] = []
        self.slack_min = math.inf
        self.braking = 0
        self.late = 0           # decided in time by Mpc, but late once the node's overhead counts
        self.refs_rejected = 0
        self.last_status: MpcStatus | None = None
        self.last_age = math.nan

        pubs = create_publishers(self, (topics.COMMAND, topics.MPC_STATUS, topics.DIAGNOSTICS,
                                        topics.REFERENCE, topics.HV_REQUEST))
        self.pub_cmd, self.pub_status, self.pub_diag, self.pub_ref, self.pub_hv = pubs.values()
        self.reported = ("", ())                     # the core status last logged
        self.published_ref = math.nan
        self.ref_subscribers = 0
        self.create_subscription(HybridStateEstimate, topics.STATE_ESTIMATE.name,
                                 self._on_estimate, qos_profile(topics.STATE_ESTIMATE.qos))
        self.create_subscription(WheelTelemetry, topics.TELEMETRY.name, self._on_telemetry,
                                 qos_profile(topics.TELEMETRY.qos))
        # reliable but volatile: matches a latched publisher and `ros2 topic pub`'s default
        # (volatile) too; a transient_local subscription would not match the latter
        self.create_subscription(Float64, topics.REFERENCE.name, self._on_reference,
                                 qos_profile(topics.RELIABLE))
        self.add_on_set_parameters_callback(self._on_set_parameters)
        self.add_post_set_parameters_callback(self._after_set_parameters)
        self._publish_reference()
        self.create_timer(REFERENCE_ANNOUNCE_PERIOD, self._announce_reference)
        self.create_timer(period, self._on_diagnostics)
        self.get_logger().info(
            f"ready: MPC, reference {self.reference:g} rad/s, {len(self.mpc.cands)} coarse "
            f"candidates, brake threshold {mpc_cfg.brake_threshold:g} rad/s; estimator "
            + (f"{mode}, K = {gain:g}" if gain else "off") + "; " + model_text)

    # -- parameters ---------------------------------------------------------------------------
    def _on_set_parameters(self, params) -> SetParametersResult:
        changes = {p.name: p.value for p in params if p.name in CONFIG_PARAMS}
        new = {p.name: p.value for p in params}
        for p in params:
            if p.name == "reference_speed" and not math.isfinite(p.value):
                return SetParametersResult(successful=False,
                                           reason="reference_speed must be a finite speed [rad/s]")
            if p.name == "time_weighted" and not isinstance(p.value, bool):
                return SetParametersResult(successful=False,
                                           reason="time_weighted must be true or false")
        try:
            dataclasses.replace(self.mpc.config, **changes)
            if any(k in new for k in ESTIMATOR_PARAMS):
                self.core.set_estimator(*self._estimator_settings(new), dry_run=True)
        except ValueError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _estimator_settings(self, new: dict) -> tuple[float, str, float]:
        return tuple(new.get(k, self.get_parameter(k).value) for k in ESTIMATOR_PARAMS)

    def _after_set_parameters(self, params) -> None:
        new = {p.name: p.value for p in params}
        changes = {k: v for k, v in new.items() if k in CONFIG_PARAMS}
        if changes:
            self.mpc.config = dataclasses.replace(self.mpc.config, **changes)
        if any(k in new for k in ESTIMATOR_PARAMS):
            self.core.set_estimator(*self._estimator_settings(new))
        if "idle_samples" in new:
            self.core.idle_samples = int(new["idle_samples"])
        if "redecide_min_time" in new:
            self.core.redecide_min_time = float(new["redecide_min_time"])
        if "reference_speed" in new:
            self.reference = float(new["reference_speed"])
            if self.reference != self.published_ref:
                self.get_logger().info(f"reference {self.reference:g} rad/s")
            self._publish_reference()

    def _publish_reference(self) -> None:
        """Publish the reference in use on ``reference_speed`` when it changed, so a bag holds
        every reference the loop ran with, set by topic or by ``param set``.  This node's own
        message comes back to it and changes nothing."""
        if self.reference != self.published_ref:
            self.published_ref = self.reference
            self.pub_ref.publish(Float64(data=self.reference))

    def _announce_reference(self) -> None:
        """Publish the reference in use again when a subscriber has joined since the last
        call: a volatile late joiner (the recorder) does not get the latched sample."""
        count = self.pub_ref.get_subscription_count()
        if count > self.ref_subscribers:
            self.pub_ref.publish(Float64(data=self.reference))
        self.ref_subscribers = count

    def _on_reference(self, msg: Float64) -> None:
        result = self.set_parameters([Parameter("reference_speed", Parameter.Type.DOUBLE,
                                                float(msg.data))])[0]
        if not result.successful:
            self.refs_rejected += 1
            self.get_logger().warn(f"reference {msg.data!r} on {topics.REFERENCE.name} "
                                   f"rejected: {result.reason}")

    # -- the loop -----------------------------------------------------------------------------
    def _on_telemetry(self, msg: WheelTelemetry) -> None:
        self.core.telemetry(msg.device_time_us * 1e-6, msg.angle,
                            int(msg.last_command_sequence))

    @gc_paused          # a garbage collection must not delay a decision or its command
    def _on_estimate(self, msg: HybridStateEstimate) -> None:
        t_in = time.perf_counter()
        self.estimates += 1
        self.window_estimates += 1
        ref = self.reference
        r = self.core.step(estimate_from_msg(msg), ref)
        if r.hv_off:
            self.pub_hv.publish(Bool(data=False))
            self.get_logger().error(f"{self.core.status().text}; hv_request false sent")
            self._on_diagnostics()
        if r.command is None:
            return
        t = self.get_clock().now().nanoseconds * 1e-9
        self.pub_cmd.publish(fill(ActuationCommand(), samples.command_msg(r.command, t)))
        if r.decision is None:
            kind = "START of the pad in contact" if r.command.now else "at the start angles"
            self.get_logger().info(f"start {self.core.starts}: actuator {r.command.n_a} {kind}")
            return
        dec = r.decision
        overhead = time.perf_counter() - t_in - dec.compute_time
        slack = dec.deadline_slack - overhead
        if slack < 0.0 and not dec.deadline_missed and not dec.braking:
            self.late += 1
        status = fill(MpcStatus(), samples.mpc_status_msg(
            t, dec.command, ref, dec.predicted_speed, dec.cost, dec.compute_time, slack,
            dec.candidates, dec.deadline_missed, dec.braking, r.d))
        self.pub_status.publish(status)
        self.last_status = status
        self.last_age = t - (msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9)
        self.braking += dec.braking
        if not dec.braking:
            self.compute.append(dec.compute_time)
            self.slack_min = min(self.slack_min, slack)

    # -- diagnostics --------------------------------------------------------------------------
    def _on_diagnostics(self) -> None:
        now = time.monotonic()
        rate = self.window_estimates / max(now - self.window_t0, 1e-9)
        self.window_estimates, self.window_t0 = 0, now
        lat = np.asarray(self.compute) * 1e3
        self.compute = []
        s = self.last_status
        values = {
            "reference_rad_s": f"{self.reference:.3f}",
            "estimate_rate_hz": f"{rate:.1f}",
            "decisions": str(self.mpc.decisions), "braking_decisions": str(self.braking),
            "deadline_misses": str(self.mpc.deadline_misses),
            "late_after_overhead": str(self.late),
            "compute_ms_p50": f"{np.percentile(lat, 50):.3f}" if lat.size else "-",
            "compute_ms_p99": f"{np.percentile(lat, 99):.3f}" if lat.size else "-",
            "compute_ms_max": f"{lat.max():.3f}" if lat.size else "-",
            "slack_ms_min": f"{self.slack_min * 1e3:.1f}" if math.isfinite(self.slack_min) else "-",
            "candidates_last": str(s.candidates_evaluated) if s else "-",
            "braking_now": str(s.braking) if s else "-",
            "predicted_speed_rad_s": f"{s.predicted_speed:.4f}" if s else "-",
            "estimate_age_ms": f"{self.last_age * 1e3:.1f}",
            "references_rejected": str(self.refs_rejected),
            "start_commands": str(self.core.starts), "started": str(self.core.started),
            "estimator_d_rad_s": f"{self.core.d:.4f}",
            "estimator_updates": str(self.core.estimator.updates if self.core.estimator else 0),
            "restarts": str(self.core.stall.restarts),
            "stalls": str(self.core.stall.total_restarts),
            "dead_pads": " ".join(str(p) for p in sorted(self.core.pads.dead)) or "-",
            "pad_gains": " ".join(_f(g) for g in self.core.pads.gains())}
        self.slack_min = math.inf
        status = self.core.status()
        if status.level > 0 and (status.code, status.pads) != self.reported:
            self.get_logger().warn(status.text)
        self.reported = (status.code, status.pads)
        if status.level > 0:
            level, text = status.level, status.text
        elif rate < 1.0:
            level, text = DiagnosticStatus.STALE[0], "no state estimate"
        elif self.mpc.deadline_misses or self.late:
            level, text = DiagnosticStatus.WARN[0], "deadline misses (fallback input sent)"
        else:
            level, text = DiagnosticStatus.OK[0], "deciding"
        publish_status(self, self.pub_diag, "mpc", "hasel_wheel_mpc", level,
                       text, values)


def _f(x: float) -> str:
    return "-" if math.isnan(x) else f"{x:.2f}"


def main(args=None):
    run_node(MpcNode, "mpc_node", args)


if __name__ == '__main__':
    main()
