"""The force multiplier of the active actuator at every sample of a multiple-shooting fit:
its pad's spread gain times the charge retention's factor exp(-rate x charge)
(:func:`~.simulate.retention_charge`, from the charge each trial starts with,
:func:`~.session.prior_charge`).  Tested in ``test_ident_fit.py``."""
from __future__ import annotations

import numpy as np

from hasel_wheel_sim import layout as L
from hasel_wheel_sim.model import N_ACTUATORS

from hasel_wheel_ident.data import Trial
from hasel_wheel_ident.session import prior_charge
from hasel_wheel_ident.shooting_layout import Layout
from hasel_wheel_ident.simulate import retention_charge

#: The most retained-charge columns kept, one per recovery time [s], before the cache is
#: emptied.
MAX_CHARGES = 64


class ForceGains:
    """The gains (n,) of the samples of ``lay`` for a model's parameter vector.  The last one
    is kept (most evaluations change no gain), and the retained charge per recovery time."""

    def __init__(self, lay: Layout, trials: list[Trial]) -> None:
        self.t, self.q, self.pad, self.trial_slices = lay.t, lay.q, lay.pad, lay.trial_slices
        self.trials = trials
        self._charges: dict[float, np.ndarray] = {}
        self._last: tuple[bytes, np.ndarray] | None = None

    def __call__(self, pv: np.ndarray) -> np.ndarray:
        """(n,) the gains of the parameter vector ``pv``, read-only."""
        key = pv[L.P_GAINS:L.P_GAINS + N_ACTUATORS].tobytes() + pv[
            [L.P_RET_RATE, L.P_RET_RECOVERY]].tobytes()
        last = self._last
        if last is not None and last[0] == key:
            return last[1]
        g = self.compute(pv)
        g.flags.writeable = False
        self._last = (key, g)
        return g

    def compute(self, pv: np.ndarray) -> np.ndarray:
        """(n,) the gains of ``pv``, a new array."""
        g = pv[L.P_GAINS + self.pad]
        rate = pv[L.P_RET_RATE]
        if rate > 0.0:
            g = g * np.exp(-rate * self.charge(float(pv[L.P_RET_RECOVERY])))
        return g

    def charge(self, recovery: float) -> np.ndarray:
        """(n,) the retained charge at every sample with a recovery of ``recovery`` [s]."""
        charge = self._charges.get(recovery)
        if charge is None:
            charge = np.concatenate([retention_charge(self.t[s], self.q[s].astype(np.int64),
                                                      self.pad[s], recovery,
                                                      prior_charge(tr, recovery))
                                     for s, tr in zip(self.trial_slices, self.trials)])
            if len(self._charges) > MAX_CHARGES:
                self._charges.clear()
            self._charges[recovery] = charge
        return charge
