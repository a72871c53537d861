"""Cautions on an effect refitted unit by unit (:class:`~.consistency.Consistency`): evidence
that it may stand in for another effect, short of a refusal.  Each is a
:class:`~.reasons.Finding` with its code: it leans on the speed (:func:`lean_caution`,
``LEANS_ON_SPEED``), changes within the trials (:func:`drift_caution`,
``DRIFTS_WITHIN_TRIALS``), or is a rise lag that holds beside a loss with the HV time that
holds too (:func:`loss_caution`, ``HOLDS_BESIDE_HV_LOSS``).  Tested in
``test_ident_consistency.py``
(``test_a_lean_on_the_speed_short_of_refusal_is_a_caution``,
``test_a_drift_within_the_trials_is_a_caution_not_a_refusal``,
``test_a_rise_lag_that_holds_beside_a_significant_loss_carries_a_caution``)."""
from __future__ import annotations

from hasel_wheel_ident.candidates import Candidate
from hasel_wheel_ident.consistency import TREND_P, Consistency, drifts, leans
from hasel_wheel_ident.measuring_devices import LOOKALIKE_P, Beside
from hasel_wheel_ident.reasons import Finding, Reason
from hasel_wheel_ident.stand_ins import LOSS_LOOKALIKES


def cautions(c: Candidate, con: Consistency | None) -> list[Finding]:
    """Every caution on ``c`` refitted as ``con``: :func:`lean_caution`,
    :func:`drift_caution`, :func:`loss_caution`, in that order; [] when there is none."""
    found = (lean_caution(c, con), drift_caution(c, con), loss_caution(c, con))
    return [f for f in found if f is not None]


def caution(c: Candidate, con: Consistency | None) -> str | None:
    """The :func:`cautions` on ``c`` in words, one sentence each; None when there is none."""
    return " ".join(f"{f.text}." for f in cautions(c, con)) or None


def _holds(b: Beside | None) -> bool | None:
    """Whether the effect holds beside the device (:meth:`~.measuring_devices.Beside.holds`);
    None when it was not refitted there."""
    return None if b is None else b.holds()


def lean_caution(c: Candidate, con: Consistency | None) -> Finding | None:
    """Code ``LEANS_ON_SPEED`` when ``c``, refitted trial by trial as ``con``,
    :func:`~.consistency.leans` on the speed; None otherwise.  Values: ``unit``,
    ``exponent`` k, ``trend_p``, and ``beside_holds`` whether it still holds beside
    :data:`~.measuring_devices.ON_LAG` (None when not refitted there)."""
    if not leans(con):
        return None
    by = "trial by trial" if con.unit == "trial" else "span by span"
    b = con.beside_lag
    beside = ("" if b is None else f"; {b.text(c.id)}: there it "
              + ("still holds" if b.holds() else "no longer holds"))
    return Finding(Reason.LEANS_ON_SPEED,
                   f"{c.id} goes with the speed, refitted {by}: {con.text(c)}; short of a "
                   f"refusal (p < {TREND_P:.0e}), but a physical {c.id} would be one value at "
                   f"every speed, so it may stand in for an effect whose size goes with the "
                   f"speed (trials at more speeds, or with longer drives at a steady speed, "
                   f"would tell){beside}",
                   {"unit": con.unit, "exponent": con.exponent, "trend_p": con.trend_p,
                    "beside_holds": _holds(b)})


def loss_caution(c: Candidate, con: Consistency | None) -> Finding | None:
    """Code ``HOLDS_BESIDE_HV_LOSS`` when ``c``, a rise lag that does not drift
    (:data:`~.stand_ins.LOSS_LOOKALIKES`), still holds beside
    :data:`~.measuring_devices.HV_LOSS` while the device is significant beside it too (p
    under :data:`~.measuring_devices.LOOKALIKE_P`): the two are close in shape on these
    trials, and the loss may be what is there; None otherwise.  Values: ``p`` the effect's
    Wald p beside the device, ``device_p`` the device's."""
    b = None if con is None else con.beside
    if (c.id not in LOSS_LOOKALIKES or b is None or drifts(con) or not b.holds()
            or not b.device_p < LOOKALIKE_P):
        return None
    return Finding(Reason.HOLDS_BESIDE_HV_LOSS,
                   f"{c.id} {b.text(c.id)}: there it still holds, but so does the loss (under "
                   f"{LOOKALIKE_P:g}); on these trials the two weaken the pushes in close "
                   f"shapes, so a loss with the accumulated HV time (charge retention) may be "
                   f"what is there", {"p": b.p, "device_p": b.device_p})


def drift_caution(c: Candidate, con: Consistency | None) -> Finding | None:
    """Code ``DRIFTS_WITHIN_TRIALS`` when ``c``, refitted on the halves of each drive,
    changes within the trials (:func:`~.consistency.drifts`); None otherwise.  Values:
    ``drift`` h, ``drift_p``, and ``beside_holds`` whether it still holds beside
    :data:`~.measuring_devices.HV_LOSS` (None when not refitted there)."""
    if not drifts(con):
        return None
    values = {"drift": con.drift, "drift_p": con.drift_p, "beside_holds": _holds(con.beside)}
    if con.beside is not None and con.beside.holds():
        return Finding(Reason.DRIFTS_WITHIN_TRIALS,
                       f"{c.id} is not the same throughout a trial, refitted on the halves of "
                       f"each drive: {con.drift_text()}; {con.beside.text(c.id)}: there it "
                       f"still holds, so an effect that changes during a trial is probably "
                       f"still missing and this one took up part of it", values)
    return Finding(Reason.DRIFTS_WITHIN_TRIALS,
                   f"{c.id} is not the same throughout a trial, refitted on the halves of each "
                   f"drive: {con.drift_text()}; either it stands in for an effect that changes "
                   f"during a trial, or such an effect is still missing and this one took up "
                   f"part of it", values)
