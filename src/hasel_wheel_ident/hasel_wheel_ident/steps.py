"""A pad whose force changed between two trials of a session (:func:`gain_step`).

HASEL pads break down: a dielectric breakdown drops one pad's force to a fraction between
one trial and the next.  One gain spread fitted over the whole session then puts that pad
between its before and its after, which is neither wheel.  The gain spread refitted trial
by trial (:class:`~.consistency.Consistency`, trials in session order) shows it: each
pad's log-gain relative to the median pad, per trial, is split at every boundary between
two trials, and the split with the largest change (weighted means before and after, the
standard error widened by the scatter about them) is the step.  It is reported when its
two-sided p, times the number of splits tried (16 pads x (m - 1) boundaries), is below
:data:`STEP_P` and the gain changes by at least :data:`MIN_STEP`.  The identified model
then takes the pad's gain after the step (:func:`latest_gains`): that is the wheel the
controller will drive.  Tested in ``test_ident_session.py``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

from hasel_wheel_sim.model import N_ACTUATORS

from hasel_wheel_ident.consistency import Consistency

#: A step this unlikely by chance (two-sided, after the multiple-split correction) is named.
STEP_P = 1e-6
#: ... and only when the gain changes by this factor or more (either way).
MIN_STEP = 1.25


@dataclass(frozen=True)
class GainStep:
    """Pad ``pad`` (0..15) changed its gain between trial ``index`` - 1 and trial ``index``
    (``trial`` names the first trial after it): ``before`` and ``after`` its gain relative
    to the median pad [1] with their 95 % intervals, ``p`` after the correction."""

    pad: int
    index: int
    trial: str
    previous: str
    before: float
    after: float
    before_ci95: tuple[float, float]
    after_ci95: tuple[float, float]
    p: float

    def text(self) -> str:
        what = "fell" if self.after < self.before else "rose"
        return (f"pad {self.pad}'s force {what} between {self.previous} and {self.trial}: "
                f"gain {self.before:.3g} (95 % {self.before_ci95[0]:.3g} to "
                f"{self.before_ci95[1]:.3g}) before, {self.after:.3g} (95 % "
                f"{self.after_ci95[0]:.3g} to {self.after_ci95[1]:.3g}) after, relative to the "
                f"median pad, p = {self.p:.1e}; a dielectric breakdown does this, and the "
                f"identified model takes the gain after it")


def relative_log_gains(con: Consistency) -> tuple[np.ndarray, np.ndarray]:
    """(m, 16) each trial's log-gains relative to its median pad, and (m, 16) their standard
    deviations, from a gain spread refitted trial by trial (d1..d15; d0 = -sum, its sd the
    median of the others')."""
    d = np.column_stack([-con.estimates.sum(axis=1), con.estimates])
    sd = np.column_stack([np.median(con.sd, axis=1), con.sd])
    return d - np.median(d, axis=1, keepdims=True), sd


def gain_step(con: Consistency | None) -> GainStep | None:
    """The largest step of one pad's gain between two trials of ``con`` (a ``gain_spread``
    refitted trial by trial, trials in session order), or None when there is none by the
    rules of the module docstring (or fewer than three trials)."""
    if con is None or con.effect != "gain_spread" or con.unit != "trial":
        return None
    m = con.estimates.shape[0]
    if m < 3:
        return None
    rel, sd = relative_log_gains(con)
    w = 1.0 / np.maximum(sd, 1e-9) ** 2
    best: tuple[float, int, int, tuple] | None = None
    for pad in range(N_ACTUATORS):
        for s in range(1, m):
            est = _split(rel[:, pad], w[:, pad], s)
            if best is None or est[0] > best[0]:
                best = (est[0], pad, s, est[1:])
    z, pad, s, (mb, sb, ma, sa) = best
    p = min(float(2 * stats.norm.sf(z)) * N_ACTUATORS * (m - 1), 1.0)
    if not (p < STEP_P and abs(ma - mb) >= math.log(MIN_STEP)):
        return None
    ci = lambda mu, se: (math.exp(mu - 1.96 * se), math.exp(mu + 1.96 * se))  # noqa: E731
    return GainStep(pad, s, con.trials[s], con.trials[s - 1], math.exp(mb), math.exp(ma),
                    ci(mb, sb), ci(ma, sa), p)


def _split(x: np.ndarray, w: np.ndarray, s: int) -> tuple[float, float, float, float, float]:
    """(|z|, mean before, its se, mean after, its se) of ``x`` (m,) with weights ``w`` split
    before index ``s``; the standard errors widened by the scatter about the two means when
    it exceeds what the weights expect."""
    wb, wa = w[:s].sum(), w[s:].sum()
    mb, ma = float(w[:s] @ x[:s] / wb), float(w[s:] @ x[s:] / wa)
    r = np.concatenate([x[:s] - mb, x[s:] - ma])
    dof = x.size - 2
    scale = max(float(w @ (r * r)) / dof, 1.0) if dof > 0 else 1.0
    sb, sa = math.sqrt(scale / wb), math.sqrt(scale / wa)
    return abs(ma - mb) / math.hypot(sb, sa), mb, sb, ma, sa


def latest_gains(gains: np.ndarray, step: GainStep) -> np.ndarray:
    """(16,) the model's pad gains ``gains`` [1] with pad ``step.pad`` at its gain after the
    step: ``step.after`` times the median of the gains."""
    out = np.array(gains, dtype=float)
    out[step.pad] = step.after * float(np.median(out))
    return out
