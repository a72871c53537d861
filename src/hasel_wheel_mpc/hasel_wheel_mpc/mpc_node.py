"""mpc_node: the model predictive speed controller (paper Sec. V) as a ROS 2 node.

Decides at each switch-on of the actuator of interest seen in ``state_estimate`` (the paper's
decision point), on an idle wheel after ``idle_samples`` samples with HV off, and once more at
once when the reference changes while the actuator is on and there is time before its
switch-off: the loop of ``closed_loop.run_closed_loop``, with :meth:`hasel_wheel_mpc.mpc.Mpc.decide`
doing the work.  ``telemetry`` tells which command the device latched (its phi_a, phi_d are the
current pad's).  Publishes ``command``, ``mpc_status`` (one per decision) and ``/diagnostics``.

The reference [rad/s] is the parameter ``reference_speed``; a std_msgs/Float64 on the topic
``reference_speed`` sets that parameter (same validation), so ``ros2 topic pub`` and
``ros2 param set`` both drive it and ``ros2 param get`` always shows the one in use.  The node
publishes the reference in use on that topic (latched) whenever it changes, so the bag has it.
"""
from __future__ import annotations

import dataclasses
import math
import time
from collections import OrderedDict, deque

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from hasel_wheel_msgs.msg import ActuationCommand, HybridStateEstimate, MpcStatus, WheelTelemetry
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_msgs.msg import Float64

from hasel_wheel_common import samples
from hasel_wheel_common import topics
from hasel_wheel_common.nodes.ros_common import (create_publishers, fill, float_param, int_param,
                                                 publish_status, qos_profile, run_node,
                                                 text_param)
from hasel_wheel_sim.model import SECTOR

from hasel_wheel_mpc.controller import MPC_PARAMS, REDECIDE_MIN_TIME, decide_at, decision_point
from hasel_wheel_mpc.mpc import Mpc, MpcConfig, gc_paused, next_pad
from hasel_wheel_mpc.node_model import declare_controller_model

D = math.radians
#: Parameters that are MpcConfig fields of the same name (changeable at run time).
CONFIG_PARAMS = MPC_PARAMS
#: (phi_a, phi_d) [rad] assumed for a latched command this node did not send (closed_loop's start).
DEFAULT_ANGLES = (D(3.0), D(22.0))
#: Until the first switch-on, an unconfirmed start command is sent again after this many samples.
START_PERIOD = 30
#: The start command aims at a pad whose switch-on is at least this far ahead [s] (latency).
START_LEAD = 0.1
#: The start pad comes from the encoder's last this many samples (angle, and speed as their
#: slope), not from the estimate: the observer is still converging then [samples].
START_SAMPLES = 30


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
        self.idle_samples = self.declare_parameter(
            "idle_samples", 150,
            int_param("decide on an idle wheel after this many samples with HV off [samples]",
                      10, 3000)).value
        self.redecide_time = self.declare_parameter(
            "redecide_min_time", REDECIDE_MIN_TIME,
            float_param("decide at once on a new reference only if the next switching (off, "
                        "or on between pads) is at least this far away [s]", 0.0, 0.2)).value
        period = self.declare_parameter(
            "diagnostics_period", 1.0, float_param("period of /diagnostics [s]", 0.1, 60.0,
                                                   True)).value
        config = dataclasses.replace(cfg, **{k: self.get_parameter(k).value for k in CONFIG_PARAMS})
        self.mpc = Mpc(params, ext, config=config)      # loads the compiled predictor

        # loop state, as in closed_loop.run_closed_loop
        self.angles: OrderedDict[int, tuple[float, float]] = OrderedDict()
        self.latched_seq = -1
        self.edges = samples.PadEdges()
        self.idle = 0
        self.last_ref = self.reference
        self.new_ref = False
        self.started = False
        self.start_pad, self.start_idle = -1, 0
        self.encoder: deque[tuple[float, float]] = deque(maxlen=START_SAMPLES)   # (t s, angle rad)
        # diagnostics
        self.estimates = 0
        self.window_estimates = 0
        self.window_t0 = time.monotonic()
        self.compute: list[float] = []
        self.slack_min = math.inf
        self.braking = 0
        self.late = 0           # decided in time by Mpc, but late once the node's overhead counts
        self.refs_rejected = 0
        self.starts = 0
        self.last_status: MpcStatus | None = None
        self.last_age = math.nan

        pubs = create_publishers(self, (topics.COMMAND, topics.MPC_STATUS, topics.DIAGNOSTICS,
                                        topics.REFERENCE))
        self.pub_cmd, self.pub_status, self.pub_diag, self.pub_ref = pubs.values()
        self.published_ref = math.nan
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
        self.create_timer(period, self._on_diagnostics)
        self.get_logger().info(
            f"ready: MPC, reference {self.reference:g} rad/s, {len(self.mpc.cands)} coarse "
            f"candidates, brake threshold {config.brake_threshold:g} rad/s; "
            + model_text)

    # -- parameters ---------------------------------------------------------------------------
    def _on_set_parameters(self, params) -> SetParametersResult:
        changes = {p.name: p.value for p in params if p.name in CONFIG_PARAMS}
        for p in params:
            if p.name == "reference_speed" and not math.isfinite(p.value):
                return SetParametersResult(successful=False,
                                           reason="reference_speed must be a finite speed [rad/s]")
            if p.name == "time_weighted" and not isinstance(p.value, bool):
                return SetParametersResult(successful=False,
                                           reason="time_weighted must be true or false")
        try:
            dataclasses.replace(self.mpc.config, **changes)
        except ValueError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _after_set_parameters(self, params) -> None:
        changes = {p.name: p.value for p in params if p.name in CONFIG_PARAMS}
        if changes:
            self.mpc.config = dataclasses.replace(self.mpc.config, **changes)
        for p in params:
            if p.name == "reference_speed":
                self.reference = float(p.value)
                if self.reference != self.published_ref:
                    self.get_logger().info(f"reference {self.reference:g} rad/s")
                self._publish_reference()
            elif p.name == "idle_samples":
                self.idle_samples = int(p.value)
            elif p.name == "redecide_min_time":
                self.redecide_time = float(p.value)

    def _publish_reference(self) -> None:
        """Publish the reference in use on ``reference_speed`` (latched) when it changed, so a
        bag holds every reference the loop ran with, set by topic or by ``param set``, even
        when a ``ros2 topic pub --once`` ended before the recorder subscribed.  This node's own
        message comes back to it and changes nothing."""
        if self.reference != self.published_ref:
            self.published_ref = self.reference
            self.pub_ref.publish(Float64(data=self.reference))

    def _on_reference(self, msg: Float64) -> None:
        result = self.set_parameters([Parameter("reference_speed", Parameter.Type.DOUBLE,
                                                float(msg.data))])[0]
        if not result.successful:
            self.refs_rejected += 1
            self.get_logger().warn(f"reference {msg.data!r} on {topics.REFERENCE.name} "
                                   f"rejected: {result.reason}")

    # -- the loop -----------------------------------------------------------------------------
    def _on_telemetry(self, msg: WheelTelemetry) -> None:
        self.latched_seq = int(msg.last_command_sequence)
        if not self.started:
            self.encoder.append((msg.device_time_us * 1e-6, msg.angle))

    @gc_paused          # a garbage collection must not delay a decision or its command
    def _on_estimate(self, e: HybridStateEstimate) -> None:
        t_in = time.perf_counter()
        self.estimates += 1
        self.window_estimates += 1
        speed = e.xi2
        self.idle = 0 if e.q else self.idle + 1
        switched_on, _ = self.edges.step(e.q, e.eta_unwrapped)
        ref = self.reference
        # a new reference counts until the next decision (controller.decision_point)
        self.new_ref = self.new_ref or ref != self.last_ref
        self.last_ref = ref
        if not self.started:
            if not e.q:
                self._start(e)
                return
            self.started = True
        why = decision_point(self.new_ref, e.q, switched_on, self.idle, self.idle_samples,
                             e.activation_counter, e.deactivation_counter, speed,
                             self.redecide_time)
        if why is None:
            return
        self.new_ref = False
        pa_now, pd_now = self.angles.get(self.latched_seq, DEFAULT_ANGLES)
        dec = decide_at(self.mpc, why, e.xi1, speed, e.eta_unwrapped, pa_now, pd_now, ref,
                        e.disturbance, samples.accel_coefficients_of(e)
                        or (e.accel_disturbance, 0.0, 0.0), e.activation_counter)
        if dec is None:
            return
        cmd = dec.command
        t = self.get_clock().now().nanoseconds * 1e-9
        self.pub_cmd.publish(fill(ActuationCommand(), samples.command_msg(cmd, t)))
        self.angles[cmd.sequence] = (cmd.phi_a, cmd.phi_d)
        while len(self.angles) > 64:
            self.angles.popitem(last=False)
        self.idle = 0
        overhead = time.perf_counter() - t_in - dec.compute_time
        slack = dec.deadline_slack - overhead
        if slack < 0.0 and not dec.deadline_missed and not dec.braking:
            self.late += 1
        status = fill(MpcStatus(), samples.mpc_status_msg(
            t, cmd, ref, dec.predicted_speed, dec.cost, dec.compute_time, slack, dec.candidates,
            dec.deadline_missed, dec.braking))
        self.pub_status.publish(status)
        self.last_status = status
        self.last_age = t - (e.header.stamp.sec + e.header.stamp.nanosec * 1e-9)
        self.braking += dec.braking
        if not dec.braking:
            self.compute.append(dec.compute_time)
            self.slack_min = min(self.slack_min, slack)

    def _start(self, e: HybridStateEstimate) -> None:
        """Start the wheel as closed_loop does: the next pad at the default angles, sequence 0.

        Until the first switch-on, on every estimate: unless the device has a pad latched
        that switches on within the next two sectors, send one (again): the command may have
        been lost while discovery was under way, or have arrived so late that its pad had
        passed and the device unwrapped it a turn ahead.  At once when the wanted pad changed,
        otherwise after START_PERIOD samples.  A wheel left to coast stops short of its next
        pad within about 2 s, and no pad starts it again.
        """
        if 0.0 < e.activation_counter <= 2.0 * SECTOR or self.pub_cmd.get_subscription_count() == 0:
            return
        (t0, a0), (t1, a1) = ((self.encoder[0], self.encoder[-1]) if len(self.encoder) > 1 else
                              ((0.0, e.xi1), (0.0, e.xi1)))
        speed = (a1 - a0) / (t1 - t0) if t1 - t0 >= 0.02 else max(e.xi2, 0.0)
        lead = self.mpc.config.deadline_margin + START_LEAD
        want = next_pad(a1, speed, DEFAULT_ANGLES[0], lead)
        if want == self.start_pad and self.idle - self.start_idle < START_PERIOD:
            return                                          # in flight
        self.start_pad, self.start_idle = want, self.idle
        cmd = samples.Command(want, *DEFAULT_ANGLES, 0)
        self.angles[0] = DEFAULT_ANGLES
        self.pub_cmd.publish(fill(ActuationCommand(), samples.command_msg(
            cmd, self.get_clock().now().nanoseconds * 1e-9)))
        self.starts += 1
        if self.starts == 1:
            self.get_logger().info(f"start: actuator {cmd.n_a} at the default angles")

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
            "start_commands": str(self.starts), "started": str(self.started)}
        self.slack_min = math.inf
        if rate < 1.0:
            level, text = DiagnosticStatus.STALE[0], "no state estimate"
        elif self.mpc.deadline_misses or self.late:
            level, text = DiagnosticStatus.WARN[0], "deadline misses (fallback input sent)"
        else:
            level, text = DiagnosticStatus.OK[0], "deciding"
        publish_status(self, self.pub_diag, "mpc", "hasel_wheel_mpc", level,
                       text, values)


def main(args=None):
    run_node(MpcNode, "mpc_node", args)


if __name__ == '__main__':
    main()
