"""Cautions on an effect refitted unit by unit (:class:`~.consistency.Consistency`): evidence
that it may stand in for another effect, short of a refusal.  It leans on the speed
(:func:`lean_caution`), changes within the trials (:func:`drift_caution`), or is a rise lag
that holds beside a loss with the HV time that holds too (:func:`loss_caution`).  Tested in
``test_ident_consistency.py``
(``test_a_lean_on_the_speed_short_of_refusal_is_a_caution``,
``test_a_rise_lag_that_holds_beside_a_significant_loss_carries_a_caution``)."""
from __future__ import annotations

from hasel_wheel_ident.candidates import Candidate
from hasel_wheel_ident.consistency import TREND_P, Consistency, drifts, leans
from hasel_wheel_ident.measuring_devices import LOOKALIKE_P
from hasel_wheel_ident.stand_ins import LOSS_LOOKALIKES


def caution(c: Candidate, con: Consistency | None) -> str | None:
    """Every caution on ``c`` refitted as ``con`` (:func:`lean_caution`,
    :func:`drift_caution`, :func:`loss_caution`), one sentence each; None when there is
    none."""
    return " ".join(f"{s}." for s in (lean_caution(c, con), drift_caution(c, con),
                                       loss_caution(c, con)) if s) or None


def lean_caution(c: Candidate, con: Consistency | None) -> str | None:
    """A caution when ``c``, refitted trial by trial as ``con``,
    :func:`~.consistency.leans` on the speed; None otherwise.  It quotes the refit beside
    :data:`~.measuring_devices.ON_LAG` when one ran."""
    if not leans(con):
        return None
    by = "trial by trial" if con.unit == "trial" else "span by span"
    b = con.beside_lag
    beside = ("" if b is None else f"; {b.text(c.id)}: there it "
              + ("still holds" if b.holds() else "no longer holds"))
    return (f"{c.id} goes with the speed, refitted {by}: {con.text(c)}; short of a refusal "
            f"(p < {TREND_P:.0e}), but a physical {c.id} would be one value at every speed, "
            f"so it may stand in for an effect whose size goes with the speed (trials at "
            f"more speeds, or with longer drives at a steady speed, would tell){beside}")


def loss_caution(c: Candidate, con: Consistency | None) -> str | None:
    """A caution when ``c``, a rise lag that does not drift
    (:data:`~.stand_ins.LOSS_LOOKALIKES`), still holds beside
    :data:`~.measuring_devices.HV_LOSS` while the device is significant beside it too (p
    under :data:`~.measuring_devices.LOOKALIKE_P`): the two are close in shape on these
    trials, and the loss may be what is there; None otherwise."""
    b = None if con is None else con.beside
    if (c.id not in LOSS_LOOKALIKES or b is None or drifts(con) or not b.holds()
            or not b.device_p < LOOKALIKE_P):
        return None
    return (f"{c.id} {b.text(c.id)}: there it still holds, but so does the loss (under "
            f"{LOOKALIKE_P:g}); on these trials the two weaken the pushes in close shapes, so "
            f"a loss with the accumulated HV time (charge retention) may be what is there")


def drift_caution(c: Candidate, con: Consistency | None) -> str | None:
    """A caution when ``c``, refitted on the halves of each drive, changes within the trials
    (:func:`~.consistency.drifts`); None otherwise."""
    if not drifts(con):
        return None
    if con.beside is not None and con.beside.holds():
        return (f"{c.id} is not the same throughout a trial, refitted on the halves of each "
                f"drive: {con.drift_text()}; {con.beside.text(c.id)}: there it still holds, "
                f"so an effect that changes during a trial is probably still missing and "
                f"this one took up part of it")
    return (f"{c.id} is not the same throughout a trial, refitted on the halves of each "
            f"drive: {con.drift_text()}; either it stands in for an effect that changes "
            f"during a trial, or such an effect is still missing and this one took up part "
            f"of it")
