"""Unexplained structure along the actuator index, measured by a refit.

The residual analysis (:mod:`.residual`) bins the acceleration residual by the driven
actuator, but its acceleration is a 0.2 s Savitzky-Golay derivative of the angle residual:
at 3 rad/s one actuator is driven for about 0.13 s, so each bin mixes neighbours and carries
far more noise than one actuator's share; a gain spread left out is then reported as its
first harmonic, a once-per-turn signature that names an off-centre mass.

So, once the search has ended and the periodic signatures are sized, the model is tested for
one force factor per actuator the way the library's effects are, with the fabrication spread's
parameterisation as a measuring device: a score test of the 15 log-factors (:mod:`.screen`)
on the final model plus the strongest periodic torque already reported (a torque fixed to
the wheel angle shows in the actuators too, since actuator i is driven at the same wheel
angles every turn); when its p is under :data:`~.residual.SIGNIFICANCE`, a refit sizes them.
Only one periodic torque can sit beside them (it rides on the model's pivot-lap term), so
factors that follow one harmonic around the wheel, the shadow of a torque fixed to the wheel
angle, are not reported as structure along the actuator index: the same rule that refuses
such gains as a fabrication spread (:func:`~.candidates.spread_pattern`).  Like
:mod:`.periodic`'s torque, the factors are a description, never chosen as an effect and
never written to model.yaml.  The figures behind these rules are in docs/identification.md.
Tested in ``test_ident_effects.py``
(``test_a_gain_spread_outside_the_library_is_reported_along_the_actuator_index``,
``test_a_periodic_torque_that_gains_could_imitate_is_not_forced_onto_them``) and
``test_ident_actuator.py``.
"""
from __future__ import annotations

import math

import numpy as np

from hasel_wheel_sim import layout as L
from hasel_wheel_sim.model import acceleration, contact_at_switch_on
from hasel_wheel_sim.params import WheelParams

from hasel_wheel_ident.candidates import BY_ID, Candidate, SPREAD_PATTERN_P, spread_pattern
from hasel_wheel_ident.data import Trial
from hasel_wheel_ident.fit import FitResult, Problem, wald_p
from hasel_wheel_ident.residual import MIN_AMPLITUDE, SIGNIFICANCE, Signature
from hasel_wheel_ident.screen import screened_refit

#: The measuring device: the fabrication spread's 15 log-factors (their sum over 16 is 0).
FACTORS = BY_ID["gain_spread"]


def driving_acceleration(problem: Problem, fit: FitResult) -> float:
    """Mean acceleration [rad/s^2] the driven actuator gives the wheel while it is on, at
    the model's own trajectory, in the model ``fit`` of ``problem`` (its chosen effects, the
    true switch-on angle and retention as the simulator applies them), with the actuators'
    own force factors (the measuring device's) taken out.

    A time average: each interval from a sample with q = 1 (and valid data) to the next
    sample of the same window counts with its length, at the mean of the actuator's share of
    the acceleration at its two ends (the trapezoid rule).  The share rises steeply through
    a push (the force acts through sin of the contact angle), so the mean of the samples
    alone falls short of the time average; a window's last sample, whose interval the next
    window starts afresh, is left out.  For the
    nominal model this is the speed the wheel gains per second on plus friction's
    deceleration (``test_ident_actuator.py``)."""
    x1, x2 = problem.simulate(fit.z)
    pv, extra = problem.model(problem.full_theta(fit.theta))
    eta = problem.eta + extra.get("eta_offset", 0.0)
    gain = problem.gains(pv) / pv[L.P_GAINS + problem.pad]
    last = np.zeros(problem.t.size, dtype=bool)
    last[problem.starts[1:] - 1] = True
    on = np.flatnonzero((problem.q > 0) & problem.ok & ~last)
    if on.size == 0:
        return math.nan

    def share(i: int, j: int, on_time: float) -> float:
        """The actuator of sample i's share of the acceleration at sample j's state."""
        phi_a = contact_at_switch_on(eta[i], problem.phi_a[i], pv)
        return (acceleration(x1[j], x2[j], 1.0, eta[i], phi_a, gain[i], on_time, pv, 1.0)
                - acceleration(x1[j], x2[j], 0.0, eta[i], phi_a, gain[i], on_time, pv, 1.0))

    total = span = 0.0
    for i in on:
        dt = float(problem.t[i + 1] - problem.t[i])
        total += 0.5 * dt * (share(i, i, problem.on_time[i])
                             + share(i, i + 1, problem.on_time[i] + dt))
        span += dt
    return total / span if span > 0.0 else math.nan


def measure(trials: list[Trial], base: WheelParams, effects: tuple[Candidate, ...],
            fit: FitResult, window: float = 1.0, threads: int = 2
            ) -> tuple[Signature, FitResult] | None:
    """(A signature along the actuator index, the refit that sized it) when one force factor
    per actuator, added to the model (nominal + ``effects``, fitted as ``fit``), is
    significant both by the score test and by the refit's Wald test
    (p < :data:`~.residual.SIGNIFICANCE`), its amplitude reaches
    :data:`~.residual.MIN_AMPLITUDE`, and the factors do not follow one harmonic around the
    wheel (:func:`~.candidates.spread_pattern`; such factors are the shadow of a torque fixed
    to the wheel angle, which the periodograms describe).  None otherwise, or when the model
    already has such factors.

    Its amplitude [rad/s^2] is half the factors' range times the mean acceleration an actuator
    gives while on (:func:`driving_acceleration`); its torque that times J/L [N*m]."""
    if any(c.id == FACTORS.id for c in effects):
        return None
    _, res = screened_refit(trials, base, tuple(effects), fit, FACTORS, window, threads,
                            significance=SIGNIFICANCE)
    if res is None:
        return None
    p = wald_p(res, FACTORS)
    d = np.array([res.values[q.name] for q in FACTORS.params])
    k, share, pattern_p = spread_pattern(d)
    if not (p < SIGNIFICANCE and pattern_p >= SPREAD_PATTERN_P):
        return None
    gains = np.array(FACTORS.describe(d)["gains"])
    problem = Problem(trials, base, tuple(effects) + (FACTORS,), window)
    drive = driving_acceleration(problem, res)
    amp = 0.5 * float(np.ptp(gains)) * drive
    if not amp >= MIN_AMPLITUDE:
        return None
    lo, hi = int(np.argmin(gains)), int(np.argmax(gains))
    inertia = base.inertia
    text = (f"varies with the actuator index: measured with the model as one force factor per "
            f"actuator, std {np.std(gains):.3g}, from {gains[lo]:.3f} (actuator {lo}) to "
            f"{gains[hi]:.3f} (actuator {hi}); half their range is {amp:.3g} rad/s^2 "
            f"({amp * inertia:.2g} N*m) of the {drive:.3g} rad/s^2 an actuator gives while on; "
            f"no one harmonic around the wheel dominates ({100 * share:.0f} % of their variance "
            f"in {k} per turn, p = {pattern_p:.2g} for independent factors)")
    return (Signature("actuator", "index", None, amp, amp * inertia, p, text,
                      factors=tuple(float(g) for g in gains)), res)
