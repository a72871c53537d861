"""Host-side open-loop controller: at every switch-on, command the next pad.

The same decision point the MPC uses (paper Sec. V-B): when the device reports q 0 -> 1, the
host decides u for the next cycle, and the device latches it when the current actuator
switches off.  ``step(sample) -> Command | None`` is the whole contract.
"""
from __future__ import annotations

import math

from hasel_wheel_common.samples import Command, PadEdges, TelemetrySample
from hasel_wheel_sim.model import SECTOR


class Sequencer:
    """u = ((eta + 1) mod 16, phi_a, phi_d) at every switch-on; restarts an idle wheel after
    ``restart_after`` samples without HV, from the sector the encoder measures
    (``test_sequencer.py::test_commands_next_pad_at_switch_on_only``,
    ``test_no_commands_while_hv_is_off_and_restart_when_idle``,
    ``test_restart_counts_from_the_measured_sector_not_a_stale_target``)."""

    def __init__(self, phi_a: float, phi_d: float, restart_after: int = 150) -> None:
        self.phi_a = phi_a
        self.phi_d = phi_d
        self.restart_after = restart_after   # samples without HV before re-sending [1]
        self._edges = PadEdges()
        self._idle = 0
        self.seq = 0

    def step(self, s: TelemetrySample) -> Command | None:
        """The command to send after sample ``s``, or None."""
        due, _ = self._edges.step(s.q, s.eta_unwrapped)
        self._idle = 0 if s.q else self._idle + 1
        if s.hv_monitor > 0 and (due or self._idle >= self.restart_after or self.seq == 0):
            self._idle = 0
            self.seq += 1
            # at a switch-on: the pad after the one that switched on; when starting or
            # restarting: the pad after the sector the encoder measures now (eq. (40))
            base = s.eta_unwrapped if due else math.floor(s.angle / SECTOR)
            return Command((base + 1) % 16, self.phi_a, self.phi_d, self.seq)
        return None
