"""The sim node's core, without ROS: a plant paced against a wall clock.

The node calls :meth:`SimRuntime.run_until` from a timer with the monotonic wall time; the
runtime advances as many 300 Hz ticks as the time scale asks for and returns the samples to
publish.  Commands are validated here; a rejected command is counted, reported and never
reaches the wheel (so no HV is switched for it).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from hasel_wheel_common import protocol as P
from hasel_wheel_common.samples import Command, TelemetrySample

from hasel_wheel_sim.params import WheelParams
from hasel_wheel_sim.plant import Plant, PlantConfig
from hasel_wheel_sim.wheel import TICK, CommandError, HybridState, validate_command

#: At most this much wall time is caught up in one call [s] (15 ticks at time scale 1).  A
#: sim further behind its wall clock drops the rest of its backlog and goes on from there: a
#: real wheel cannot run ahead to catch up, and a burst would outrun the commands the
#: controller sends in reply (each drop is counted in ``overruns``).  Test:
#: ``test_sim_runtime.py::test_falling_behind_drops_the_backlog_and_is_counted``.
MAX_LAG = 0.05
MAX_TICKS_PER_CALL = round(MAX_LAG / TICK)     # at time scale 1 [ticks]


@dataclass(frozen=True)
class Output:
    """What one tick gives the node: the host-side sample (None if lost) and the truth."""

    t: float
    sample: TelemetrySample | None
    truth: HybridState


class SimRuntime:
    """A :class:`Plant` paced at ``time_scale`` simulated seconds per wall second."""

    def __init__(self, params: WheelParams | None = None, config: PlantConfig | None = None,
                 initial_speed: float = 1.0, time_scale: float = 1.0) -> None:
        self.plant = Plant(params, config, xi1=0.0, xi2=initial_speed)
        self.set_time_scale(time_scale)
        self._wall0: float | None = None
        self._sim0 = 0.0
        self._pending: Command | None = None
        self.commands_received = 0
        self.commands_rejected = 0
        self.samples_lost = 0
        self.overruns = 0
        self.last_rejection = ""
        self.last_rejection_code = 0     # protocol reject reason of the last refused command
        self.hv_enabled = True           # False after an HV-off request: commands are refused

    def set_time_scale(self, scale: float) -> None:
        """Simulated seconds per wall second, in (0, 100]."""
        if not (isinstance(scale, (int, float)) and math.isfinite(scale) and 0.0 < scale <= 100.0):
            raise ValueError(f"time_scale = {scale!r}: expected a number in (0, 100]")
        self.time_scale = float(scale)
        self._wall0 = None  # re-anchor the pacing at the next call

    def set_hv(self, enabled: bool) -> None:
        """HV on or off, as the device's HV frame: off switches every pad off at once, forgets
        the pending and latched command and refuses commands (reason HV disabled) until HV is
        on again (``test_sim_runtime.py::test_hv_off_cuts_the_pad_and_refuses_commands``)."""
        self.hv_enabled = bool(enabled)
        if not self.hv_enabled:
            self._pending = None
            self.plant.wheel.cut_hv()

    def submit(self, command: Command) -> str | None:
        """Queue a command for the next tick; return the rejection reason, or None if accepted."""
        self.commands_received += 1
        if not self.hv_enabled:
            self.commands_rejected += 1
            self.last_rejection = "HV is off (hv_request false)"
            self.last_rejection_code = P.R_HV_DISABLED
            return self.last_rejection
        try:
            validate_command(command.n_a, command.phi_a, command.phi_d)
        except CommandError as exc:
            self.commands_rejected += 1
            self.last_rejection = str(exc)
            self.last_rejection_code = exc.code
            return self.last_rejection
        self._pending = command
        return None

    def step(self) -> Output:
        """Advance exactly one tick, sending the queued command (if any)."""
        cmd, self._pending = self._pending, None
        sample = self.plant.step(cmd)
        if sample is None:
            self.samples_lost += 1
        return Output(self.plant.t, sample, self.plant.wheel.state)

    def run_until(self, wall_now: float) -> list[Output]:
        """Advance to where the wall clock (monotonic seconds) says the simulation should be."""
        if self._wall0 is None:
            self._wall0, self._sim0 = wall_now, self.plant.t
        target = self._sim0 + (wall_now - self._wall0) * self.time_scale
        due = int(math.floor((target - self.plant.t) / TICK + 1e-9))
        cap = max(1, round(MAX_LAG * self.time_scale / TICK))
        if due > cap:
            self.overruns += 1
            out = [self.step() for _ in range(cap)]
            self._wall0, self._sim0 = wall_now, self.plant.t
            return out
        return [self.step() for _ in range(max(due, 0))]

    def diagnostics(self) -> dict[str, str]:
        """Key/value health report for /diagnostics."""
        s = self.plant.wheel.state
        return {"sim_time_s": f"{self.plant.t:.3f}", "time_scale": f"{self.time_scale:g}",
                "speed_rad_s": f"{s.xi2:.4f}", "hv_on": str(bool(s.q)),
                "hv_enabled": str(self.hv_enabled),
                "actuator": str(s.actuator), "commands_received": str(self.commands_received),
                "commands_rejected": str(self.commands_rejected),
                "last_rejection": self.last_rejection, "samples_lost": str(self.samples_lost),
                "overruns": str(self.overruns)}
