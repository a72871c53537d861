"""An open-loop characterisation schedule run from the host: (phi_a, phi_d) steps in turn.

The trial node (and anything else that has the wheel's telemetry) drives the wheel through a
list of steps like Table II's, each held for a fixed time of device clock.  Within a step,
:class:`~hasel_wheel_bringup.sequencer.Sequencer` commands the pad after the one that switched on,
at the step's angles; the first ``priming`` commands of the run use ``priming_phi_a`` instead
(the paper primes with six activations at 3 deg).  For every step it measures the steady
speed from the encoder: the slope of the unwrapped angle over the step's last
``steady_window`` seconds.  After the last step it sends nothing more, so the wheel finishes
its current cycle and coasts (``test_trial_schedule.py::
test_steps_run_back_to_back_from_the_first_sample_with_hv_on``,
``test_priming_commands_use_the_priming_angle_then_the_step_angle``,
``test_steady_speed_is_the_true_mean_speed_over_the_window``).

``step(sample) -> Command | None`` is the whole contract, as for the Sequencer.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

from hasel_wheel_common.samples import Command, TelemetrySample

from hasel_wheel_bringup.sequencer import Sequencer
from hasel_wheel_bringup.trials import STEADY_WINDOW, TrialSpec


@dataclass(frozen=True)
class StepResult:
    """One finished step (angles rad, times s of device clock, speed rad/s)."""

    index: int
    phi_a: float
    phi_d: float
    t_start: float
    t_end: float
    steady_speed: float     # encoder angle slope over [t_end - window, t_end] [rad/s]
    window: float           # length of that window [s]
    commands: int           # commands sent during the step [1]

    def line(self) -> str:
        """One human-readable line (angles in degrees, as Table II lists them)."""
        return (f"step {self.index + 1}: phi_a {math.degrees(self.phi_a):5.2f} deg, "
                f"phi_d {math.degrees(self.phi_d):5.2f} deg, {self.t_end - self.t_start:.1f} s, "
                f"{self.commands} commands: steady speed {self.steady_speed:.4f} rad/s "
                f"(encoder slope over the last {self.window:g} s)")


class TrialSchedule:
    """Run ``steps`` one after the other on a wheel, from its first sample with HV on.

    ``steps`` are :class:`~hasel_wheel_bringup.trials.TrialSpec` (their ``phi_a``, ``phi_d``,
    ``duration``, ``priming`` and ``priming_phi_a`` are used; ``initial_speed`` and ``rule``
    belong to the plant and the firmware, not to a host schedule).  ``steady_window`` [s] is
    cut to half a step when a step is shorter than twice it.
    """

    def __init__(self, steps: Sequence[TrialSpec], steady_window: float = STEADY_WINDOW) -> None:
        if not steps:
            raise ValueError("a trial schedule needs at least one (phi_a, phi_d) step")
        if not steady_window > 0.0:
            raise ValueError(f"steady_window = {steady_window!r} s: expected a positive time")
        self.steps = list(steps)
        self.steady_window = steady_window
        first = self.steps[0]
        self.priming_left = first.priming
        self.seq = Sequencer(first.priming_phi_a if first.priming else first.phi_a, first.phi_d)
        self.results: list[StepResult] = []
        self.index = -1              # -1 until the first sample with HV on
        self.t_start = math.nan      # start of the current step [s]
        self._window_start: tuple[float, float] | None = None   # (t, angle) [s, rad]
        self._commands = 0

    @property
    def done(self) -> bool:
        """True once the last step has ended."""
        return self.index >= len(self.steps)

    @property
    def current(self) -> TrialSpec | None:
        """The step running now (None before the start and after the end)."""
        return self.steps[self.index] if 0 <= self.index < len(self.steps) else None

    def window(self, spec: TrialSpec) -> float:
        """The steady-speed window of a step [s]."""
        return min(self.steady_window, 0.5 * spec.duration)

    def step(self, s: TelemetrySample) -> Command | None:
        """The command to send after sample ``s`` (t [s] device clock), or None."""
        if self.done:
            return None
        if self.index < 0:
            if s.hv_monitor <= 0.0:
                return None
            self._begin(0, s.t)
        spec = self.steps[self.index]
        while s.t >= self.t_start + spec.duration:       # (a gap in telemetry can span a step)
            self._finish(spec, s)
            if self.done:
                return None
            spec = self.steps[self.index]
        if self._window_start is None and s.t >= self.t_start + spec.duration - self.window(spec):
            self._window_start = (s.t, s.angle)
        cmd = self.seq.step(s)
        if cmd is not None:
            self._commands += 1
            if self.priming_left:
                self.priming_left -= 1
                if not self.priming_left:
                    self.seq.phi_a = spec.phi_a
        return cmd

    def _begin(self, index: int, t: float) -> None:
        self.index = index
        self.t_start = t
        self._window_start = None
        self._commands = 0
        if index < len(self.steps):
            spec = self.steps[index]
            self.seq.phi_d = spec.phi_d
            if not self.priming_left:
                self.seq.phi_a = spec.phi_a

    def _finish(self, spec: TrialSpec, s: TelemetrySample) -> None:
        """Close the current step at its nominal end, with ``s`` the first sample after it."""
        t_end = self.t_start + spec.duration
        if self._window_start is None:                  # no sample inside the window
            speed, window = math.nan, 0.0
        else:
            t0, a0 = self._window_start
            window = s.t - t0
            speed = (s.angle - a0) / window if window > 0.0 else math.nan
        self.results.append(StepResult(self.index, spec.phi_a, spec.phi_d, self.t_start, t_end,
                                       speed, round(window, 6), self._commands))
        self._begin(self.index + 1, t_end)
