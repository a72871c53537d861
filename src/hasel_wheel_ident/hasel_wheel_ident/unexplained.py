"""What the final model leaves unexplained, sized and described: a drift measured beside
each measuring device (:mod:`.measuring_devices`), periodic signatures sized by a refit
(:mod:`.periodic`), one force factor per actuator (:mod:`.actuator`), and what the library's
refused effects say the structure is not.  A description, never a name."""
from __future__ import annotations

import math
from collections.abc import Callable

from hasel_wheel_ident import actuator, periodic
from hasel_wheel_ident.candidates import Candidate
from hasel_wheel_ident.data import Trial
from hasel_wheel_ident.device_verdict import devices_verdict, lead_device
from hasel_wheel_ident.evaluation import Evaluation
from hasel_wheel_ident.fit import FitResult, wald_p
from hasel_wheel_ident.friction_trend import FrictionTrend
from hasel_wheel_ident.session_trend import SESSION_AXES
from hasel_wheel_ident.identification import Identification
from hasel_wheel_ident.measuring_devices import (DEVICE_TREND_AXIS, DEVICE_WORDS, HV_LOSS,
                                                 ON_LAG, can_measure_beside, can_measure_lag,
                                                 refit_beside)
from hasel_wheel_ident.metrics import drift_text, fitted_metrics, pooled_rmse
from hasel_wheel_ident.refusals import Refusals
from hasel_wheel_ident.residual import (TREND_SIGNIFICANCE, Signature, Trend, along_p,
                                        autocorrelation_signature, drift_along)
from hasel_wheel_sim.params import WheelParams

#: Unexplained periodic signatures sized by a refit (:mod:`.periodic`), strongest first.
MEASURED_SIGNATURES = 3

#: Evaluation limit of each refit of both devices together (:func:`devices_together`): each
#: starts from one device's converged refit and adds one parameter.
TOGETHER_NFEV = 30

#: (effects, their fit): a model with or without a measuring device beside it
Measuring = tuple[tuple[Candidate, ...], FitResult]
Say = Callable[[str], None]


def drift_signature(sig: Signature) -> bool:
    """Whether ``sig`` is a drift during the drives along one of the trend axes (time, HV
    time, speed; :func:`~.residual.drive_trend`)."""
    return sig.drift


def device_axis(sig: Signature, trend: Trend | None, min_gain: float) -> str | None:
    """The axis to report the drift ``sig`` (the signature of ``trend``) along in place of
    the one the regression read, or None to keep it: the axis
    (:data:`~.measuring_devices.DEVICE_TREND_AXIS`) of the device that takes up the most of it
    (:func:`~.device_verdict.lead_device` with ``min_gain`` [1]), when it differs from
    ``sig``'s and the trend along it is significant (:func:`~.residual.along_p` under
    :data:`~.residual.TREND_SIGNIFICANCE`).  Tested in ``test_ident_residual.py``."""
    axis = DEVICE_TREND_AXIS.get(lead_device(sig.devices, min_gain))
    if (axis is None or trend is None or axis == sig.axis
            or along_p(trend, axis) >= TREND_SIGNIFICANCE):
        return None
    return axis


def describe_unexplained(ident: Identification, chosen: tuple[Candidate, ...],
                         current: Evaluation, refusals: Refusals, min_gain: float, say: Say,
                         threads: int) -> None:
    """Size and describe what the final model (``chosen``, fitted as ``current``) leaves
    unexplained, in ``ident.diagnostics_after.signatures`` (changed in place; periodic
    signatures a refit does not confirm go to ``ident.unconfirmed``).  ``refusals`` tells
    what the structure is not; ``min_gain`` [1] is the search's bar."""
    measuring: Measuring = (chosen, current.fit)
    if any(drift_signature(s) for s in ident.diagnostics_after.signatures):
        measuring = _measure_drift(ident, chosen, current, min_gain, say, threads)
    _size_beside(ident, chosen, measuring, say, threads)
    _set_apart_unconfirmed(ident, current)
    _note_what_it_is_not(ident, chosen, refusals)
    trend = ident.friction_trend
    if trend is not None and trend.significant:
        # the coast-downs name what the trials' change along the session only shows
        sigs = ident.diagnostics_after.signatures
        sigs[:] = [s for s in sigs if s.axis not in SESSION_AXES]
        sigs.append(session_signature(trend, ident.base))


def session_signature(trend: FrictionTrend, base: WheelParams) -> Signature:
    """The friction trend ``trend`` as a signature along session time (axis
    ``session_time``, unit s, not periodic): torque half the change of tau_f over the
    coast-downs' span [N*m], amplitude the deceleration it makes, (r + L)/L tau / (J/L)
    [rad/s^2]; the model has no effect for it, so it stays unexplained."""
    torque = 0.5 * abs(trend.slope) * trend.span
    amplitude = torque * (base.r + base.L) / base.L / base.inertia
    return Signature("session_time", "s", None, amplitude, torque, trend.p, trend.text())


def _measure_drift(ident: Identification, chosen: tuple[Candidate, ...], current: Evaluation,
                   min_gain: float, say: Say, threads: int) -> Measuring:
    """Refit each measuring device that can go beside the model, alone and together, note
    what each takes up of the drift, and return the model the periodic signatures are sized
    beside: with the device that takes up the most (the HV-time loss when none does)."""
    sigs = ident.diagnostics_after.signatures
    devices = [d for d, can in ((HV_LOSS, can_measure_beside(chosen)),
                                (ON_LAG, can_measure_lag(chosen))) if can]
    alone, measuring = _devices_alone(ident, chosen, current, devices, say, threads)
    together = devices_together(ident.trials, ident.base, chosen, alone, ident.window,
                                threads, say)
    if together is not None:
        for sig in sigs:
            if drift_signature(sig):
                for device in devices:
                    if device.id in sig.devices:
                        sig.devices[device.id]["wald_p_together"] = wald_p(together, device)
    trend = ident.diagnostics_after.trend
    for sig in list(sigs):
        if len(sig.devices) > 1:
            sig.text += "; " + devices_verdict(sig.devices, min_gain)
            axis = device_axis(sig, trend, min_gain)
            if axis is not None:
                drift_along(sig, trend, axis, "the device for it takes up the most")
                sigs[:] = [s for s in sigs if s is sig or s.axis != axis]
    lead = next((lead_device(s.devices, min_gain) for s in sigs if drift_signature(s)), None)
    if lead == ON_LAG.id and ON_LAG.id in alone:
        measuring = (chosen + (ON_LAG,), alone[ON_LAG.id])
    return measuring


def _devices_alone(ident: Identification, chosen: tuple[Candidate, ...], current: Evaluation,
                   devices: list[Candidate], say: Say, threads: int
                   ) -> tuple[dict[str, FitResult], Measuring]:
    """(Device id -> its finite refit beside the model, the model with the HV-time loss
    beside it when that refit is finite, else the model alone); each drift signature gets
    the device's figures in ``devices`` and a sentence in ``text``."""
    trials, sigs = ident.trials, ident.diagnostics_after.signatures
    e_model = pooled_rmse(current.sim_fitted)
    alone: dict[str, FitResult] = {}
    measuring: Measuring = (chosen, current.fit)
    for device in devices:
        noun, words = DEVICE_WORDS[device.id]
        say(f"refitting with {noun} beside the unexplained drift (a measuring device)")
        problem, device_fit = refit_beside(trials, ident.base, chosen, current.fit, device,
                                           ident.window, threads)
        value = device_fit.values[device.params[0].name]
        p = wald_p(device_fit, device)
        e = pooled_rmse(fitted_metrics(problem, device_fit, trials))
        if not (math.isfinite(value) and math.isfinite(e)):
            continue                # a refit that failed measures nothing
        alone[device.id] = device_fit
        if device is HV_LOSS:
            measuring = (chosen + (HV_LOSS,), device_fit)
        for sig in sigs:
            if drift_signature(sig):
                sig.devices[device.id] = {"value": value, "unit": device.params[0].unit,
                                          "wald_p": p, "sim_rmse_rad_s": e,
                                          "sim_rmse_model_rad_s": e_model}
                sig.text += (f"; with {noun} beside the model ({words(value)}, a "
                             f"measuring device, never named; Wald p {p:.1e}), the free "
                             f"run on all trials is {e:.4f} rad/s against {e_model:.4f}")
    return alone, measuring


def devices_together(trials: list[Trial], base: WheelParams, chosen: tuple[Candidate, ...],
                     alone: dict[str, FitResult], window: float, threads: int,
                     say: Say) -> FitResult | None:
    """The final model (``chosen``) with both measuring devices beside it, or None unless
    each was refitted alone (``alone``: device id -> that refit).  Fitted from each device's
    refit with the other added at its start value; the better window fit is kept; None
    when neither is finite."""
    if set(alone) != {HV_LOSS.id, ON_LAG.id}:
        return None
    say("refitting with both measuring devices beside the unexplained drift")
    fits = [refit_beside(trials, base, chosen + (first,), alone[first.id], second, window,
                         threads, TOGETHER_NFEV)[1]
            for first, second in ((HV_LOSS, ON_LAG), (ON_LAG, HV_LOSS))]
    fits = [f for f in fits if math.isfinite(f.rmse)]
    return min(fits, key=lambda f: f.rmse) if fits else None


def _size_beside(ident: Identification, chosen: tuple[Candidate, ...], measuring: Measuring,
                 say: Say, threads: int) -> None:
    """Size the strongest periodic signatures beside ``measuring``, then one force factor
    per actuator beside the strongest periodic torque, and say when a measuring device was
    beside them."""
    trials, base, window = ident.trials, ident.base, ident.window
    sigs = ident.diagnostics_after.signatures
    todo = [i for i, sig in enumerate(sigs) if periodic.frequency(sig, base)][:MEASURED_SIGNATURES]
    beside = measuring
    torque_beside = False          # the strongest periodic torque is beside the factors
    for i in todo:
        say(f"sizing the unexplained signature: {sigs[i].text}")
        sigs[i], refit, term = periodic.measure(sigs[i], trials, base, *measuring,
                                                window, threads)
        if i == todo[0] and refit is not None:
            beside = (measuring[0] + (term,), refit)
            torque_beside = True
    say("testing one force factor per actuator")
    by_actuator = actuator.measure(trials, base, beside[0], beside[1], window, threads)
    if by_actuator is not None:
        sig, factors_fit = by_actuator
        # the strongest periodic torque may be only the factors' first harmonic: sized again
        if torque_beside:
            sigs[todo[0]] = periodic.sized(sigs[todo[0]], factors_fit,
                                           periodic.frequency(sigs[todo[0]], base), base)
        sigs[:] = [s for s in sigs if s.axis not in ("actuator", "autocorrelation")] + [sig]
    if len(measuring[0]) > len(chosen):
        device = measuring[0][-1]
        noun, words = DEVICE_WORDS[device.id]
        value = measuring[1].values[device.params[0].name]
        for sig in sigs:
            if sig.torque_ci95 is not None or sig.factors is not None:
                sig.text += (f"; sized with {noun} beside it ({words(value)}), a measuring "
                             f"device for the unexplained drift")


def _set_apart_unconfirmed(ident: Identification, current: Evaluation) -> None:
    """Move the periodic signatures their refit does not confirm to ``ident.unconfirmed``;
    with nothing left, a correlated residual is the signature.  A drift, or a structure no
    axis shows, gets the free run's steady-state error trial by trial."""
    diag = ident.diagnostics_after
    sigs = diag.signatures
    ident.unconfirmed = [s for s in sigs if not periodic.confirmed(s)]
    sigs[:] = [s for s in sigs if periodic.confirmed(s)]
    if not sigs:
        correlated = autocorrelation_signature(diag, ident.base.inertia)
        sigs += [correlated] if correlated is not None else []
    for sig in sigs:
        if sig.axis == "autocorrelation" or drift_signature(sig):
            sig.text += ("; the free run's steady-state speed error (simulated minus "
                         "measured) trial by trial: " + drift_text(ident.trials,
                                                                   current.sim_fitted))


def _note_what_it_is_not(ident: Identification, chosen: tuple[Candidate, ...],
                         refusals: Refusals) -> None:
    """Add to each signature the library effects of its shape refused as stand-ins (once
    per turn of their axis), and to a drift the effects refused beside a measuring device
    in the refits the search kept (one note per effect)."""
    for sig in ident.diagnostics_after.signatures:
        for c, why in refusals.stand_ins.values():
            if (c.axis == sig.axis and c not in chosen and sig.period is not None
                    and abs(sig.period / (2 * math.pi) - 1.0) < 0.02):
                sig.text += f"; refitted to it, {why}"
        if drift_signature(sig):
            noted = set()
            for ev in (e for r in ident.rounds for e in r if not e.accepted):
                for cid in ev.effects:
                    why = refusals.within.get((ev.fit.z.tobytes(), cid))
                    if why is not None and cid not in ident.chosen and cid not in noted:
                        noted.add(cid)
                        sig.text += f"; {why}"
