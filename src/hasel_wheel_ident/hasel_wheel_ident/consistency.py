"""An effect refitted unit by unit (:class:`Consistency`, made by
:func:`~.trial_refit.trial_consistency`) and the rules on it.

* Its size m_j (the parameters projected on their mean direction, in units of their typical
  magnitude) regressed on ln v_j, v_j the unit's mean speed while driven [rad/s]: size ~ v^k
  (:func:`~.size_trends.speed_trend`).  It is *inconsistent* (:func:`inconsistent`, refused
  as a stand-in) when the slope's two-sided p < :data:`TREND_P` and |k| > :data:`EXPONENT`;
  short of that with p < :data:`LEAN_P` it *leans* (:func:`leans`, a caution).
* Refitted on the halves of each drive, size ~ hv^h with hv the accumulated HV time [s]
  (:func:`~.size_trends.hv_drift`); it *drifts* (:func:`drifts`, a caution) when
  p < :data:`TREND_P` and |h| > :data:`DRIFT`.
* It is tested beside a force that builds up after each switch-on when it grows with the
  speed (:func:`grows_with_speed`).

The evidence behind each threshold is in docs/identification.md.  Tested in
``test_ident_consistency.py``
(``test_an_effect_is_inconsistent_only_if_its_trend_is_both_significant_and_steep``,
``test_a_drift_within_the_trials_is_a_caution_not_a_refusal``,
``test_a_lean_on_the_speed_short_of_refusal_is_a_caution``,
``test_only_a_size_that_grows_with_the_speed_is_tested_beside_the_switch_on_lag``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from hasel_wheel_ident.candidates import Candidate

if TYPE_CHECKING:
    from hasel_wheel_ident.measuring_devices import Beside

#: A trend of an effect's size with the units' speed this unlikely by chance (two-sided) ...
TREND_P = 1e-3
#: ... and steeper than size ~ speed^EXPONENT makes it inconsistent (:func:`inconsistent`).
EXPONENT = 0.5
#: A change within the trials this unlikely by chance (p < TREND_P, two-sided), and steeper
#: than size ~ hv^DRIFT, is reported as a caution (:func:`drifts`).
DRIFT = 0.05
#: A trend with the units' speed this unlikely by chance (two-sided), steeper than
#: speed^(+-EXPONENT) but short of TREND_P, is reported as a caution (:func:`leans`), not
#: refused.
LEAN_P = 1e-2
#: An effect whose size grows with the units' speed (k > :data:`EXPONENT`) with a trend
#: this unlikely by chance (two-sided) or less is refitted beside
#: :data:`~.measuring_devices.ON_LAG` (:func:`~.stand_ins.lag_stand_in`).
SEEK_P = 0.1


@dataclass
class Consistency:
    """An effect refitted trial by trial.

    ``effect`` its id; ``names`` (k,) the parameters refitted; ``trials`` (m,) the trials'
    names; ``estimates`` (m, k) the parameters per trial and ``sd`` (m, k) their standard
    deviations, each in its own unit; ``pooled`` (k,) their inverse-covariance mean; ``chi2``
    on ``dof`` degrees of freedom about one value, and its ``p``; ``speeds`` (m,) [rad/s]
    each trial's mean measured speed while driven; ``exponent`` k (size ~ speed^k) with its
    standard deviation ``exponent_sd`` and the two-sided ``trend_p`` of the slope.

    Within each trial (:func:`~.size_trends.hv_drift`): ``halves`` (m, 2) the size (the
    projection on the pooled direction, in units of the parameters' typical magnitudes)
    refitted on the first and the second half of the trial's drive, ``halves_sd`` (m, 2)
    their standard deviations, ``hv`` (m, 2) [s] the mean accumulated HV on-time of the
    driven actuator in each half; ``drift`` h (size ~ hv^h within a trial) with ``drift_sd``
    and the two-sided ``drift_p`` of "no change"; None, 0, inf and 1 when it cannot be
    formed."""

    effect: str
    names: list[str]
    trials: list[str]
    estimates: np.ndarray
    sd: np.ndarray
    pooled: np.ndarray
    chi2: float
    dof: int
    p: float
    speeds: list[float]
    exponent: float
    exponent_sd: float
    trend_p: float
    #: "trial" when the units refitted one by one are the trials, "span" when they are spans
    #: of the trials' drives (:func:`~.drive_cuts.speed_spans`; ``trials`` then names the
    #: spans)
    unit: str = "trial"
    #: the trials' names, for the halves (``trials`` names the spans when ``unit`` is "span")
    halves_trials: list[str] = field(default_factory=list)
    halves: np.ndarray | None = None
    halves_sd: np.ndarray | None = None
    hv: np.ndarray | None = None
    drift: float = 0.0
    drift_sd: float = math.inf
    drift_p: float = 1.0
    #: refitted beside :data:`~.measuring_devices.HV_LOSS`
    #: (:func:`~.stand_ins.drift_stand_in`); None when not refitted
    beside: Beside | None = None
    #: refitted beside :data:`~.measuring_devices.ON_LAG` (:func:`~.stand_ins.lag_stand_in`);
    #: None when not refitted
    beside_lag: Beside | None = None

    def text(self, candidate: Candidate) -> str:
        """The per-trial values in words, slowest trial first."""
        rows = []
        for name, v, x in sorted(zip(self.trials, self.speeds, self.estimates),
                                 key=lambda r: r[1]):
            if len(self.names) == candidate.size:     # its physical size, e.g. a torque
                label, val = next((k, float(w)) for k, w in candidate.describe(x).items()
                                  if isinstance(w, float))
            else:
                label, val = self.names[0], float(x[0])
            rows.append(f"{label} {val:.4g} at {v:.2f} rad/s ({name})")
        return (", ".join(rows) + f": size ~ speed^k, k = {self.exponent:+.2f} +- "
                f"{self.exponent_sd:.2f} (p = {self.trend_p:.1e} for no trend); chi2 "
                f"{self.chi2:.1f} on {self.dof} dof about one value (p = {self.p:.1e})")

    def drift_text(self) -> str:
        """The change within the trials in words."""
        if self.halves is None:
            return "no change within the trials could be measured"
        rows = [f"{a:.3g} -> {b:.3g} ({name}, {h0:.2f} -> {h1:.2f} s of HV per actuator)"
                for name, (a, b), (h0, h1) in zip(self.halves_trials or self.trials,
                                                  self.halves, self.hv)
                if np.isfinite(a) and np.isfinite(b)]
        return ("its size from the first to the second half of each drive, relative to the "
                "typical magnitude: " + ", ".join(rows) + f": size ~ hv^h, h = "
                f"{self.drift:+.2f} +- {self.drift_sd:.2f} (p = {self.drift_p:.1e} for no "
                f"change)")


def drifts(c: Consistency | None) -> bool:
    """True when the effect's size changes within the trials as the actuators accumulate HV
    time: significantly (p < TREND_P) and steeper than hv^(+-DRIFT)."""
    return c is not None and c.drift_p < TREND_P and abs(c.drift) > DRIFT


def inconsistent(c: Consistency | None) -> bool:
    """True when the effect is not one value across the trials (or their spans, ``unit``
    "span"): its size trends with their speed, significantly (p < TREND_P) and steeper than
    speed^(+-EXPONENT).  A drift within the trials (:func:`drifts`) is reported, not
    refused."""
    return c is not None and c.trend_p < TREND_P and abs(c.exponent) > EXPONENT


def leans(c: Consistency | None) -> bool:
    """True when the effect's size trends with the trials' speed (p < LEAN_P, steeper than
    speed^(+-EXPONENT)) short of :func:`inconsistent`: evidence, not enough to refuse it."""
    return (c is not None and c.trend_p < LEAN_P and abs(c.exponent) > EXPONENT
            and not inconsistent(c))


def grows_with_speed(c: Consistency | None) -> bool:
    """True when the effect's size grows with the trials' speed, steeper than
    speed^EXPONENT with a trend p under :data:`SEEK_P`: reason enough to test it beside
    :data:`~.measuring_devices.ON_LAG` (:func:`~.stand_ins.lag_stand_in`), not to refuse
    it."""
    return c is not None and c.exponent > EXPONENT and c.trend_p < SEEK_P
