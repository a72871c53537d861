"""Is an effect the same in every trial?  :func:`trial_consistency` refits it on each trial
alone (or on spans of the drives when the trials share their speed,
:func:`~.drive_cuts.speed_units`) with the nominal model (:data:`NOMINAL`), the other effects
held, and on the halves of each drive (:func:`~.drive_cuts.drive_halves`).  The refits of one
trial run side by side, one thread each (the compiled simulator releases the GIL), as the
folds do.  The rules on the result are in :mod:`.consistency`.  Tested in
``test_ident_consistency.py`` (``test_the_right_effect_is_the_same_in_every_trial``,
``test_the_right_effect_is_the_same_in_both_halves_of_every_drive``)."""
from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from scipy import stats

from hasel_wheel_sim.params import WheelParams

from hasel_wheel_ident.candidates import Candidate, ParamSpec
from hasel_wheel_ident.consistency import Consistency
from hasel_wheel_ident.data import Trial
from hasel_wheel_ident.drive_cuts import drive_halves, driven_speed, speed_units
from hasel_wheel_ident.fit import FitResult, Problem
from hasel_wheel_ident.size_trends import hv_drift, speed_trend

#: The nominal model's parameters (:func:`~.fit.nominal_specs`), refitted in each trial too.
NOMINAL = frozenset({"peak", "centre", "width", "b", "brake_gain", "tau_f"})

#: Evaluation limit of each trial's refit, which starts at the fit on all trials (the folds'
#: limit too).
MAX_NFEV = 30


@dataclass(frozen=True)
class _Refits:
    """Refits of single trials of ``trials`` with ``effects`` (windows ``window`` [s]), the
    parameters ``held`` fixed, ``threads`` at a time."""

    trials: list[Trial]
    base: WheelParams
    effects: tuple[Candidate, ...]
    window: float
    held: dict[str, float]
    threads: int

    def fit(self, j: int, start: dict[str, float], x0: np.ndarray,
            keep: tuple[float, float] | None = None,
            fixed: dict[str, float] | None = None) -> FitResult:
        """Trial ``j`` refitted from ``start`` and the window starts ``x0``, weighing the
        samples in ``keep`` [s] (all when None), ``fixed`` (``held`` when None) fixed."""
        prob = Problem([self.trials[j]], self.base, self.effects, window=self.window,
                       fixed=self.held if fixed is None else fixed, keep=keep)
        return prob.fit(start=start, x0=x0, max_nfev=MAX_NFEV)

    def map(self, one: Callable, jobs: Iterable) -> list[FitResult]:
        """``one`` of every job, ``threads`` at a time, in order."""
        with ThreadPoolExecutor(max_workers=max(self.threads, 1)) as pool:
            return list(pool.map(one, jobs))


def trial_consistency(trials: list[Trial], base: WheelParams, effects: tuple[Candidate, ...],
                      fit: FitResult, effect: Candidate, window: float = 1.0,
                      threads: int = 2) -> Consistency | None:
    """Refit ``effect``'s own parameters (its ``per_trial`` ones) and the nominal model on each
    trial alone, any other effect held at ``fit`` (the fit of the model with ``effects`` on
    all ``trials``).  Returns the per-trial estimates in each parameter's own unit (see
    :class:`~.consistency.Consistency`); None with fewer than two trials."""
    if len(trials) < 2:
        return None
    params = [p for p in effect.params
              if effect.per_trial is None or p.name in effect.per_trial]
    own = {p.name for p in params}
    held = {n: v for n, v in fit.values.items() if n not in own and n not in NOMINAL}
    refits = _Refits(trials, base, effects, window, held, threads)
    seen, fits = _trial_fits(refits, fit)
    spans = speed_units(seen)
    if spans:
        units, unit_fits = [piece for _, piece in spans], _span_fits(refits, fits, spans)
    else:
        units, unit_fits = seen, fits
    con, u, pooled = _pooled(effect, params, units, unit_fits, "span" if spans else "trial")
    if spans:       # the halves below are halves of the trials, sized by the trials' fits
        u = np.array(_estimates(seen, fits, params)[0]) / _scale(params)
        con.halves_trials = [tr.name for tr in seen]
    norm = float(np.linalg.norm(pooled))
    if norm > 0.0:
        _measure_halves(con, refits, seen, fits, params, pooled / norm, u)
    return con


def _trial_fits(refits: _Refits, fit: FitResult) -> tuple[list[Trial], list[FitResult]]:
    """(the trials as the fits see them, each trial's refit).  Each trial's windows start
    where the fit on all trials put them (a trial is cut the same way alone).  The trials
    are those with a tail at rest trimmed (:func:`~.fit.at_rest_trimmed`): the speeds,
    spans and halves are taken from these, so that a wheel that stalls for good while driven
    has no half in the trimmed tail (a fit of no samples)."""
    every = Problem(refits.trials, refits.base, refits.effects, window=refits.window)
    start, x_all = dict(fit.values), fit.x0
    fits = refits.map(lambda j: refits.fit(j, start, x_all[every.trial_windows[j]]),
                      range(len(refits.trials)))
    return every.trials, fits


def _span_fits(refits: _Refits, fits: list[FitResult],
               spans: list[tuple[int, Trial]]) -> list[FitResult]:
    """Each span weighed alone (``keep``) from its trial's fit, the samples before it still
    running the model (a retained charge builds up from the trial's start)."""
    def one(job: tuple[int, Trial]) -> FitResult:
        j, piece = job
        keep = (float(piece.t[0]), float(np.nextafter(piece.t[-1], math.inf)))
        return refits.fit(j, fits[j].values, fits[j].x0, keep=keep)

    return refits.map(one, spans)


def _scale(params: list[ParamSpec]) -> np.ndarray:
    """(k,) each parameter's typical magnitude, the unit of the sizes."""
    return np.array([p.scale for p in params])


def _pooled(effect: Candidate, params: list[ParamSpec], units: list[Trial],
            fits: list[FitResult], unit: str) -> tuple[Consistency, np.ndarray, np.ndarray]:
    """(the record, the estimates u (m, k) and their inverse-covariance mean (k,), both in
    units of each parameter's typical magnitude, so that no unit dominates the norm).  A
    direction a unit does not determine (an infinite variance) carries no information."""
    est, sd, cov, speeds = _estimates(units, fits, params)
    scale = _scale(params)
    x = np.array(est)
    u = x / scale
    k = x.shape[1]
    covs = [c / np.outer(scale, scale) for c in cov]
    infos = [np.linalg.pinv(np.where(np.isfinite(c), c, 0.0)) for c in covs]
    pooled = np.linalg.pinv(np.sum(infos, axis=0)) @ np.sum([i @ v for i, v in zip(infos, u)],
                                                            axis=0)
    chi2 = float(sum((v - pooled) @ i @ (v - pooled) for i, v in zip(infos, u)))
    dof = (len(units) - 1) * k
    exponent, exponent_sd, trend_p = speed_trend(u, covs, pooled, speeds)
    con = Consistency(effect.id, [p.name for p in params], [tr.name for tr in units], x,
                      np.array(sd), pooled * scale, chi2, dof, float(stats.chi2.sf(chi2, dof)),
                      speeds, exponent, exponent_sd, trend_p, unit)
    return con, u, pooled


def _estimates(units: list[Trial], fits: list[FitResult], params: list[ParamSpec]
               ) -> tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray], list[float]]:
    """(estimates, their sd, their covariance, the unit's speed [rad/s]) of ``params`` in
    each fit of ``fits``, one per trial or span of ``units``."""
    est, sd, cov, speeds = [], [], [], []
    for tr, res in zip(units, fits):
        order = [res.names.index(p.name) for p in params]
        est.append(res.theta[order])
        c = res.cov[np.ix_(order, order)]
        cov.append(c)
        sd.append(np.sqrt(np.maximum(np.diag(c), 0.0)))
        speeds.append(driven_speed(tr))
    return est, sd, cov, speeds


def _measure_halves(con: Consistency, refits: _Refits, seen: list[Trial],
                    fits: list[FitResult], params: list[ParamSpec], d: np.ndarray,
                    u: np.ndarray) -> None:
    """Refit the effect on the halves of each trial's drive, every other parameter held at
    the trial's fit, and keep on ``con`` the sizes along the direction ``d`` (k,), their HV
    times and the drift (:func:`~.size_trends.hv_drift`) against the whole trials' sizes
    ``u @ d``."""
    own = {p.name for p in params}

    def half(job: tuple[int, tuple[float, float]]) -> FitResult:
        j, span = job
        res = fits[j]
        fixed = {**refits.held, **{n: v for n, v in res.values.items() if n not in own}}
        return refits.fit(j, res.values, res.x0, keep=span, fixed=fixed)

    cuts = [drive_halves(tr) for tr in seen]
    jobs = [(j, span) for j, c in enumerate(cuts) if c is not None for span in c[0]]
    done = dict(zip(jobs, refits.map(half, jobs)))
    halves = np.full((len(seen), 2), np.nan)
    halves_var = np.full((len(seen), 2), np.inf)
    hv = np.full((len(seen), 2), np.nan)
    for j, c in enumerate(cuts):
        if c is None:
            continue
        hv[j] = c[1]
        for i, span in enumerate(c[0]):
            halves[j, i], halves_var[j, i] = _size(done[(j, span)], params, d)
    con.halves, con.hv = halves, hv
    con.halves_sd = np.sqrt(halves_var)
    con.drift, con.drift_sd, con.drift_p = hv_drift(halves, halves_var, hv, u @ d)


def _size(res: FitResult, params: list[ParamSpec], d: np.ndarray) -> tuple[float, float]:
    """(size, its variance) of ``params`` in the fit ``res`` along the direction ``d``, in
    units of their typical magnitudes; an infinite variance when the fit leaves one
    undetermined."""
    scale = _scale(params)
    order = [res.names.index(p.name) for p in params]
    cj = res.cov[np.ix_(order, order)] / np.outer(scale, scale)
    return d @ (res.theta[order] / scale), (d @ cj @ d if np.all(np.isfinite(cj)) else np.inf)
