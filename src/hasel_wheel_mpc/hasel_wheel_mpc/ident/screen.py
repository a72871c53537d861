"""Screening the candidate library: every candidate added to the current model and refitted
by one Gauss-Newton step (a score test), so that only the promising ones need a full fit
and cross-validation.

At a converged fit of the current model the gradient of its own parameters is zero.  Adding
a candidate and taking one Gauss-Newton step in all parameters (the window starts projected
out) predicts how far the squared error would fall:

    delta = r' J (J' J)^+ J' r              J (n, g + k) projected Jacobian, r (n,) residual

Under "the candidate is absent", delta / (s^2 x inflation) follows chi^2 with k degrees of
freedom (Rao's score test), s^2 the residual variance and the inflation the factor for the
residual's autocorrelation (:func:`~.fit.autocorrelation_inflation`).  An effect whose
derivative vanishes at its null value (a rise time of 0) is screened at its start value
instead, where it has a gradient; the step is then predicted from there.

Each candidate is screened from two places: the current model's parameters and the
reference force law (with the current tau_f).  A model that bent its force law to mimic a
missing effect can sit far from where the true force law and that effect together are best;
the full fit starts from whichever place predicts the lower error.  A candidate far from
linear in its parameters is also screened at the further values it lists
(``Candidate.screen_at``), from both places.  A 50 ms rise lag on 3 x 34 s, which the
nominal force law half absorbs, scored chi^2 8 from a rise time of 5 ms and 227 once 20 and
60 ms were added; refitted, it cut the held-out simulation error 3.8x, tau within 2 % (ad-hoc
runs; test_ident_effects.py asserts it is named, within 10 %, the error at least halved).  The statistic is the
best place's, not corrected for trying several: it only chooses what to refit, and the
refit's held-out errors and Wald test decide.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

from hasel_wheel_sim.params import WheelParams

from .candidates import Candidate
from .data import Trial
from .fit import FitResult, ParameterError, Problem
from .threads import with_one_blas_thread


@dataclass
class Screening:
    """One candidate's score test against the current model."""

    candidate: str
    dof: int                       # the candidate's parameter count
    statistic: float               # delta / (s^2 x inflation)
    p_value: float                 # chi^2(dof) survival of the statistic
    log10_p: float                 # its log10 (finite where p underflows to 0)
    predicted_rmse: float          # [rad] after the Gauss-Newton step
    start: dict[str, float]        # where a full fit should start (parameter name -> value)


@with_one_blas_thread
def screen(trials: list[Trial], base: WheelParams, chosen: tuple[Candidate, ...],
           current: FitResult, current_problem: Problem, candidate: Candidate,
           window: float, reference: dict[str, float]) -> Screening:
    """Score test of ``candidate`` added to the model ``chosen`` fitted as ``current``.

    ``reference`` holds the second start's values (the reference force law, the current
    tau_f).  The window starts of ``current`` warm-start both."""
    prob = Problem(trials, base, chosen + (candidate,), window)
    x_start = current_problem.window_starts(current.z)
    n_used = int(prob.ok.sum())
    sse0 = current.rmse ** 2 * n_used
    s2, inflation = current_problem.noise(current_problem.residual(current.z),
                                          len(current.names))
    best: tuple[float, np.ndarray, np.ndarray, float] | None = None
    places = [current.values, {**reference, **{k: v for k, v in current.values.items()
                                               if k not in reference}}]
    places += [{**place, **at} for at in candidate.screen_at for place in places[:2]]
    for values in places:
        theta = np.array([values.get(prob.specs[i].name, prob.specs[i].start)
                          for i in prob.free])
        x0, r, d1, d2 = prob.solve_starts(prob.full_theta(theta), x_start)
        J = prob.jacobian(theta, x0, r, d1, d2)
        scale = np.array([prob.specs[i].scale for i in prob.free])
        coef, *_ = np.linalg.lstsq(J * scale, r, rcond=1e-10)
        fitted = (J * scale) @ coef
        sse = float(r @ r - fitted @ fitted)
        if best is None or sse < best[0]:
            lo = np.array([prob.specs[i].lower for i in prob.free])
            hi = np.array([prob.specs[i].upper for i in prob.free])
            best = (sse, theta, np.clip(theta - scale * coef, lo, hi), float(r @ r))
    sse, theta, stepped, sse_here = best
    # the full fit starts from the better place for the force law (one linearised step can
    # overshoot its strongly nonlinear bump) and from the step for the candidate's own
    # parameters, clipped into their bounds and shortened until the error it gives is no
    # worse than with them at their start values (a rise time stepped to its bound can make
    # the error 30x worse, and a fit started there wanders)
    own = np.array([prob.names.index(p.name) for p in candidate.params if p.name in prob.names],
                   dtype=int)
    trial = theta.copy()
    for shrink in range(6):                                  # step x 1, 1/4, ..., 1/1024
        trial[own] = theta[own] + (stepped[own] - theta[own]) * 0.25 ** shrink
        try:
            _, r_try, _, _ = prob.solve_starts(prob.full_theta(trial), x_start)
        except ParameterError:
            continue
        if float(r_try @ r_try) <= sse_here:
            break
    else:
        trial[own] = theta[own]
    start = {nm: float(v) for nm, v in zip(prob.names, trial)}
    delta = max(sse0 - sse, 0.0)
    statistic = delta / (s2 * inflation)
    return Screening(candidate.id, candidate.size, statistic,
                     float(stats.chi2.sf(statistic, candidate.size)),
                     float(stats.chi2.logsf(statistic, candidate.size) / math.log(10.0)),
                     math.sqrt(max(sse, 0.0) / n_used), start)
