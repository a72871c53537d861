"""Which pads still push: each pad's push measured from its own switch-on cycles.

A HASEL pad whose dielectric has broken down still takes HV but no longer pushes.  Over one
driving cycle of pad i (its switch-on to the next pad's, duration dt [s]; no other pad pushes
in it) the wheel's speed changes by dv [rad/s]; a coasting wheel would have changed by a0 dt,
a0 [rad/s^2] the model's acceleration with no pad on (friction, drag).  The pad's push is

    p_i = dv - a0 dt   [rad/s],

smoothed per pad over its cycles (exponential, weight :data:`SMOOTHING`).  Its gain is p_i
over the median push of the pads measured, and a pad is dead when its last
:data:`DEAD_CYCLES` cycles each gave less than :data:`DEAD_GAIN` of that median; its
measured gain is then their mean over the median.  Braking
cycles (phi_a < 0) and cycles while the pads push too little to tell (median below
:data:`MIN_PUSH`) are not counted.  Tests: ``test_pad_health.py``.
"""
from __future__ import annotations

from collections import deque
from typing import NamedTuple

import numpy as np

from hasel_wheel_sim.model import N_ACTUATORS

#: Weight of a new cycle in a pad's smoothed push [1].
SMOOTHING = 0.3
#: A cycle pushing less than this fraction of the median push is a failed push [1].
DEAD_GAIN = 0.3
#: Failed pushes in a row that make a pad dead [count] (each pad pushes once per turn).
DEAD_CYCLES = 3
#: Below this median push [rad/s] nothing is judged: the pads' pushes cannot be told from noise.
MIN_PUSH = 0.02


class PadVerdict(NamedTuple):
    """A pad found dead: its index, its measured gain [1] and the time [s] of the finding."""

    pad: int
    gain: float
    t: float


class PadHealth:
    """Per-pad pushes and the dead pads found from them (see the module docstring)."""

    def __init__(self) -> None:
        self.push = np.full(N_ACTUATORS, np.nan)      # smoothed push per pad [rad/s]
        self._recent = [deque(maxlen=DEAD_CYCLES) for _ in range(N_ACTUATORS)]
        self.dead: dict[int, PadVerdict] = {}
        self.cycles = 0

    def median(self) -> float:
        """Median smoothed push [rad/s] of the pads measured so far (nan before any)."""
        seen = self.push[np.isfinite(self.push)]
        return float(np.median(seen)) if len(seen) else float("nan")

    def gains(self) -> np.ndarray:
        """Measured gain per pad [1]: its smoothed push over the median (nan: not measured)."""
        m = self.median()
        return self.push / m if m > MIN_PUSH else np.full(N_ACTUATORS, np.nan)

    def cycle(self, pad: int, t: float, dt: float, dv: float, coast_accel: float) -> PadVerdict | None:
        """One driving cycle of ``pad`` (0..15) that ended at ``t`` [s]: it lasted ``dt`` [s]
        and changed the speed by ``dv`` [rad/s]; ``coast_accel`` [rad/s^2] is the model's
        acceleration with no pad on.  Returns the verdict when this cycle makes it dead."""
        push = dv - coast_accel * dt
        old = self.push[pad]
        self.push[pad] = push if np.isnan(old) else old + SMOOTHING * (push - old)
        self.cycles += 1
        m = self.median()
        if not m > MIN_PUSH:
            return None
        recent = self._recent[pad]
        recent.append(push)
        if pad in self.dead or len(recent) < DEAD_CYCLES or max(recent) >= DEAD_GAIN * m:
            return None
        verdict = PadVerdict(pad, float(max(np.mean(recent) / m, 0.0)), t)
        self.dead[pad] = verdict
        return verdict
