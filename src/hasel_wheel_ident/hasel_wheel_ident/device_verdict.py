"""Which measuring device (:mod:`.measuring_devices`) takes up the most of an unexplained
drift, from their refits beside the final model: :func:`lead_device` and its words,
:func:`devices_verdict`.  Each device's refit is a dict: ``sim_rmse_rad_s`` the free run on
all trials with it [rad/s], ``sim_rmse_model_rad_s`` without it, and optionally
``wald_p_together`` its Wald p with all the devices refitted together.  Tested in
``test_ident_consistency.py``
(``test_the_device_that_takes_up_the_most_of_a_drift_must_cut_it_and_beat_the_other``,
``test_the_device_alone_significant_beside_the_other_takes_up_the_most``).  Its verdict is a
:class:`~.reasons.Finding` (:func:`devices_finding`)."""
from __future__ import annotations

import math

from hasel_wheel_ident.measuring_devices import BESIDE_P, DEVICE_WORDS, LOOKALIKE_P
from hasel_wheel_ident.reasons import Finding, Reason


def lead_device(devices: dict[str, dict], min_gain: float) -> str | None:
    """The id of the device that takes up the most of a drift, or None when none does: it
    cuts the model's free run by half of ``min_gain`` (a fraction) or more, and either it
    alone stays significant together (:func:`together_lead`) or its free run is that much
    below every other device's.  Devices whose figures are not finite are left out."""
    devices = _finite(devices)
    if not devices:
        return None
    need = 0.5 * min_gain
    together = together_lead(devices)
    best = together or min(devices, key=lambda k: devices[k]["sim_rmse_rad_s"])
    d = devices[best]
    e = d["sim_rmse_rad_s"]
    if 1.0 - e / d["sim_rmse_model_rad_s"] < need:
        return None
    if together is None and not all(e <= (1.0 - need) * o["sim_rmse_rad_s"]
                                    for k, o in devices.items() if k != best):
        return None
    return best


def together_lead(devices: dict[str, dict]) -> str | None:
    """The one device that stays significant with every other beside it, when the devices
    were refitted together (``wald_p_together`` of each): its Wald p there under
    :data:`~.measuring_devices.BESIDE_P` while every other's is
    :data:`~.measuring_devices.LOOKALIKE_P` or more.  None when the refit together is
    missing, or does not single one out.

    This overrides the free runs: on short trials a look-alike can run them better than the
    loss that is there.  (A p of 1 can also mean a parameter the fit leaves undetermined,
    :func:`~.fit.wald_p`: beside the other device that device is then not needed either.)"""
    ps = {k: d.get("wald_p_together", math.nan) for k, d in devices.items()}
    if len(ps) < 2 or not all(math.isfinite(p) for p in ps.values()):
        return None
    lead = [k for k, p in ps.items() if p < BESIDE_P]
    if len(lead) != 1 or not all(p >= LOOKALIKE_P for k, p in ps.items() if k != lead[0]):
        return None
    return lead[0]


def _finite(devices: dict[str, dict]) -> dict[str, dict]:
    """The devices whose free runs are finite (and the model's positive)."""
    return {k: d for k, d in devices.items()
            if math.isfinite(d["sim_rmse_rad_s"]) and math.isfinite(d["sim_rmse_model_rad_s"])
            and d["sim_rmse_model_rad_s"] > 0.0}


def devices_verdict(devices: dict[str, dict], min_gain: float) -> str:
    """:func:`devices_finding` in words (a description, not a name)."""
    return devices_finding(devices, min_gain).text


def devices_finding(devices: dict[str, dict], min_gain: float) -> Finding:
    """Which measuring device takes up the most of a drift (:func:`lead_device`): code
    ``DEVICE_LEADS`` with values ``lead`` (its id) and ``together`` (whether the refit of
    the devices together singled it out, :func:`together_lead`); else why none does,
    ``NO_DEVICE_REFITTED`` (no finite figures), ``NO_DEVICE_CUTS`` (none cuts the model's
    free run by half of ``min_gain``) or ``DEVICES_NOT_TOLD_APART``, with value ``need``
    (that half, a fraction)."""
    lead = lead_device(devices, min_gain)
    if lead is not None:
        together = lead == together_lead(_finite(devices))
        return Finding(Reason.DEVICE_LEADS, _lead_words(devices, lead, together),
                       {"lead": lead, "together": together})
    devices = _finite(devices)
    if not devices:
        return Finding(Reason.NO_DEVICE_REFITTED, "no device could be refitted beside the model")
    need = 0.5 * min_gain
    if all(1.0 - d["sim_rmse_rad_s"] / d["sim_rmse_model_rad_s"] < need
           for d in devices.values()):
        return Finding(Reason.NO_DEVICE_CUTS,
                       f"no device takes up much of it (each cuts the free run on all trials "
                       f"by less than {100 * need:.0f} %)", {"need": need})
    return Finding(Reason.DEVICES_NOT_TOLD_APART,
                   f"no device takes up clearly more of it than the others (free runs within "
                   f"{100 * need:.0f} % of each other): its shape is not told", {"need": need})


def _lead_words(devices: dict[str, dict], lead: str, together: bool) -> str:
    """The device ``lead`` in words, with the Wald p of each device refitted together when
    that singled it out (``together``)."""
    why = ""
    if together:
        others = ", ".join(f"{DEVICE_WORDS[k][0]} {d['wald_p_together']:.1e}"
                           for k, d in devices.items() if k != lead)
        why = (f": refitted together, only it stays significant (Wald p "
               f"{devices[lead]['wald_p_together']:.1e}; {others})")
    return (f"of these, {DEVICE_WORDS[lead][0]} takes up the most of it{why} (a "
            f"description, not a name)")
