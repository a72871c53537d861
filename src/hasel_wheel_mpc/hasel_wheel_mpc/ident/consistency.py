"""Is an effect the same in every trial?  Its parameters refitted trial by trial.

A physical effect of the wheel has one value: an off-centre mass is as heavy in the slow
trial as in the fast one.  An effect that only stands in for another does not.  Fitted to an
angle sensor's reading error e sin(xi1 + phase), an off-centre mass needs the torque
J e xi2^2, which grows with the trial's speed; fitted to an off-centre mass T sin(xi1 + phase),
a reading error needs e = T / (J xi2^2), which falls with it.  So each chosen effect is
refitted on each trial alone, together with the force law (:data:`FORCE_LAW`), while
friction and any other effect are held at the fit on all trials, and its size is regressed on
the trial's speed.  The force law has to move as well: held at the fit on all trials, it
biases an effect that trades off with it.  Viscous drag shares its speed dependence with the
force law's b, and the right drag model gave k = -0.24 to -0.62 (p down to 0.01) over four
plant seeds with the force law held, -0.01 and +0.06 with it refitted (ad hoc, 3 x 34 s).

Size.  The parameters of trial j, u_j (k,) in units of each one's typical magnitude, are
projected onto the direction of their inverse-covariance mean ubar: m_j = ubar' u_j / |ubar|,
with variance ubar' C_j ubar / |ubar|^2 from the fit's covariance C_j (widened for the
residual's autocorrelation, :func:`~.fit.autocorrelation_inflation`).

Trend.  Weighted least squares m_j = a + b (ln v_j - mean ln v), v_j the trial's mean speed
while driven; the exponent k = b / a is the power of the speed the size goes with
(size ~ v^k near the trials' speeds).  The effect is *inconsistent* when the slope is
significant (two-sided p < :data:`TREND_P`) and |k| > :data:`EXPONENT`.  Right models gave
exponents of -0.1 to +0.1 with p > 0.05; the stand-ins above gave +1.4 and -1.2 (ad hoc,
3 x 34 s, see the README).  The homogeneity chi^2 of the u_j about ubar and their spread
are reported beside it.
"""
from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from scipy import stats

from hasel_wheel_sim.params import WheelParams

from .candidates import Candidate
from .data import Trial
from .fit import FitResult, Problem

#: The force law's coordinates (:func:`~.fit.nominal_specs`), refitted in each trial too.
FORCE_LAW = frozenset({"peak", "centre", "width", "b", "brake_gain"})

#: Evaluation limit of each trial's refit, which starts at the fit on all trials (the folds'
#: limit too).
MAX_NFEV = 30

#: A trend of an effect's size with the trials' speed this unlikely by chance (two-sided) ...
TREND_P = 1e-3
#: ... and steeper than size ~ speed^EXPONENT makes it inconsistent (:func:`inconsistent`).
EXPONENT = 0.5


@dataclass
class Consistency:
    """An effect refitted trial by trial.

    ``names`` (k,) the parameters refitted, ``estimates`` (m, k) their values per trial, ``sd`` (m, k) their standard deviations,
    ``pooled`` (k,) the inverse-covariance mean; ``chi2`` on ``dof`` degrees of freedom and its
    ``p``; ``spread`` [1] the RMS distance of the trials' estimates from the pooled one over
    the pooled one's norm; ``speeds`` [rad/s] each trial's mean measured speed while driven;
    ``exponent`` k (size ~ speed^k) with its standard deviation and the slope's ``trend_p``."""

    effect: str
    names: list[str]
    trials: list[str]
    estimates: np.ndarray
    sd: np.ndarray
    pooled: np.ndarray
    chi2: float
    dof: int
    p: float
    spread: float
    speeds: list[float]
    exponent: float
    exponent_sd: float
    trend_p: float

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


def trial_consistency(trials: list[Trial], base: WheelParams, effects: tuple[Candidate, ...],
                      fit: FitResult, effect: Candidate, window: float = 1.0,
                      threads: int = 2) -> Consistency | None:
    """Refit ``effect``'s own parameters (its ``per_trial`` ones) and the force law on each
    trial alone, everything else held at ``fit`` (the fit of the model with ``effects`` on all
    ``trials``).  None with fewer than two trials."""
    if len(trials) < 2:
        return None
    params = [p for p in effect.params
              if effect.per_trial is None or p.name in effect.per_trial]
    own = {p.name for p in params}
    held = {n: v for n, v in fit.values.items() if n not in own and n not in FORCE_LAW}
    start = dict(fit.values)
    # each trial's windows start where the fit on all trials put them (the same windows:
    # a trial is cut the same way alone), and the trials are fitted side by side, one thread
    # each (the compiled simulator releases the GIL), as the folds are
    every = Problem(trials, base, effects, window=window)
    x_all = fit.z[len(fit.names):].reshape(-1, 2)

    def one(j: int) -> FitResult:
        prob = Problem([trials[j]], base, effects, window=window, fixed=held)
        return prob.fit(start=start, x0=x_all[every.trial_windows[j]], max_nfev=MAX_NFEV)

    with ThreadPoolExecutor(max_workers=max(threads, 1)) as pool:
        fits = list(pool.map(one, range(len(trials))))
    est, sd, cov, speeds = [], [], [], []
    for tr, res in zip(trials, fits):
        order = [res.names.index(p.name) for p in params]
        est.append(res.theta[order])
        c = res.cov[np.ix_(order, order)]
        cov.append(c)
        sd.append(np.sqrt(np.maximum(np.diag(c), 0.0)))
        driven = tr.q.astype(bool) | (tr.n_a >= 0)
        span = tr.t[driven] if driven.any() else tr.t
        ang = tr.angle[driven] if driven.any() else tr.angle
        speeds.append(float((ang[-1] - ang[0]) / max(span[-1] - span[0], 1e-9)))
    # in units of each parameter's typical magnitude, so that no unit dominates the norm
    scale = np.array([p.scale for p in params])
    x = np.array(est)
    u = x / scale
    k = x.shape[1]
    infos = [np.linalg.pinv(c / np.outer(scale, scale)) for c in cov]
    pooled = np.linalg.pinv(np.sum(infos, axis=0)) @ np.sum([i @ v for i, v in zip(infos, u)],
                                                            axis=0)
    chi2 = float(sum((v - pooled) @ i @ (v - pooled) for i, v in zip(infos, u)))
    dof = (len(trials) - 1) * k
    norm = float(np.linalg.norm(pooled))
    exponent, exponent_sd, trend_p = _trend(u, infos, pooled, speeds)
    spread = (math.sqrt(float(np.mean(np.sum((u - pooled) ** 2, axis=1)))) / norm
              if norm > 0 else math.inf)
    return Consistency(effect.id, [p.name for p in params], [tr.name for tr in trials], x, np.array(sd), pooled * scale,
                       chi2, dof, float(stats.chi2.sf(chi2, dof)), spread, speeds, exponent,
                       exponent_sd, trend_p)


def _trend(u: np.ndarray, infos: list[np.ndarray], pooled: np.ndarray,
           speeds: list[float]) -> tuple[float, float, float]:
    """(k, sd of k, two-sided p of the slope) of the sizes m_j = pooled' u_j / |pooled|
    against ln(speed) (see the module docstring); (0, inf, 1) when it cannot be formed."""
    norm = float(np.linalg.norm(pooled))
    x = np.log(np.maximum(np.asarray(speeds), 1e-9))
    if norm <= 0.0 or np.ptp(x) <= 0.0:
        return 0.0, math.inf, 1.0
    d = pooled / norm
    m = u @ d
    var = np.array([d @ np.linalg.pinv(i) @ d for i in infos])
    w = 1.0 / np.maximum(var, 1e-300)
    X = np.column_stack([np.ones_like(x), x - np.average(x, weights=w)])
    cov = np.linalg.inv(X.T @ (w[:, None] * X))
    a, b = cov @ X.T @ (w * m)
    if a <= 0.0:
        return 0.0, math.inf, 1.0
    k = b / a
    # delta method for b / a
    sd = abs(k) * math.sqrt(max(cov[1, 1] / b ** 2 + cov[0, 0] / a ** 2
                                - 2 * cov[0, 1] / (a * b), 0.0)) if b != 0 else math.sqrt(cov[1, 1]) / a
    return float(k), float(sd), float(2 * stats.norm.sf(abs(b) / math.sqrt(cov[1, 1])))


def inconsistent(c: Consistency | None) -> bool:
    """True when the effect's size trends with the trials' speed: significantly
    (p < TREND_P) and steeper than speed^(+-EXPONENT)."""
    return c is not None and c.trend_p < TREND_P and abs(c.exponent) > EXPONENT


def stand_in(trials: list[Trial], base: WheelParams, effects: tuple[Candidate, ...],
             fit: FitResult, added: tuple[Candidate, ...], window: float = 1.0,
             threads: int = 2) -> str | None:
    """Why one of ``added`` (effects of the model ``effects``, fitted as ``fit`` on all
    ``trials``) looks like a stand-in for another effect, or None: its size trends with the
    trials' speed (:func:`inconsistent`)."""
    for c in added:
        con = trial_consistency(trials, base, effects, fit, c, window, threads)
        if inconsistent(con):
            return (f"{c.id} is not the same in every trial, refitted trial by trial: "
                    f"{con.text(c)}; a physical {c.id} would not change with the speed, so it "
                    f"stands in for an effect whose size goes otherwise with the speed")
    return None
