"""Screening the candidate library: every candidate added to the current model and refitted
by one Gauss-Newton step (a score test), so that only the promising ones need a full fit
and cross-validation.

At a converged fit of the current model the gradient of its own parameters is zero.  Adding
a candidate and taking one Gauss-Newton step in all parameters (the window starts projected
out) predicts how far the squared error would fall:

    delta = r' J (J' J)^+ J' r              J (n, g + k) projected Jacobian, r (n,) residual

Under "the candidate is absent", delta / (s^2 x inflation) follows chi^2 with k degrees of
freedom (Rao's score test), s^2 the residual variance and the inflation the factor for the
residual's autocorrelation (:func:`~.uncertainty.autocorrelation_inflation`).  An effect whose
derivative vanishes at its null value (a rise time of 0) is screened at its start value
instead, where it has a gradient; the step is then predicted from there.

Each candidate is screened from two places: the current model's parameters and the
reference force law (with the current tau_f).  A model that bent its force law to mimic a
missing effect can sit far from where the true force law and that effect together are best;
the full fit starts from whichever place predicts the lower error.  A candidate far from
linear in its parameters is also screened at the further values it lists
(``Candidate.screen_at``), from both places: a rise lag that the nominal force law half
absorbs scores little from a rise time near zero and far more from the rise times it lists.

One Gauss-Newton step predicts well only near the optimum.  A candidate with a ``scan`` grid
(the rise lag: 10 ms to 0.32 s in factors of 2) is also evaluated, not predicted, at every
grid value from both places; where the error falls significantly at a place alone, a short
fit from the best grid value gives one more place (:func:`scan_places`).  A slow rise lag
that the nominal fit bends its force law to mimic is then found where one step from either
place predicts little; on data without the effect the scan finds nothing significant and
adds no fit (``test_ident_effects.py``:
``test_a_slow_rise_lag_that_the_force_law_bends_to_mimic_is_found_by_the_scan``).

A current fit that looks bent (:func:`bent`: it stopped at its evaluation limit, or a
nominal parameter ended on a bound) gets one more place per candidate: a short fit
(:data:`RESTART_NFEV` evaluations) of the model with the candidate, from the reference force
law, tau_f and braking gain.  In a closed loop the pushes and brakes answer a disturbance,
so the nominal force law can take much of it up and end bent, where one step predicts
nothing; the short fit from the reference reaches the noise floor and names the effect
(``test_ident_effects.py``:
``test_a_torque_a_closed_loop_leans_against_is_found_from_the_reference_force_law``,
``test_strong_retention_that_bends_the_nominal_fit_is_screened_from_the_reference_law``).
The place counts with the error its fit reached (:func:`short_fit`), and the current
model's own short fit from the same values (:func:`restart_from`, once per round) sets the
baseline where it is lower than the current fit's, so that a candidate is not credited with
what the restart alone gains.  A fit that converged inside its ranges does not get this
place, nor does one on trials with coast-downs that only stopped unconverged
(:meth:`~.search.Search._screen`: there the steps, the scan and the second start name the
effects, and the short fits only cost time).

The statistic is the best place's, not corrected for trying several: it only chooses what
to refit, and the refit's held-out errors and Wald test decide.  (The scan's short fit makes
it close to a likelihood-ratio statistic, which has the same chi^2 law under "absent".)
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

from hasel_wheel_sim.params import ParameterError, WheelParams

from hasel_wheel_ident.candidates import Candidate
from hasel_wheel_ident.data import Trial
from hasel_wheel_ident.fit import FitResult, Problem, force_coordinates
from hasel_wheel_ident.threads import with_one_blas_thread


SCREEN_P = 1e-6     # score-test p-value below which a candidate is refitted in full
SCAN_NFEV = 8       # evaluations of the short fit from a scan's best point
RESTART_NFEV = 4    # evaluations of the short fits from a Restart (a bent fit's candidates)


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
    scanned: bool = False          # the best place was found by the scan (:func:`scan_places`)
    restarted: bool = False        # the best place was the short fit from a :class:`Restart`


@dataclass(frozen=True)
class Restart:
    """Where the candidates of a bent fit (:func:`bent`) are also fitted from, briefly.

    ``values``: parameter name -> start value (the reference force law, tau_f, braking
    gain); ``sse`` [rad^2]: the squared window error the current model itself reaches by the
    same short fit from there (:func:`restart_from`).  Where that is below the current fit's
    own, it is the baseline of every score, so that a candidate is not credited with what
    the restart alone gains."""

    values: dict[str, float]
    sse: float


def _sse(prob: Problem, values: dict[str, float], x_start: np.ndarray) -> float:
    """Squared window error [rad^2] with the parameters at ``values`` (start values for the
    rest); inf outside the physical ranges."""
    theta = np.array([values.get(prob.specs[i].name, prob.specs[i].start) for i in prob.free])
    try:
        _, r, _, _ = prob.solve_starts(prob.full_theta(theta), x_start)
    except ParameterError:
        return math.inf
    return float(r @ r)


def scan_places(prob: Problem, candidate: Candidate, places: list[dict[str, float]],
                x_start: np.ndarray, significant: float) -> list[dict[str, float]]:
    """Further places to screen ``candidate`` from, found by its ``scan`` grid.

    At each of ``places`` the squared window error is evaluated along the grid, outward from
    the start value (the other parameters held at the place), until it has risen by more than
    ``significant`` above the lowest so far: past that minimum it rose on, in every profile
    seen (a rise lag's error at a fixed force law).  Where the lowest lies below the error with the
    candidate at its start value by more than ``significant`` [rad^2] (the score test's
    critical drop), the effect is there at that place alone, and a short fit of every
    parameter (:data:`SCAN_NFEV` evaluations) from that grid value gives a place close
    enough to the optimum for the Gauss-Newton step.  ``x_start`` (w, 2) warm-starts the
    window starts.  Returns the short fits' values, one dict per place where the scan found
    the effect (none on data without it, so nothing is spent there)."""
    found: list[dict[str, float]] = []
    if not candidate.scan:
        return found
    for place in places:
        null = sse = _sse(prob, place, x_start)
        at = None
        for g in candidate.scan:
            e = _sse(prob, {**place, **g}, x_start)
            if e < sse:
                sse, at = e, g
            elif e > sse + significant:
                break               # past the lowest: the error rises from here on
        if at is not None and null - sse > significant:
            found.append(prob.fit(start={**place, **at}, x0=x_start, max_nfev=SCAN_NFEV).values)
    return found


@with_one_blas_thread
def screen(trials: list[Trial], base: WheelParams, chosen: tuple[Candidate, ...],
           current: FitResult, current_problem: Problem, candidate: Candidate,
           window: float, reference: dict[str, float], restart: Restart | None = None,
           noise: tuple[float, float] | None = None) -> Screening:
    """Score test of ``candidate`` added to the model ``chosen`` fitted as ``current``.

    ``reference`` holds the second start's values (the reference force law, the current
    tau_f).  The window starts of ``current`` warm-start both.  ``restart`` (given when the
    current fit is bent: :func:`bent`) is one more place: a short fit
    (:data:`RESTART_NFEV` evaluations) of the model with the candidate from its values, which
    counts with the error it reached.  ``noise``: the current fit's (residual variance
    [rad^2], inflation) from :meth:`~.fit.Problem.noise`, computed here when None (give it
    when screening from several threads: ``current_problem`` is not thread-safe)."""
    prob = Problem(trials, base, chosen + (candidate,), window)
    x_start = current_problem.window_starts(current.z)
    n_used = int(prob.ok.sum())
    sse0 = current.rmse ** 2 * n_used
    if restart is not None:
        sse0 = min(sse0, restart.sse)
    s2, inflation = noise or current_problem.noise(current_problem.residual(current.z),
                                                   len(current.names))
    best: tuple[float, np.ndarray, np.ndarray, float, bool] | None = None
    places = [current.values, {**reference, **{k: v for k, v in current.values.items()
                                               if k not in reference}}]
    places += [{**place, **at} for at in candidate.screen_at for place in places[:2]]
    n_given = len(places)
    places += scan_places(prob, candidate, places[:2], x_start,
                          stats.chi2.isf(SCREEN_P, candidate.size) * s2 * inflation)
    for k, values in enumerate(places):
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
            best = (sse, theta, np.clip(theta - scale * coef, lo, hi), float(r @ r),
                    k >= n_given)
    assert best is not None
    restarted = False
    if restart is not None:
        # the short fit's own error, not a step predicted from it: from that far a linear
        # step can promise a drop that no fit delivers
        f, sse_f = short_fit(prob, current.values, restart.values, x_start)
        if sse_f < best[0]:
            best = (sse_f, f.theta, f.theta, sse_f, False)
            restarted = True
    sse, theta, stepped, sse_here, scanned = best
    # the full fit starts from the better place for the force law (one linearised step can
    # overshoot its strongly nonlinear bump) and from the step for the candidate's own
    # parameters, clipped into their bounds and shortened until the error it gives is no
    # worse than with them at their start values (a rise time stepped to its bound can make
    # the error 30x worse, and a fit started there wanders)
    own = np.array([prob.names.index(p.name) for p in candidate.params if p.name in prob.names],
                   dtype=int)
    trial = theta.copy()
    for shrink in range(0 if restarted else 6):              # step x 1, 1/4, ..., 1/1024
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
                     math.sqrt(max(sse, 0.0) / n_used), start, scanned, restarted)


def short_fit(prob: Problem, current: dict[str, float], values: dict[str, float],
              x_start: np.ndarray) -> tuple[FitResult, float]:
    """The short fit (:data:`RESTART_NFEV` evaluations) of ``prob`` from ``values`` (the
    current fit's ``current`` values for the rest), warm-started at the window starts
    ``x_start``; and its squared window error [rad^2]."""
    f = prob.fit(start={**current, **values}, x0=x_start, max_nfev=RESTART_NFEV)
    return f, f.rmse ** 2 * int(prob.ok.sum())


def restart_from(problem: Problem, fit: FitResult, values: dict[str, float]) -> Restart:
    """The :class:`Restart` at ``values`` for the model of ``problem`` fitted as ``fit``: the
    squared window error [rad^2] its own :func:`short_fit` from ``values`` reaches."""
    _, sse = short_fit(problem, fit.values, values, problem.window_starts(fit.z))
    return Restart(dict(values), sse)


def bent(problem: Problem, fit: FitResult) -> str | None:
    """Why ``fit`` (of ``problem``) looks bent by something its model lacks: it stopped at its
    evaluation limit, or a nominal parameter ended on a bound of its range; None otherwise."""
    why = [] if fit.converged else [f"stopped unconverged after {fit.nfev} evaluations"]
    edge = problem.at_bounds(fit)
    if edge:
        why.append(f"{', '.join(edge)} on {'its bound' if len(edge) == 1 else 'their bounds'}")
    return "; ".join(why) or None


#: Evaluations of a sizing refit started from a score test's step (:func:`screened_refit`).
SIZING_EVALUATIONS = 30


def screened_refit(trials: list[Trial], base: WheelParams, effects: tuple[Candidate, ...],
                   fit: FitResult, term: Candidate, window: float = 1.0, threads: int = 2,
                   significance: float = 1.0) -> tuple[Screening, FitResult | None]:
    """``term`` added to the model (nominal + ``effects``, fitted as ``fit``): its score test
    (:func:`screen`, from the fit and from the reference force law), and, when that test's p
    is under ``significance``, a short refit (:data:`SIZING_EVALUATIONS`) from its step with
    the window starts of ``fit``; None in its place otherwise.  For measuring terms that
    describe unexplained structure (:mod:`.periodic`, :mod:`.actuator`): a model that bent
    its force law to take up the structure sits far from where the law and the term together
    are best, and from there a refit creeps."""
    current = Problem(trials, base, tuple(effects), window)
    reference = dict(force_coordinates(base), tau_f=fit.values.get("tau_f", base.tau_f))
    sc = screen(trials, base, tuple(effects), fit, current, term, window, reference)
    if not sc.p_value < significance:
        return sc, None
    problem = Problem(trials, base, tuple(effects) + (term,), window, threads=threads)
    return sc, problem.fit(start=sc.start, x0=fit.x0,
                           max_nfev=SIZING_EVALUATIONS)
