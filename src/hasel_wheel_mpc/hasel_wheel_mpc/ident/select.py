"""The whole identification: nominal fit, residual analysis, and the search for the missing
effect with held-out validation by trial.

Search (forward selection).  Starting from the nominal model, every candidate not yet in
the model is added and the model refitted.  A candidate is accepted only when both hold:

* **held-out error**: the angle RMSE on trials left out of the fit (k-fold by trial, each
  fold refitted) falls by at least ``min_gain`` (default 10 %) against the current model.
  Cross-validation is the penalty for complexity: parameters that only fit noise do not
  help on trials they never saw;
* **significance**: its parameters differ from "no effect" by more than chance, a Wald
  test  (x - x0)' C^-1 (x - x0) against chi^2 with p < 1e-6.

The best accepted candidate joins the model and the search repeats, up to ``max_effects``.
Whatever structure remains in the residual afterwards is reported as unexplained, with its
signature (:mod:`.residual`).
"""
from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from hasel_wheel_sim.params import WheelParams

from .candidates import LIBRARY, Candidate
from .data import Trial
from .fit import FitResult, FrictionEstimate, Problem, coastdown_friction
from .residual import Diagnostics, analyse


@dataclass
class Evaluation:
    """One model (nominal + ``effects``) fitted on all trials and cross-validated."""

    effects: tuple[str, ...]
    fit: FitResult
    heldout_rmse: float                     # pooled over folds [rad]
    heldout_per_trial: dict[str, float]     # [rad]
    wald_p: float = math.nan                # of the last added effect
    accepted: bool = False
    reason: str = ""


@dataclass
class Identification:
    friction: FrictionEstimate | None
    nominal: Evaluation
    final: Evaluation
    rounds: list[list[Evaluation]] = field(default_factory=list)
    diagnostics_before: Diagnostics | None = None
    diagnostics_after: Diagnostics | None = None
    problem_before: Problem | None = None
    problem_after: Problem | None = None

    @property
    def chosen(self) -> tuple[str, ...]:
        return self.final.effects


def folds_of(n_trials: int, k: int) -> list[list[int]]:
    """Trial indices held out in each fold: leave-one-out up to k trials, else k groups."""
    k = min(k, n_trials)
    return [list(range(i, n_trials, k)) for i in range(k)]


def _fit(trials, base, effects, window, start, max_nfev=100) -> FitResult:
    return Problem(trials, base, effects, window).fit(start=start, max_nfev=max_nfev)


def evaluate(trials: list[Trial], base: WheelParams, effects: tuple[Candidate, ...],
             window: float, start: dict[str, float], folds: list[list[int]]) -> Evaluation:
    """Fit on all trials, then per fold on the rest, and score the held-out trials.

    The fit on all trials starts twice, from ``start`` (the current model) and from the
    reference parameters, and keeps the better: a nominal model that bent its force law to
    mimic a missing effect is a poor place to start looking for that effect."""
    full = _fit(trials, base, effects, window, start)
    if start:
        fresh = _fit(trials, base, effects, window, {"tau_f": start["tau_f"]}
                     if "tau_f" in start else {})
        if fresh.rmse < full.rmse:
            full = fresh
    start = dict(start, **full.values)
    per_trial: dict[str, float] = {}
    sq = n = 0.0
    if len(trials) > 1:
        for held in folds:
            train = [t for i, t in enumerate(trials) if i not in held]
            test = [t for i, t in enumerate(trials) if i in held]
            f = _fit(train, base, effects, window, start, max_nfev=30)
            pt = Problem(test, base, effects, window)
            theta = np.array([f.values[nm] for nm in pt.names])
            _, r, _, _ = pt.solve_starts(pt.full_theta(theta), pt.initial_starts())
            for tr, s in zip(test, pt.trial_slices):
                rr = r[s][pt.ok[s]]
                per_trial[tr.name] = float(np.sqrt(np.mean(rr ** 2)))
                sq += float(rr @ rr)
                n += rr.size
    heldout = math.sqrt(sq / n) if n else full.rmse
    return Evaluation(tuple(c.id for c in effects), full, heldout, per_trial or
                      dict(full.per_trial_rmse))


def wald_p(fit: FitResult, effect: Candidate) -> float:
    """p-value of "this effect is absent" from the fit's covariance."""
    names = [p.name for p in effect.params]
    idx = [fit.names.index(nm) for nm in names]
    x = fit.theta[idx]
    null = np.array([_null_value(effect, nm) for nm in names])
    C = fit.cov[np.ix_(idx, idx)]
    try:
        chi2 = float((x - null) @ np.linalg.solve(C, x - null))
    except np.linalg.LinAlgError:
        return 1.0
    return float(stats.chi2.sf(chi2, len(idx)))


def _null_value(effect: Candidate, name: str) -> float:
    """The parameter value at which the effect vanishes."""
    if effect.id == "charge_retention":
        return 0.0 if name == "rate" else math.nan
    return 0.0


def identify(trials: list[Trial], base: WheelParams | None = None,
             library: tuple[Candidate, ...] = LIBRARY, window: float = 1.0, k_folds: int = 5,
             min_gain: float = 0.10, max_effects: int = 2, threads: int = 2,
             analyse_residuals: bool = True) -> Identification:
    """Run the whole identification on ``trials`` (see the module docstring)."""
    base = base or WheelParams()
    friction = coastdown_friction(trials, base)
    start = {"tau_f": friction.tau_f} if friction else {}
    folds = folds_of(len(trials), k_folds)
    current = evaluate(trials, base, (), window, start, folds)
    current.accepted, current.reason = True, "nominal model"
    nominal = current
    chosen: tuple[Candidate, ...] = ()
    rounds: list[list[Evaluation]] = []
    for _ in range(max_effects):
        todo = [c for c in library if c not in chosen]
        if not todo:
            break
        st = dict(start, **current.fit.values)

        def run(c: Candidate) -> Evaluation:
            ev = evaluate(trials, base, chosen + (c,), window, st, folds)
            ev.wald_p = wald_p(ev.fit, c) if c.id != "charge_retention" else \
                _retention_p(ev.fit)
            gain = 1.0 - ev.heldout_rmse / current.heldout_rmse
            ok_gain = gain >= min_gain
            ok_sig = ev.wald_p < 1e-6
            ev.accepted = ok_gain and ok_sig
            ev.reason = (f"held-out RMSE {1e3 * ev.heldout_rmse:.3f} mrad vs "
                         f"{1e3 * current.heldout_rmse:.3f} ({100 * gain:+.1f} %, need "
                         f"{100 * min_gain:.0f} %); Wald p = {ev.wald_p:.1e} (need < 1e-6)")
            return ev

        with ThreadPoolExecutor(max_workers=max(threads, 1)) as pool:
            evs = list(pool.map(run, todo))
        rounds.append(evs)
        good = [e for e in evs if e.accepted]
        if not good:
            break
        best = min(good, key=lambda e: e.heldout_rmse)
        chosen = tuple(next(c for c in library if c.id == i) for i in best.effects)
        current = best
    ident = Identification(friction, nominal, current, rounds)
    if analyse_residuals:
        ident.problem_before = Problem(trials, base, (), window)
        ident.diagnostics_before = analyse(ident.problem_before, nominal.fit)
        ident.problem_after = Problem(trials, base, chosen, window)
        ident.diagnostics_after = analyse(ident.problem_after, current.fit)
    return ident


def _retention_p(fit: FitResult) -> float:
    """Retention is absent when its rate is 0 (its recovery is then undetermined)."""
    i = fit.names.index("rate")
    sd = math.sqrt(max(fit.cov[i, i], 1e-300))
    return float(stats.norm.sf(fit.theta[i] / sd))
