"""trial_node: an open-loop characterisation run (Table II style) as a ROS 2 node.

Drives the wheel through a schedule of (phi_a, phi_d) steps, each held for ``step_duration``
seconds of device clock, from the first telemetry sample with high voltage on
(:class:`hasel_wheel_bringup.trial_schedule.TrialSchedule` does the work).  Publishes ``command``
and ``/diagnostics``; logs each step's steady speed (encoder slope over its last
``steady_window`` seconds) as it ends, and a summary at the end.  Then it exits, so the launch
that started it (open_loop_trial.launch.py) stops the plant and the recording: the wheel
finishes its last cycle and coasts, and the driver switches high voltage off as it stops.

The schedule is fixed for a run: its parameters are read-only.
"""
from __future__ import annotations

import math
import time

from diagnostic_msgs.msg import DiagnosticStatus
from hasel_wheel_msgs.msg import ActuationCommand, WheelTelemetry
from rclpy.node import Node
from rclpy.task import Future

from hasel_wheel_common import samples
from hasel_wheel_common import topics
from hasel_wheel_common.nodes.ros_common import (create_publishers, fill, float_param, int_param,
                                                 publish_status, qos_profile, run_node,
                                                 text_param)

from hasel_wheel_bringup.trial_schedule import TrialSchedule
from hasel_wheel_bringup.trials import STEADY_WINDOW, trials_from_mapping

D = math.radians
#: Table II's activation angles [rad] and its deactivation angle.
TABLE_II_PHI_A = [D(a) for a in (1.0, 3.0, 5.0, 7.0, 9.0, 11.0)]
TABLE_II_PHI_D = [D(22.0)]


class TrialNode(Node):

    def __init__(self) -> None:
        super().__init__("trial_node")
        phi_a = self.declare_parameter(
            "phi_a", TABLE_II_PHI_A,
            text_param("activation angle of each step [rad], 0 <= phi_a < phi_d <= pi/8")).value
        phi_d = self.declare_parameter(
            "phi_d", TABLE_II_PHI_D,
            text_param("deactivation angle [rad]: one for every step, or one per phi_a")).value
        duration = self.declare_parameter(
            "step_duration", 60.0, float_param("how long each step is held [s]", 1.0, 3600.0,
                                               True)).value
        priming = self.declare_parameter(
            "priming_count", 0, int_param("the run's first commands use priming_phi_a "
                                          "(the paper primes with 6) [1]", 0, 100, True)).value
        priming_phi_a = self.declare_parameter(
            "priming_phi_a", D(3.0), float_param("activation angle of the priming commands "
                                                 "[rad]", 0.0, math.pi / 8, True)).value
        window = self.declare_parameter(
            "steady_window", STEADY_WINDOW,
            float_param("steady speed = encoder slope over each step's last this many seconds "
                        "(at most half a step) [s]", 0.1, 600.0, True)).value
        period = self.declare_parameter(
            "diagnostics_period", 1.0, float_param("period of /diagnostics [s]", 0.1, 60.0,
                                                   True)).value
        # the embedded runner's validation: phi_a < phi_d, ranges, one phi_d or one per phi_a
        steps = trials_from_mapping(
            {"phi_a": {"values": list(phi_a), "unit": "rad"},
             "phi_d": {"values": list(phi_d), "unit": "rad"},
             "duration": {"value": duration, "unit": "s"}, "priming_count": priming,
             "priming_phi_a": {"value": priming_phi_a, "unit": "rad"}}, where="trial_node")
        self.schedule = TrialSchedule(steps, window)
        #: Completes when the last step has ended; main() spins until then.
        self.finished = Future()
        self.samples = 0
        self.window_samples = 0
        self.window_t0 = time.monotonic()
        self.last_sample: samples.TelemetrySample | None = None

        pubs = create_publishers(self, (topics.COMMAND, topics.DIAGNOSTICS))
        self.pub_cmd, self.pub_diag = pubs.values()
        self.create_subscription(WheelTelemetry, topics.TELEMETRY.name, self._on_telemetry,
                                 qos_profile(topics.TELEMETRY.qos))
        self.create_timer(period, self._on_diagnostics)
        self.get_logger().info(
            f"ready: open-loop trial, {len(steps)} steps of {duration:g} s, phi_a "
            f"{', '.join(f'{math.degrees(s.phi_a):g}' for s in steps)} deg, phi_d "
            f"{', '.join(sorted({f'{math.degrees(s.phi_d):g}' for s in steps}))} deg, "
            f"{priming} priming commands; starts at the first sample with HV on")

    def _on_telemetry(self, msg: WheelTelemetry) -> None:
        if self.finished.done():
            return
        self.samples += 1
        self.window_samples += 1
        s = samples.telemetry_from_msg(msg)
        self.last_sample = s
        # until the plant's command subscription is matched, a command would be lost; a wheel
        # left without one coasts to a stop, and an open-loop trial does not start a stopped one
        if self.schedule.index < 0 and self.pub_cmd.get_subscription_count() == 0:
            return
        done_before = len(self.schedule.results)
        started = self.schedule.index >= 0
        cmd = self.schedule.step(s)
        if not started and self.schedule.index == 0:
            self.get_logger().info(f"step 1 starts at t = {s.t:.3f} s (device clock)")
        if cmd is not None:
            t = self.get_clock().now().nanoseconds * 1e-9
            self.pub_cmd.publish(fill(ActuationCommand(), samples.command_msg(cmd, t)))
        for r in self.schedule.results[done_before:]:
            self.get_logger().info(r.line())
        if self.schedule.done:
            self.get_logger().info(
                "trial finished; steady speeds [rad/s]: "
                + ", ".join(f"{math.degrees(r.phi_a):g}/{math.degrees(r.phi_d):g} deg "
                            f"{r.steady_speed:.4f}" for r in self.schedule.results))
            self._on_diagnostics()
            self.finished.set_result(self.schedule.results)

    def _on_diagnostics(self) -> None:
        now = time.monotonic()
        rate = self.window_samples / max(now - self.window_t0, 1e-9)
        self.window_samples, self.window_t0 = 0, now
        sch, s = self.schedule, self.last_sample
        spec = sch.current
        last = sch.results[-1] if sch.results else None
        values = {
            "step": f"{sch.index + 1}/{len(sch.steps)}" if spec else ("done" if sch.done else "-"),
            "phi_a_deg": f"{math.degrees(spec.phi_a):.2f}" if spec else "-",
            "phi_d_deg": f"{math.degrees(spec.phi_d):.2f}" if spec else "-",
            "time_in_step_s": f"{s.t - sch.t_start:.1f}" if spec and s else "-",
            "commands_sent": str(sch.seq.seq),
            "telemetry_rate_hz": f"{rate:.1f}", "telemetry_samples": str(self.samples),
            "hv_on": str(bool(s and s.hv_monitor > 0.0)),
            "last_step_steady_speed_rad_s": f"{last.steady_speed:.4f}" if last else "-"}
        if sch.done:
            level, text = DiagnosticStatus.OK[0], "trial finished"
        elif s is None or rate < 1.0:
            level, text = DiagnosticStatus.STALE[0], "no telemetry"
        elif sch.index < 0:
            level, text = DiagnosticStatus.WARN[0], "waiting for high voltage"
        else:
            level, text = DiagnosticStatus.OK[0], "running"
        publish_status(self, self.pub_diag, "open-loop trial", "hasel_wheel_bringup", level, text,
                       values)


def main(args=None):
    run_node(TrialNode, "trial_node", args)


if __name__ == '__main__':
    main()
