"""Unexplained structure along the actuator index, measured by a refit.

The residual analysis (:mod:`.residual`) bins the acceleration residual by the driven
actuator, but its acceleration is a 0.2 s Savitzky-Golay derivative of the angle residual:
at 3 rad/s one actuator is driven for about 0.13 s, so each bin mixes neighbours and carries
far more noise than one actuator's share.  A gain spread of std 0.1 with its candidate left
out (5 x 60 s, plant seed 11, ad hoc) binned at p = 0.65, and the only structure reported was
its first harmonic, "periodic in wheel angle, 1 per turn", which names an off-centre mass.

So, once the search has ended and the periodic signatures are sized, the model is tested for
one force factor per actuator the way the library's effects are, with the fabrication spread's
parameterisation as a measuring device: a score test of the 15 log-factors (:mod:`.screen`)
on the final model plus the strongest periodic torque already reported (a torque fixed to
the wheel angle shows in the actuators too, since actuator i is driven at the same wheel
angles every turn); when significant, a refit sizes them.  Like :mod:`.periodic`'s torque,
the factors are a description, never chosen as an effect and never written to model.yaml.
Ad hoc, 5 x 60 s, plant seed 11, gain spread not in the library: score chi^2 872 (15 dof) with
a spread of std 0.1; 15 on data without an effect, 33 to 50 with a viscous drag, a 40 ms rise
lag or retention of 0.2/s left out.
"""
from __future__ import annotations

import math

import numpy as np
from scipy import stats

from hasel_wheel_sim.model import acceleration, param_vector
from hasel_wheel_sim.params import WheelParams

from .candidates import BY_ID, Candidate, spread_pattern, SPREAD_PATTERN_P
from .data import Trial
from .fit import FitResult, Problem, force_coordinates
from .residual import SIGNIFICANCE, Signature
from .screen import screen

#: Evaluations of the sizing refit (it starts from the score test's step).
MAX_EVALUATIONS = 30
FACTORS = BY_ID["gain_spread"]


def driving_acceleration(problem: Problem, fit: FitResult) -> float:
    """Mean acceleration [rad/s^2] the driven actuator gives the wheel while it is on, in the
    model ``fit`` of ``problem`` (its force law at the model's own trajectory)."""
    x1, x2 = problem.simulate(fit.z)
    pv = param_vector(fit.params)
    on = np.flatnonzero((problem.q > 0) & problem.ok)
    if on.size == 0:
        return math.nan
    total = 0.0
    for i in on:
        total += (acceleration(x1[i], x2[i], 1.0, problem.eta[i], problem.phi_a[i], 1.0,
                               problem.on_time[i], pv, 1.0)
                  - acceleration(x1[i], x2[i], 0.0, problem.eta[i], problem.phi_a[i], 1.0,
                                 problem.on_time[i], pv, 1.0))
    return total / on.size


def measure(trials: list[Trial], base: WheelParams, effects: tuple[Candidate, ...],
            fit: FitResult, window: float = 1.0, threads: int = 2
            ) -> tuple[Signature, FitResult] | None:
    """(A signature along the actuator index, the refit that sized it) when one force factor
    per actuator, added to the model (nominal + ``effects``, fitted as ``fit``), is
    significant both by the score test and by the refit's Wald test
    (p < :data:`~.residual.SIGNIFICANCE`); None otherwise, or when the model already has
    such factors.

    Its amplitude [rad/s^2] is half the factors' range times the mean acceleration an actuator
    gives while on (:func:`driving_acceleration`); its torque that times J/L [N*m]."""
    if any(c.id == FACTORS.id for c in effects):
        return None
    current = Problem(trials, base, tuple(effects), window)
    reference = dict(force_coordinates(base), tau_f=fit.values.get("tau_f", base.tau_f))
    sc = screen(trials, base, tuple(effects), fit, current, FACTORS, window, reference)
    if sc.p_value >= SIGNIFICANCE:
        return None
    problem = Problem(trials, base, tuple(effects) + (FACTORS,), window, threads=threads)
    res = problem.fit(start=sc.start, x0=fit.z[fit.theta.size:].reshape(-1, 2),
                      max_nfev=MAX_EVALUATIONS)
    idx = [res.names.index(p.name) for p in FACTORS.params]
    d = res.theta[idx]
    try:
        chi2 = float(d @ np.linalg.solve(res.cov[np.ix_(idx, idx)], d))
    except np.linalg.LinAlgError:
        return None
    p = float(stats.chi2.sf(chi2, len(idx)))
    if p >= SIGNIFICANCE:
        return None
    gains = np.exp(np.concatenate(([-np.sum(d)], d)))
    drive = driving_acceleration(problem, res)
    amp = 0.5 * float(np.ptp(gains)) * drive
    lo, hi = int(np.argmin(gains)), int(np.argmax(gains))
    k, share, pattern_p = spread_pattern(d)
    shape = (f"{100 * share:.0f} % of their variance in {k} per wheel turn: a pattern fixed to "
             f"the wheel angle more than independent actuators"
             if pattern_p < SPREAD_PATTERN_P else
             f"no one harmonic around the wheel dominates ({100 * share:.0f} % in {k} per "
             f"turn, p = {pattern_p:.2g} for independent factors)")
    inertia = base.inertia
    text = (f"varies with the actuator index: measured with the model as one force factor per "
            f"actuator, std {np.std(gains):.3g}, from {gains[lo]:.3f} (actuator {lo}) to "
            f"{gains[hi]:.3f} (actuator {hi}); half their range is {amp:.3g} rad/s^2 "
            f"({amp * inertia:.2g} N*m) of the {drive:.3g} rad/s^2 an actuator gives while on; "
            f"{shape}; Wald chi^2 {chi2:.0f} on {len(idx)} dof")
    return (Signature("actuator", "index", None, amp, amp * inertia, p, text,
                      factors=tuple(float(g) for g in gains)), res)
