"""How an effect's refitted size moves: with the units' speed (:func:`speed_trend`, size ~
v^k) and within the trials with the accumulated HV time (:func:`hv_drift`, size ~ hv^h).
Sizes are in units of the parameters' typical magnitudes; both return (exponent, its sd,
two-sided p of no trend).  Tested in ``test_ident_consistency.py``
(``test_the_trend_is_the_weighted_regression_on_log_speed``,
``test_the_drift_within_trials_is_the_weighted_mean_of_each_trials_log_ratio``)."""
from __future__ import annotations

import math

import numpy as np
from scipy import stats

#: What :func:`speed_trend` and :func:`hv_drift` return when no trend can be formed.
NO_TREND = (0.0, math.inf, 1.0)


def speed_trend(u: np.ndarray, covs: list[np.ndarray], pooled: np.ndarray,
                speeds: list[float]) -> tuple[float, float, float]:
    """(k, sd of k, two-sided p of the slope) of the sizes m_j = pooled' u_j / |pooled| of
    the m units' estimates u (m, k) with covariances ``covs`` (m of (k, k)), regressed with
    inverse-variance weights on ln of the units' ``speeds`` [rad/s]: m = a + b (ln v - mean),
    k = b / a.  :data:`NO_TREND` when it cannot be formed: no size, one speed, fewer than two
    units with a finite variance, or a size that is not positive."""
    norm = float(np.linalg.norm(pooled))
    x = np.log(np.maximum(np.asarray(speeds), 1e-9))
    if norm <= 0.0 or np.ptp(x) <= 0.0:
        return NO_TREND
    d = pooled / norm
    m = u @ d
    var = np.array([d @ c @ d for c in covs])
    ok = np.isfinite(var) & (var > 0.0)
    if ok.sum() < 2 or np.ptp(x[ok]) <= 0.0:
        return NO_TREND
    w = np.where(ok, 1.0 / np.where(ok, var, 1.0), 0.0)
    X = np.column_stack([np.ones_like(x), x - np.average(x, weights=w)])
    cov = np.linalg.inv(X.T @ (w[:, None] * X))
    a, b = cov @ X.T @ (w * np.where(ok, m, 0.0))
    if a <= 0.0:
        return NO_TREND
    k = b / a
    p = float(2 * stats.norm.sf(abs(b) / math.sqrt(cov[1, 1])))
    return float(k), _ratio_sd(k, a, b, cov), p


def _ratio_sd(k: float, a: float, b: float, cov: np.ndarray) -> float:
    """The sd of k = b / a by the delta method, (a, b) with covariance ``cov`` (2, 2)."""
    return float(abs(k) * math.sqrt(max(cov[1, 1] / b ** 2 + cov[0, 0] / a ** 2
                                        - 2 * cov[0, 1] / (a * b), 0.0)) if b != 0
                 else math.sqrt(cov[1, 1]) / a)


def hv_drift(halves: np.ndarray, var: np.ndarray, hv: np.ndarray,
             whole: np.ndarray) -> tuple[float, float, float]:
    """(h, sd of h, two-sided p of h = 0): how the size changes within a trial, size ~ hv^h.

    ``halves`` (m, 2) the sizes refitted on each trial's halves with variances ``var``
    (m, 2), at the mean HV times ``hv`` (m, 2) [s]; ``whole`` (m,) the size fitted on the
    whole trial.  Each trial gives h_j = (late - early) / (whole * ln(hv_late / hv_early)),
    with variance (var_early + var_late) / (whole * ln ratio)^2; they are averaged with
    inverse-variance weights.  :data:`NO_TREND` when no trial gives one (no cut, or a size
    that is not positive on the whole trial)."""
    num = den = 0.0
    for (a, b), (va, vb), (h0, h1), m in zip(halves, var, hv, whole):
        if not (np.isfinite(a) and np.isfinite(b) and m > 0.0 and h0 > 0.0 and h1 > h0):
            continue
        g = m * math.log(h1 / h0)
        v = (va + vb) / g ** 2
        if not (np.isfinite(v) and v > 0.0):
            continue
        num += (b - a) / g / v
        den += 1.0 / v
    if den <= 0.0:
        return NO_TREND
    h = num / den
    sd = 1.0 / math.sqrt(den)
    return float(h), float(sd), float(2 * stats.norm.sf(abs(h) / sd))
