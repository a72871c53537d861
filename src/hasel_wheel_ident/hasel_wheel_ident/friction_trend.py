"""Friction along the session: tau_f of each coast-down in session order, and a trend
test along session time (:func:`friction_trend`).

A bearing that warms up, or a lubricant that dries, changes the friction from one trial to
the next; one tau_f pooled over the session hides it.  Each coast-down's tau_f
(:func:`~.fit.coast_estimates`) is placed at the session time of its middle, and a
weighted line tau_f = tau_0 + s t is fitted (weights: each estimate's inverse variance,
widened by the scatter about the line beyond what the regressions expect, as the pooled
estimate is).  The trend is reported when the slope's two-sided p < :data:`TREND_P`, and
the fits then take each trial's friction from the line (:func:`along_the_trend`).
Tested in ``test_ident_session.py``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy import stats

from hasel_wheel_sim.params import WheelParams

from hasel_wheel_ident.data import Trial
from hasel_wheel_ident.fit import coast_estimates

#: A friction trend this unlikely by chance (two-sided) is reported.
TREND_P = 1e-3


@dataclass(frozen=True)
class CoastFriction:
    """One coast-down's tau_f [N*m] with its 95 % interval, in trial ``trial`` at session
    time ``session_t`` [s] (its middle; None when the session time is unknown)."""

    trial: str
    session_t: float | None
    tau_f: float
    ci95: tuple[float, float]


@dataclass(frozen=True)
class FrictionTrend:
    """tau_f = ``tau_start`` + ``slope`` t along session time t [s]: ``slope`` [N*m/s] with
    its standard deviation ``slope_sd`` and the two-sided ``p`` of "no trend"; ``rate`` =
    slope / tau_start [1/s], the relative change per second of session; ``span`` [s] from
    the first coast-down to the last."""

    tau_start: float
    slope: float
    slope_sd: float
    p: float
    rate: float
    span: float

    @property
    def significant(self) -> bool:
        return self.p < TREND_P

    def text(self) -> str:
        """The trend in words a researcher acts on."""
        what = "rises" if self.slope > 0 else "falls"
        per10 = 100.0 * self.rate * 600.0
        over = 100.0 * self.rate * self.span
        size = (f"tau_f {per10:+.1f} % per 10 min of session ({over:+.1f} % over the "
                f"{self.span / 60:.1f} min from the first coast-down to the last), "
                f"p = {self.p:.1e}")
        if not self.significant:
            return f"no friction trend along the session: {size}"
        text = f"friction {what} along the session: {size}"
        text += ("; a warming bearing or a drying lubricant would do this" if self.slope > 0
                 else "; a bearing running in or a lubricant spreading would do this")
        return text + ("; the fits take each trial's tau_f from this line, and the model the "
                       "latest trial's (the library has no effect for a drift)")


def along_the_trend(trials: list[Trial], trend: FrictionTrend) -> list[Trial]:
    """``trials`` (with session times) with the friction of ``trend`` at the middle of each,
    relative to that at the middle of the last (``Trial.friction_scale`` [1]): the fits then
    take tau_f of the latest trial, the wheel the controller will drive, and each trial's
    friction from the line."""
    def at(tr: Trial) -> float:
        return trend.tau_start + trend.slope * (tr.session_start + 0.5 * tr.duration)

    last = at(trials[-1])
    return [replace(tr, friction_scale=at(tr) / last) for tr in trials]


def coast_frictions(trials: list[Trial], base: WheelParams) -> list[CoastFriction]:
    """Every coast-down's tau_f, trials in the order given (session order)."""
    out = []
    for tr in trials:
        for a, b, e, v in coast_estimates(tr, base):
            half = 1.96 * math.sqrt(max(v, 0.0))
            mid = None if tr.session_start is None else tr.session_start + 0.5 * float(
                tr.t[a] + tr.t[b - 1]) - float(tr.t[0])
            out.append(CoastFriction(tr.name, mid, e, (e - half, e + half)))
    return out


def friction_trend(coasts: list[CoastFriction]) -> FrictionTrend | None:
    """The line through ``coasts`` along session time, or None with fewer than three timed
    coast-downs or no spread in time."""
    timed = [c for c in coasts if c.session_t is not None]
    if len(timed) < 3:
        return None
    t = np.array([c.session_t for c in timed])
    e = np.array([c.tau_f for c in timed])
    sd = np.array([(c.ci95[1] - c.ci95[0]) / (2 * 1.96) for c in timed])
    w = 1.0 / np.maximum(sd, 1e-15) ** 2
    X = np.column_stack([np.ones_like(t), t])
    A = X.T @ (w[:, None] * X)
    if np.linalg.cond(A) > 1e14:
        return None
    coef = np.linalg.solve(A, X.T @ (w * e))
    r = e - X @ coef
    dof = t.size - 2
    scale = max(float(np.sum(w * r * r)) / dof, 1.0)
    cov = np.linalg.inv(A) * scale
    slope, slope_sd = float(coef[1]), math.sqrt(float(cov[1, 1]))
    p = float(2 * stats.t.sf(abs(slope) / slope_sd, dof)) if slope_sd > 0 else 1.0
    return FrictionTrend(float(coef[0]), slope, slope_sd, p, slope / float(coef[0]),
                         float(np.ptp(t)))
