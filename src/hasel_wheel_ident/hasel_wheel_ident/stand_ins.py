"""Why an effect refitted unit by unit stands in for another effect (a refusal): its size
trends with the speed (:func:`stand_in_reason`, code ``SPEED_STAND_IN``), or it no longer
holds beside a measuring device (:mod:`.measuring_devices`) that takes up a change within the
trials (:func:`drift_stand_in`: ``DRIFT_STAND_IN``, ``HV_LOSS_LOOKALIKE``) or a loss at each
switch-on (:func:`lag_stand_in`: ``SWITCH_ON_LAG_STAND_IN``).  Tested in
``test_ident_consistency.py``
(``test_a_drifting_stand_in_loses_its_hold_beside_the_measured_loss``,
``test_a_rise_lag_standing_in_for_weak_retention_is_refused_beside_the_loss``,
``test_retention_standing_in_for_a_rise_lag_loses_its_hold_beside_the_lag``)."""
from __future__ import annotations

from hasel_wheel_sim.params import WheelParams

from hasel_wheel_ident.candidates import Candidate
from hasel_wheel_ident.consistency import Consistency, drifts, grows_with_speed, inconsistent
from hasel_wheel_ident.data import Trial
from hasel_wheel_ident.drive_cuts import MIN_SPEED_RATIO
from hasel_wheel_ident.fit import FitResult
from hasel_wheel_ident.measuring_devices import (HV_LOSS, LOOKALIKE_P, ON_LAG,
                                                 can_measure_beside, can_measure_lag,
                                                 measure_beside)
from hasel_wheel_ident.reasons import Finding, Reason

#: Effects refitted beside :data:`~.measuring_devices.HV_LOSS` whether they drift or not
#: (:func:`drift_stand_in`): a rise lag takes a bite out of every push, and so does a loss
#: with the HV time, which need not show as a drift of the lag's size within the trials
#: (docs/identification.md).
LOSS_LOOKALIKES = frozenset({"rise_lag"})


def stand_in_reason(c: Candidate, con: Consistency | None) -> Finding | None:
    """Code ``SPEED_STAND_IN`` when ``c``, refitted trial by trial as ``con``, is
    :func:`~.consistency.inconsistent` (its size trends with the trials' speed); None
    otherwise.  Values: ``unit`` ("trial" or "span"), ``exponent`` k and ``trend_p``."""
    if not inconsistent(con):
        return None
    how = ("in every trial, refitted trial by trial" if con.unit == "trial" else
           "at every speed, refitted span by span (the trials' speeds while driven differ by "
           f"less than {MIN_SPEED_RATIO}x; {len(con.trials)} spans of "
           f"{len(con.halves_trials)} drives)")
    return Finding(Reason.SPEED_STAND_IN,
                   f"{c.id} is not the same {how}: {con.text(c)}; a physical {c.id} would be "
                   f"one value at every speed, so it stands in for an effect whose size goes "
                   f"otherwise with the speed",
                   {"unit": con.unit, "exponent": con.exponent, "trend_p": con.trend_p})


def drift_stand_in(trials: list[Trial], base: WheelParams, effects: tuple[Candidate, ...],
                   fit: FitResult, effect: Candidate, con: Consistency | None,
                   min_gain: float, window: float = 1.0, threads: int = 2) -> Finding | None:
    """Why ``effect`` (in ``effects``, the model fitted on all ``trials`` as ``fit``, with
    windows of ``window`` [s]) stands in for a change within the trials (code
    ``DRIFT_STAND_IN``, or ``HV_LOSS_LOOKALIKE`` for a rise lag that does not drift), or
    None; values: ``drift`` h, ``p`` (its Wald p beside the device), ``device_p``.

    Tested when :func:`~.measuring_devices.can_measure_beside`, for an effect that drifts
    (:func:`~.consistency.drifts` of ``con``, its check trial by trial) and for every rise
    lag (:data:`LOSS_LOOKALIKES`).  It is refitted beside
    :data:`~.measuring_devices.HV_LOSS`.  An effect that drifts stands in when it no longer
    holds there (:meth:`~.measuring_devices.Beside.holds`).  A rise lag that does not drift
    stands in when it no longer holds there *and* the device itself is significant beside it
    (p under :data:`~.measuring_devices.LOOKALIKE_P`): the loss is then there and the lag is
    not needed.  The refit is kept on ``con`` (``beside``); when it is void, None."""
    drifting = drifts(con)
    if con is None or not can_measure_beside(effects) or not (
            drifting or effect.id in LOSS_LOOKALIKES):
        return None
    con.beside = b = measure_beside(trials, base, effects, fit, effect, HV_LOSS, min_gain,
                                    window, threads)
    if b is None or b.holds():
        return None
    values = {"drift": con.drift, "p": b.p, "device_p": b.device_p}
    if drifting:
        return Finding(Reason.DRIFT_STAND_IN,
                       f"{effect.id} changes within the trials ({con.drift_text()}); "
                       f"{b.text(effect.id, need=True)}: there it no longer holds, so it "
                       f"stands in for an effect that changes during the trials", values)
    if not b.device_p < LOOKALIKE_P:
        return None
    return Finding(Reason.HV_LOSS_LOOKALIKE,
                   f"{effect.id} and a loss with the accumulated HV time weaken the pushes in "
                   f"close shapes; {b.text(effect.id, need=True)}: there it no longer holds "
                   f"while the loss does (under {LOOKALIKE_P:g}), so it stands in for a loss "
                   f"that grows with the HV time", values)


def lag_stand_in(trials: list[Trial], base: WheelParams, effects: tuple[Candidate, ...],
                 fit: FitResult, effect: Candidate, con: Consistency | None,
                 min_gain: float, window: float = 1.0, threads: int = 2) -> Finding | None:
    """Why ``effect`` (in ``effects``, the model fitted on all ``trials`` as ``fit``, with
    windows of ``window`` [s]) stands in for a force that builds up after each switch-on
    (code ``SWITCH_ON_LAG_STAND_IN``; values ``exponent`` k, ``p`` its Wald p beside the
    device, ``device_p``), or None.

    Only an effect whose size grows with the speed (:func:`~.consistency.grows_with_speed`
    of ``con``) is tested, and only when :func:`~.measuring_devices.can_measure_lag`.  It is
    refitted beside :data:`~.measuring_devices.ON_LAG` and stands in when it no longer holds
    there (:meth:`~.measuring_devices.Beside.holds`).  The refit is kept on ``con``
    (``beside_lag``); when it is void, None."""
    if not grows_with_speed(con) or not can_measure_lag(effects):
        return None
    con.beside_lag = measure_beside(trials, base, effects, fit, effect, ON_LAG, min_gain,
                                    window, threads)
    if con.beside_lag is None or con.beside_lag.holds():
        return None
    b = con.beside_lag
    return Finding(Reason.SWITCH_ON_LAG_STAND_IN,
                   f"{effect.id} grows with the speed ({con.text(effect)}); "
                   f"{b.text(effect.id, need=True)}: there it no longer holds, so it stands "
                   f"in for a loss at each switch-on, which takes a larger share of the "
                   f"shorter pushes at speed",
                   {"exponent": con.exponent, "p": b.p, "device_p": b.device_p})
