"""One model fitted on all trials and cross-validated by trial: :class:`Evaluation` and
:func:`evaluate`."""
from __future__ import annotations

import math
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from hasel_wheel_bag.progress import progress_bar
from hasel_wheel_sim.params import WheelParams

from hasel_wheel_ident.candidates import Candidate
from hasel_wheel_ident.data import Trial
from hasel_wheel_ident.fit import FitResult, Problem
from hasel_wheel_ident.metrics import TrialMetrics, fitted_metrics, pooled_rmse, trial_metrics
from hasel_wheel_ident.reasons import Reason


@dataclass
class Evaluation:
    """One model (nominal + ``effects``) fitted on all trials and cross-validated."""

    effects: tuple[str, ...]
    fit: FitResult
    heldout_rmse: float                     # pooled over folds [rad]
    heldout_per_trial: dict[str, float]     # [rad]
    wald_p: float = math.nan                # of the last added effect
    accepted: bool = False
    plausible: bool = True                  # its values look like the physics it names
    reason: str = ""                        # the verdict in words
    codes: list[Reason] = field(default_factory=list)   # the verdict as codes
    sim_fitted: dict[str, TrialMetrics] = field(default_factory=dict)   # free run, all-trial fit
    sim_heldout: dict[str, TrialMetrics] = field(default_factory=dict)  # free run, fold fits
    fold_values: dict[str, dict[str, float]] = field(default_factory=dict)  # trial -> its fold fit

    @property
    def sim_heldout_rmse(self) -> float:
        """Held-out simulation error [rad/s] pooled over trials (Table III's metric)."""
        return pooled_rmse(self.sim_heldout or self.sim_fitted)


def folds_of(n_trials: int, k: int) -> list[list[int]]:
    """Trial indices held out in each fold: leave-one-out up to k trials, else k groups."""
    k = min(k, n_trials)
    return [list(range(i, n_trials, k)) for i in range(k)]


def _subset_starts(problem: Problem, z: np.ndarray, keep: list[int]) -> np.ndarray:
    """(w', 2) the fitted window starts of the trials ``keep`` (windows never cross trials)."""
    x0 = problem.window_starts(z)
    return np.concatenate([x0[problem.trial_windows[i]] for i in keep])


def evaluate(trials: list[Trial], base: WheelParams, effects: tuple[Candidate, ...],
             window: float, start: dict[str, float], folds: list[list[int]],
             threads: int = 2, cv_below: float | None = None,
             sim_below: float | None = None,
             refuse: Callable[[FitResult], object | None] | None = None,
             x0: np.ndarray | None = None, max_nfev: int = 100,
             progress: str | None = None) -> Evaluation:
    """Fit on all trials from ``start`` (``window`` [s]), then per fold on the rest
    (warm-started from the full fit), and score the held-out trials with their window
    starts re-solved.

    The folds are skipped (held-out error nan) when the fit on all trials already shows
    that the model cannot pass: its window RMSE is above ``cv_below`` [rad]; its pooled
    free-run error on its own trials is not below ``sim_below`` [rad/s]; or ``refuse``
    returns a refusal (not None).  ``threads``: the threads of the fit on all trials and
    the folds run side by side.  ``x0`` (w, 2) and ``max_nfev``: the fit on all trials'
    window starts and evaluation limit (:meth:`~.fit.Problem.fit`).  ``progress``, when
    given, labels a bar of the folds on stderr (on a terminal).  Tested in
    ``test_ident_effects.py::test_a_refit_refused_on_all_trials_is_not_cross_validated``."""
    problem = Problem(trials, base, effects, window, threads=threads)
    full = problem.fit(start=start, x0=x0, max_nfev=max_nfev)
    ev = Evaluation(tuple(c.id for c in effects), full, full.rmse, dict(full.per_trial_rmse))
    ev.sim_fitted = fitted_metrics(problem, full, trials)
    if len(trials) < 2 or (cv_below is not None and full.rmse > cv_below) or \
            (sim_below is not None and pooled_rmse(ev.sim_fitted) >= sim_below) or \
            (refuse is not None and refuse(full) is not None):
        if len(trials) >= 2:
            ev.heldout_rmse = math.nan
        return ev
    _cross_validate(ev, problem, trials, base, effects, window, folds, max(threads, 1),
                    progress)
    return ev


def _cross_validate(ev: Evaluation, problem: Problem, trials: list[Trial], base: WheelParams,
                    effects: tuple[Candidate, ...], window: float, folds: list[list[int]],
                    workers: int, progress: str | None = None) -> None:
    """Fit each fold on the other trials (``workers`` folds side by side, one thread each;
    a fold left alone at the end gets them all) and set ``ev``'s held-out figures."""
    full = ev.fit
    alone = len(folds) - 1 if len(folds) % workers == 1 and len(folds) > 1 else -1

    def one_fold(i_held: tuple[int, list[int]]) -> tuple[list[int], Problem, np.ndarray,
                                                         np.ndarray, np.ndarray,
                                                         dict[str, float]]:
        i_fold, held = i_held
        train = [i for i in range(len(trials)) if i not in held]
        pf = Problem([trials[i] for i in train], base, effects, window,
                     threads=workers if i_fold == alone else 1)
        f = pf.fit(start=full.values, x0=_subset_starts(problem, full.z, train), max_nfev=30)
        pt = Problem([trials[i] for i in held], base, effects, window)
        theta = np.array([f.values[nm] for nm in pt.names])
        x, r, _, _ = pt.solve_starts(pt.full_theta(theta), _subset_starts(problem, full.z, held))
        return held, pt, theta, x, r, f.values

    sq = n = 0.0
    with ThreadPoolExecutor(max_workers=workers) as pool:
        fits = pool.map(one_fold, enumerate(folds))
        if progress:
            fits = progress_bar(fits, progress, len(folds), unit="fold", scale=False)
        for held, pt, theta, x, r, values in fits:
            for j, (i, s) in enumerate(zip(held, pt.trial_slices)):
                tr = trials[i]
                rr = r[s][pt.ok[s]]
                ev.heldout_per_trial[tr.name] = float(np.sqrt(np.mean(rr ** 2)))
                sq += float(rr @ rr)
                n += rr.size
                ev.sim_heldout[tr.name] = trial_metrics(pt, theta, tr,
                                                        x[pt.trial_windows[j][0]])
                ev.fold_values[tr.name] = dict(values)
    ev.heldout_rmse = math.sqrt(sq / n)
