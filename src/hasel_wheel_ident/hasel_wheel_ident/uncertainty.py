"""The uncertainty of a multiple-shooting fit: the residual's variance and the widening for
its autocorrelation (:func:`noise`, :func:`autocorrelation_inflation`), and the parameters'
covariance from the projected Jacobian (:func:`covariance`).  Tested in ``test_ident_fit.py``."""
from __future__ import annotations

import numpy as np


def noise(r: np.ndarray, g: int, ok: np.ndarray, starts: np.ndarray,
          quantised: bool) -> tuple[float, float]:
    """(s^2 [rad^2], inflation) of the residual r (n,) of a fit with g shared parameters,
    counting the samples ``ok`` (n,) of the windows that begin at ``starts`` (w + 1,).

    With encoder intervals (``quantised``) only the samples outside their interval carry
    error (the rest are 0 and say only "inside"), so the variance is over those, and their
    autocorrelation is taken about zero (the zeros are not noise about a mean)."""
    active = ok & (r != 0.0) if quantised else ok
    # a window with no counted sample (outside ``keep``) fits no start
    weighed = int(np.count_nonzero(np.add.reduceat(ok, starts[:-1])))
    dof = max(int(active.sum()) - g - 2 * weighed, 1)
    return (float(r @ r) / dof,
            autocorrelation_inflation(r, starts, active, centred=not quantised))


def covariance(J: np.ndarray, scale: np.ndarray, s2: float, tol: float = 1e-10) -> np.ndarray:
    """(g, g) parameter covariance s2 (J'J)^-1 from the Jacobian J (n, g), computed in the
    parameters' typical scales (g,).  A direction the data does not determine (relative
    eigenvalue below ``tol``) gets infinite variance in every parameter it involves, so its
    interval reads (-inf, inf) rather than a falsely tight one."""
    Js = J * scale
    w, V = np.linalg.eigh(Js.T @ Js)
    top = max(float(w[-1]), 1e-300)
    ok = w > tol * top
    inv = (V[:, ok] / w[ok]) @ V[:, ok].T
    cov = inv * s2 * np.outer(scale, scale)
    blind = np.any(np.abs(V[:, ~ok]) > 1e-3, axis=1) if (~ok).any() else np.zeros(len(w), bool)
    cov[blind, :] = np.where(np.eye(len(w), dtype=bool)[blind, :], np.inf, 0.0)
    cov[:, blind] = np.where(np.eye(len(w), dtype=bool)[:, blind], np.inf, 0.0)
    return cov



def autocorrelation_inflation(r: np.ndarray, starts: np.ndarray, used: np.ndarray,
                              max_lag: int = 30, centred: bool = True) -> float:
    """1 + 2 sum_{l=1..max_lag} rho_l: how much a correlated residual widens the intervals.

    Least-squares intervals assume independent residuals.  A 10-bit encoder sampled at 300 Hz
    aliases its count steps into a slow sawtooth, so neighbouring residuals are correlated
    and carry less information than their number suggests.  The sum of the residual's
    autocorrelations (inside windows, up to ``max_lag`` samples) is the factor by which the
    variance of a slowly varying projection of it grows.  Never below 1.
    """
    num = np.zeros(max_lag + 1)
    for w in range(starts.shape[0] - 1):
        a, b = starts[w], starts[w + 1]
        rr = np.where(used[a:b], r[a:b], 0.0)
        if centred:
            rr = rr - rr.mean()
        m = rr.shape[0]
        for lag in range(min(max_lag, m - 1) + 1):
            num[lag] += float(rr[lag:] @ rr[:m - lag])
    if num[0] <= 0.0:
        return 1.0
    rho = num[1:] / num[0]
    return float(max(1.0 + 2.0 * np.sum(rho), 1.0))
