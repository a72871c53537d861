"""A change of the unmodelled acceleration from one trial to the next along the session
(:func:`session_drift`).

The drive trend (:func:`~.residual.drive_trend`) reads each trial apart, with an intercept
of its own, so a change between trials is invisible to it.  Here each trial's mean window
defect [rad/s^2] (:func:`~.residual.window_defects`) is regressed on the trial's place in
the session, along each axis of :data:`SESSION_AXES`: the session time at its middle [s],
and the HV on-time of all pads accumulated by then [s].  A weighted line (each mean's
standard error from its windows' scatter, widened by the scatter about the line) is
t-tested on m - 2 degrees of freedom; the axis with the smaller p is taken when p (times
the two axes) < :data:`~.residual.TREND_SIGNIFICANCE` and the line's change over the
session reaches :data:`~.residual.MIN_AMPLITUDE`.  Only trials that all carry a session
time, four or more, are read.  Tested in ``test_ident_session.py``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

from hasel_wheel_ident.data import Trial

#: The session axes, with their units and words.
SESSION_AXES = {"session_time": ("s", "session time"),
                "session_hv_time": ("s", "HV on-time accumulated over the session")}
#: Fewer trials than this are not read for a change along the session.
MIN_TRIALS = 4


@dataclass(frozen=True)
class SessionDrift:
    """The trials' mean unmodelled acceleration along ``axis`` (of :data:`SESSION_AXES`):
    ``slope`` [rad/s^2 per s] with ``slope_sd``, ``change`` [rad/s^2] of the line from the
    first trial to the last, ``p`` (adjusted for the two axes), ``p_values`` per axis
    (unadjusted)."""

    axis: str
    slope: float
    slope_sd: float
    change: float
    p: float
    p_values: dict[str, float]

    def text(self, inertia: float) -> str:
        """In words; ``inertia`` [kg*m^2] (J/L) turns accelerations into torques."""
        unit, words = SESSION_AXES[self.axis]
        what = "grows" if self.slope > 0 else "falls"
        others = ", ".join(f"{SESSION_AXES[k][1]} p = {v:.1e}" for k, v in self.p_values.items()
                           if k != self.axis)
        return (f"changes from trial to trial: the unmodelled acceleration {what} along "
                f"{words} by {abs(self.slope) * 600:.3g} rad/s^2 per 10 min "
                f"({abs(self.change):.3g} rad/s^2, {abs(self.change) * inertia:.2g} N*m, from "
                f"the first trial to the last), p = {self.p:.1e}"
                + (f"; against {others}" if others else ""))


def trial_positions(trials: list[Trial]) -> dict[str, np.ndarray] | None:
    """(m,) per trial: session time at its middle [s] and the HV on-time of all pads
    accumulated by then [s]; None unless every trial has a session time."""
    if any(tr.session_start is None for tr in trials):
        return None
    mid, hv = [], []
    for tr in trials:
        half = float(tr.t[0]) + 0.5 * tr.duration
        own = tr.switch_ons()
        before = float(np.sum(tr.prior[:, 1] - tr.prior[:, 0]))
        hv.append(before + float(np.sum(np.clip(np.minimum(own[:, 1], half) - own[:, 0], 0.0,
                                                None))))
        mid.append(tr.session_start + 0.5 * tr.duration)
    return {"session_time": np.array(mid), "session_hv_time": np.array(hv)}


def session_drift(trials: list[Trial], acc: np.ndarray, trial_of: np.ndarray,
                  significance: float, min_amplitude: float) -> SessionDrift | None:
    """The change along the session of the window defects ``acc`` (k,) [rad/s^2] of the
    trials ``trial_of`` (k,) (indices into ``trials``), or None (module docstring)."""
    pos = trial_positions(trials)
    m = len(trials)
    if pos is None or m < MIN_TRIALS:
        return None
    y, se = np.zeros(m), np.zeros(m)
    for j in range(m):
        a = acc[trial_of == j]
        if a.size < 3:
            return None
        y[j], se[j] = float(a.mean()), float(a.std(ddof=1)) / math.sqrt(a.size)
    w = 1.0 / np.maximum(se, 1e-12) ** 2
    fits = {}
    for axis, x in pos.items():
        X = np.column_stack([np.ones(m), x])
        A = X.T @ (w[:, None] * X)
        if np.linalg.cond(A) > 1e14:
            continue
        coef = np.linalg.solve(A, X.T @ (w * y))
        r = y - X @ coef
        scale = max(float(np.sum(w * r * r)) / (m - 2), 1.0)
        sd = math.sqrt(float(np.linalg.inv(A)[1, 1]) * scale)
        p = float(2 * stats.t.sf(abs(coef[1]) / sd, m - 2)) if sd > 0 else 1.0
        fits[axis] = (float(coef[1]), sd, float(coef[1] * np.ptp(x)), p)
    if not fits:
        return None
    best = min(fits, key=lambda k: fits[k][3])
    slope, sd, change, p = fits[best]
    p = min(p * len(SESSION_AXES), 1.0)
    if not (p < significance and abs(change) >= min_amplitude):
        return None
    return SessionDrift(best, slope, sd, change, p, {k: v[3] for k, v in fits.items()})
