"""The size of an unexplained periodic signature, measured by a refit.

The residual analysis (:mod:`.residual`) finds a periodic structure in what the fitted model
leaves, and sizes it from that residual.  But the fit had already bent the model (the force
law's shape, friction) to take up part of the structure before the residual was looked at,
so the residual shows less than all of it.  Here the structure is measured the way the
library's effects are: a torque periodic along the same axis with the same period,

    tau = P sin(k xi1) + Q cos(k xi1)          P, Q [N*m], k = 2 pi / (its period in xi1)

is added to the model and refitted together with everything else; its amplitude
hypot(P, Q) and the phase atan2(Q, P) replace the residual's figures.  This term is a
measuring device, not an explanation: it is never chosen as an effect and never goes into
``model.yaml``.  It rides on the model's pivot-lap term (the frequency in its ``r/L`` slot),
so it is not used when that term is already part of the model.  Tested in
``test_ident_candidates.py`` (``test_the_signature_term_is_the_torque_it_names``),
``test_ident_residual.py``
(``test_a_period_is_confirmed_by_its_refits_wald_test_against_the_closed_form``) and
``test_ident_effects.py`` (``test_an_effect_outside_the_library_is_reported_not_forced``).
"""
from __future__ import annotations

import dataclasses
import math

from hasel_wheel_sim import layout as L
from hasel_wheel_sim.params import WheelParams

from hasel_wheel_ident.candidates import Candidate, ParamSpec
from hasel_wheel_ident.data import Trial
from hasel_wheel_ident.fit import FitResult, wald_p
from hasel_wheel_ident.residual import MIN_AMPLITUDE, SIGNIFICANCE, Signature
from hasel_wheel_ident.screen import screened_refit

#: Signature axes whose period this module can turn into a frequency along xi1.
ANGLE_AXES = ("wheel_angle", "pivot_angle", "wheel_angle_unwrapped")


def frequency(sig: Signature, base: WheelParams) -> float | None:
    """k [1/rad]: cycles of ``sig`` per radian of wheel angle xi1, times 2 pi; None when the
    signature is not periodic along an angle."""
    if sig.period is None or sig.axis not in ANGLE_AXES or sig.period <= 0.0:
        return None
    k = 2 * math.pi / sig.period
    return k * base.r / base.L if sig.axis == "pivot_angle" else k


def periodic_torque(k: float) -> Candidate:
    """A torque P sin(k xi1) + Q cos(k xi1) [N*m] as a candidate-like term (not in the library)."""
    def apply(x, pv, extra):
        pv[L.P_PIVOT_RATIO] = k
        pv[L.P_PLATFORM_TORQUE] = math.hypot(x[0], x[1])
        pv[L.P_PLATFORM_PHASE] = math.atan2(x[1], x[0])

    return Candidate(f"periodic_torque_{k:.6g}", "a torque periodic in the wheel angle",
                     (ParamSpec("P_sig", "N*m", 0.0, -0.5, 0.5, 1e-3),
                      ParamSpec("Q_sig", "N*m", 0.0, -0.5, 0.5, 1e-3)), apply,
                     lambda x: {"torque_N_m": math.hypot(x[0], x[1]),
                                "phase_rad": math.atan2(x[1], x[0])}, "wheel_angle_unwrapped")


def confirmed(sig: Signature) -> bool:
    """False for a signature sized by a refit (:func:`sized`) whose Wald test does not reach
    :data:`~.residual.SIGNIFICANCE` or whose amplitude is under
    :data:`~.residual.MIN_AMPLITUDE` [rad/s^2]: the model refitted with that torque does
    not need it (a drift can make the residual's periodograms name periods that are not
    there).  True for every other signature."""
    if sig.torque_ci95 is None:
        return True
    return sig.p_value < SIGNIFICANCE and sig.amplitude >= MIN_AMPLITUDE


def measure(sig: Signature, trials: list[Trial], base: WheelParams,
            effects: tuple[Candidate, ...], fit: FitResult, window: float = 1.0,
            threads: int = 2) -> tuple[Signature, FitResult | None, Candidate | None]:
    """(``sig`` sized by a refit of the model (nominal + ``effects``, fitted as ``fit``) plus
    :func:`periodic_torque` at its period (:func:`sized`), that refit, the torque term); or
    (``sig``, None, None) unchanged when it is not periodic along an angle or the model
    already has a pivot-lap term.  The refit starts where the score test's step predicts
    the lower error (:func:`~.screen.screened_refit`): from the refitted model the torque
    creeps towards its size over many evaluations, from the reference force law it reaches
    it in a few."""
    k = frequency(sig, base)
    if k is None or any(c.id == "platform_periodic" for c in effects):
        return sig, None, None
    term = periodic_torque(k)
    _, res = screened_refit(trials, base, tuple(effects), fit, term, window, threads)
    return sized(sig, res, k, base), res, term


def sized(sig: Signature, res: FitResult, k: float, base: WheelParams) -> Signature:
    """``sig`` sized by ``res``, a fit of a model with :func:`periodic_torque` ``(k)`` in it:
    amplitude [rad/s^2], torque [N*m] with its 95 % interval, phase [rad], and as its
    p-value the Wald test's of "P = Q = 0" in that fit (2 dof)."""
    p, q = res.values["P_sig"], res.values["Q_sig"]
    torque = math.hypot(p, q)
    # 95 % interval of the amplitude from the fit's covariance (delta method)
    i, j = res.names.index("P_sig"), res.names.index("Q_sig")
    grad = [p / torque, q / torque] if torque > 0 else [1.0, 0.0]
    var = (grad[0] ** 2 * res.cov[i, i] + 2 * grad[0] * grad[1] * res.cov[i, j]
           + grad[1] ** 2 * res.cov[j, j])
    half = 1.96 * math.sqrt(max(var, 0.0))
    inertia = base.inertia
    text = (f"{sig.text.split(', amplitude')[0]}, amplitude {torque / inertia:.3g} rad/s^2 "
            f"({torque:.3g} N*m, 95 % {max(torque - half, 0.0):.3g} to {torque + half:.3g}; "
            f"phase {math.atan2(q, p):.3g} rad; fitted with the model as a torque "
            f"P sin(k xi1) + Q cos(k xi1), k = {k:.4g}/rad)")
    return dataclasses.replace(sig, amplitude=torque / inertia, torque=torque, text=text,
                               p_value=wald_p(res, periodic_torque(k)),
                               phase=math.atan2(q, p),
                               torque_ci95=(max(torque - half, 0.0), torque + half))
