"""The identification report: ``report.md`` with PNG figures, ``report.json`` for machines,
and ``model.yaml``, the identified model that the sim and the MPC load.

``report.json`` (schema ``hasel_wheel.identification/1``); every key below is always present:

=========================  ===============================================================
schema                     "hasel_wheel.identification/1"
trials                     [{name, source, duration_s, samples, activations, coasts,
                            rest_tail}]; rest_tail: the rest at the end of the record, whose
                            samples after its first the fits leave out (fit.RestTail):
                            {from_s [s, after the trial's first sample] its first sample, seconds [s] to
                            the end, scheduled_share and hv_share [1] of the samples left
                            out with a pad scheduled and on, pad (0..15) the one in contact
                            and target (0..15) the command's for most of them, null when
                            none, stalled: the wheel stopped for good while driven, a pad
                            scheduled for most of a rest of 1 s or more, text: the stall in
                            words, null unless stalled}; null when the fits keep every
                            sample (no rest at the end, the whole record at rest, or too
                            little before it)
friction                   {tau_f_N_m, ci95_N_m: [lo, hi], segments} or null (no coast-down)
nominal                    {parameters: {name: {value, unit, ci95: [lo, hi]}},
                            wheel: {sigma1..sigma6, tau_f, brake_gain}}
fits                       {nominal: F, final: F}, F = {converged, evaluations, message}:
                            whether the least-squares fit on all trials met its tolerances
                            or stopped at its evaluation limit (then its values are where
                            it stopped, not a minimum)
chosen_effects             [stable identifier, ...] in the order chosen; [] when none
effects                    [{id, title, parameters: {name: {value, unit, ci95}},
                            physical: {...}, physical_ci95: {name: [lo, hi]}, wald_p}]
                            for the chosen ones (wald_p: "absent" in the final model);
                            consistency: {units, speed_exponent, speed_exponent_sd,
                            speed_trend_p, drift_exponent, drift_exponent_sd, drift_p,
                            beside_hv_loss, beside_on_lag, caution} the effect refitted
                            trial by trial
                            (units "trial"), or span by span when the trials' speeds
                            differ by less than 1.2x ("span", each drive cut in up to
                            six), size ~ speed^k, and on the halves of each drive (size ~
                            hv^h), as checked when it was added (ident/consistency.py);
                            caution: a sentence for each warning (its size leans on
                            the speed short of refusal, or changes within the
                            trials), else null; an exponent and its p are null where
                            they cannot be formed; beside_hv_loss {rate_per_s, values, wald_p,
                            device_wald_p, sim_rmse_rad_s, sim_rmse_without_rad_s}: a
                            drifting effect (or any rise lag) refitted beside a force
                            loss growing with HV time (the device's rate, the effect's
                            own parameters there by name in their units, its Wald p
                            there, the device's own Wald p, the free run on all trials
                            with it and without it), null when not refitted;
                            beside_on_lag {time_constant_s, values, wald_p, device_wald_p,
                            sim_rmse_rad_s, sim_rmse_without_rad_s}: the same for an
                            effect whose size grows with the speed (k > 0.5, p < 0.1),
                            refitted beside a force that builds up after each switch-on
                            (1 - exp(-t_on / time_constant_s)), null when not refitted;
                            null when not checked
candidates                 [{round, id, score_statistic, score_dof, score_p,
                            predicted_window_rmse_rad, refitted, converged (null: not
                            refitted), window_rmse_rad,
                            heldout_window_rmse_rad (null: not cross-validated, the fit
                            on all trials did not beat the current model), wald_p,
                            parameters {name: {value, unit, ci95}} (the candidate's own,
                            as its refit on all trials ended, accepted or not; null: not
                            refitted), physical {name: value} (the scalar ones of the same
                            in physical terms, Candidate.describe; null: not refitted),
                            accepted, ran_on (true for the one refit that stopped at its
                            limit and ran on from there into the final model, whose values,
                            under effects, are then the run-on fit's, not these;
                            Identification.ran_on_from), reason}]
tried_together             [{round, ids, window_rmse_rad, heldout_window_rmse_rad, wald_p,
                            accepted, ran_on (as for candidates), reason}] two effects refitted together because each
                            alone fitted the windows better but was refused
                            (select.supported_pair), or one alone was accepted and the
                            other, refused, fitted the held-out windows as well
                            (select.tied_pair); [] when none
unexplained                [{axis, unit, period, amplitude_rad_s2, torque_N_m, p_value,
                            text, phase_rad, torque_ci95_N_m, actuator_factors, drift,
                            drift_devices}] structure
                            left in the final model's residual; [] when none.  A
                            signature periodic in an angle is sized by a refit of a
                            torque at its period (ident/periodic.py):
                            torque_N_m * sin(2 pi x / period + phase_rad) along its
                            axis x, with a 95 % interval, and p_value is that refit's
                            Wald test of "no torque"; phase_rad and torque_ci95_N_m are
                            null where it is sized from the residual alone.  drift
                            true: a drift during the drive along axis "time", "hv_time"
                            or "speed" (residual.drive_trend; the axis of the measuring
                            device that takes up the most of it instead, when that axis
                            shows it too: consistency.lead_device, residual.drift_along);
                            drift_devices {hv_loss,
                            on_lag: {value, unit, wald_p, sim_rmse_rad_s,
                            sim_rmse_model_rad_s, wald_p_together}}: each measuring
                            device (a force loss growing with HV time, rate [1/s]; a
                            force building up after each switch-on, time constant [s])
                            refitted beside the final model, and the free run on all
                            trials with it and without it, for a drift ({} otherwise,
                            and without a device the model has an effect of its own
                            form for); wald_p_together its Wald p with both devices
                            refitted together beside the model (only when both are);
                            amplitude_rad_s2 is half the fitted curve's largest range
                            within a trial.  Axis "actuator": one force factor per
                            actuator, sized by a refit (ident/actuator.py), listed in
                            actuator_factors [1] (actuators 0..15, geometric mean 1);
                            null for every other axis.
                            Axis "autocorrelation" (unit s, period null):
                            a residual that is not white while no axis shows structure;
                            amplitude_rad_s2 is the constant acceleration error per window
                            that leaves as much correlated residual
                            (residual.autocorrelation_signature)
near_misses                [{ids, physical {id: {name: value}}, wald_p,
                            heldout_simulation_rmse_rad_s,
                            final_heldout_simulation_rmse_rad_s, cut [1] (1 - the two's
                            ratio), bar [1] (the cut the search asked for, 0.10), reason}]
                            refits turned away at the free-run bar with a cut of at least
                            half of it, that passed the other tests (select.near_misses):
                            refused, not named; [] when none
unconfirmed                [{axis, period, amplitude_rad_s2, p_value, torque_ci95_N_m,
                            text}] periods the residual's periodograms showed that their
                            refit did not confirm (periodic.confirmed: the refit's Wald p
                            of "no torque" not under 1e-6, or under the reporting floor);
                            not structure the model leaves; [] when none
metrics                    {before: M, after: M}, M = {window_rmse_rad, heldout_window_rmse_rad,
                            simulation: {pooled_fitted_rmse_rad_s, pooled_heldout_rmse_rad_s,
                            per_trial: {name: {fitted: T, heldout: T}}}},
                            T = {rmse, r2, nrmse, steady_state_error, samples} (rad/s, 1);
                            prediction: {name: {rms_rad, normalised_rms,
                            whiteness_outside}} (one-step prediction residual, first 20 s)
diagnostics                {before: D, after: D}, D = {whiteness_outside, band99,
                            input_correlation_max, rms_accel_rad_s2, structures:
                            {axis: {p_value, amplitude_rad_s2}}}
paper_table3               {phi_a_deg: {rmse_m_s, r2, ess_m_s}}
model_file                 "model.yaml"; left_out_effects: chosen effects the file cannot hold
figures                    [file names]
identifiability            ["singular value  verdict: combination", ...] (when computed)
closed_loop                {model: {rmse_rad_s, nrmse, segment_steady_error_percent,
                            decisions, braking}} (with ``--compare-plant``)
numerics                   {blas: [{library, version, kernels}], coretype_env}: the BLAS
                            that ran the fits and its kernel set (choices near a gate can
                            differ between kernel sets; hasel_wheel_ident.numerics pins
                            "Haswell" on x86-64)
=========================  ===============================================================

The stable effect identifiers are those of :mod:`.candidates` (README, "Identification").
"""
from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np

from hasel_wheel_sim.model_file import save_model

from hasel_wheel_ident import plots
from hasel_wheel_ident.candidates import BY_ID, Candidate
from hasel_wheel_ident.consistency import Beside, Consistency, caution
from hasel_wheel_ident.data import find_coasts
from hasel_wheel_ident.numerics import blas_in_use
from hasel_wheel_sim.paper import TABLE_III
from hasel_wheel_ident.metrics import TrialMetrics, pooled_rmse
from hasel_wheel_ident.prediction import PREDICTION_SPAN
from hasel_wheel_ident.residual import Diagnostics
from hasel_wheel_ident.fit import effect_wald_p, rest_tail
from hasel_wheel_ident.select import Evaluation, Identification, near_misses

SCHEMA = "hasel_wheel.identification/1"
#: report.md's note on the refit that stopped at its limit and ran on into the final model
RAN_ON_NOTE = "(where its fit stopped; it ran on to the chosen values above)"


def _num(v):
    """JSON-safe number: nan and inf become null."""
    if v is None:
        return None
    v = float(v)
    return v if math.isfinite(v) else None


def _fmt(v: float | None, spec: str) -> str:
    """A JSON number for the Markdown; null (nan or inf) reads as "n/a"."""
    return "n/a" if v is None else format(v, spec)


def _params(ev: Evaluation, names: list[str] | None = None) -> dict:
    fit = ev.fit
    out = {}
    for nm, unit in zip(fit.names, fit.units):
        if names is not None and nm not in names:
            continue
        out[nm] = {"value": _num(fit.values[nm]), "unit": unit,
                   "ci95": [_num(fit.ci95[nm][0]), _num(fit.ci95[nm][1])]}
    return out


def _physical(c: Candidate, ev: Evaluation) -> dict[str, float | None]:
    """The scalar physical values (``Candidate.describe``) of ``c`` as ``ev`` fitted it."""
    d = c.describe(np.array([ev.fit.values[p.name] for p in c.params]))
    return {k: _num(v) for k, v in d.items() if isinstance(v, float)}


def _near_miss(e: Evaluation, final: Evaluation, bar: float) -> dict:
    """A refit :func:`~.select.near_misses` lists, for report.json (``bar`` [1]: the
    search's ``min_gain``)."""
    added = e.effects[len(final.effects):]
    return {"ids": list(added),
            "physical": {i: _physical(BY_ID[i], e) for i in added},
            "wald_p": _num(e.wald_p),
            "heldout_simulation_rmse_rad_s": _num(e.sim_heldout_rmse),
            "final_heldout_simulation_rmse_rad_s": _num(final.sim_heldout_rmse),
            "cut": _num(1.0 - e.sim_heldout_rmse / final.sim_heldout_rmse),
            "bar": bar, "reason": e.reason}


def near_miss_text(m: dict) -> str:
    """One line on a ``near_misses`` entry of report.json."""
    each = {i: ", ".join(f"{k} {_fmt(v, '.4g')}" for k, v in m["physical"][i].items())
            for i in m["ids"]}
    values = "; ".join(f"{i}: {v}" for i, v in each.items()) if len(each) > 1 else \
        next(iter(each.values()), "")
    return (f"{'+'.join(m['ids'])} ({values}): Wald p {_fmt(m['wald_p'], '.1e')}, held-out "
            f"simulation error {_fmt(m['final_heldout_simulation_rmse_rad_s'], '.4f')} -> "
            f"{_fmt(m['heldout_simulation_rmse_rad_s'], '.4f')} rad/s "
            f"({_fmt(None if m['cut'] is None else 100 * m['cut'], '.1f')} % lower; the bar "
            f"is {100 * m['bar']:.0f} %)")


def _rest_tail(tr) -> dict | None:
    """report.json's ``rest_tail`` of a trial (:func:`~.fit.rest_tail`)."""
    rt = rest_tail(tr)
    if rt is None:
        return None
    return {"from_s": rt.from_s, "seconds": rt.seconds, "scheduled_share": rt.scheduled_share,
            "hv_share": rt.hv_share, "pad": rt.pad, "target": rt.target,
            "stalled": rt.stalled, "text": rt.text(tr.name) if rt.stalled else None}


def stall_texts(data: dict) -> list[str]:
    """The stalls of report.json's trials in words, one per trial that stalled."""
    return [t["rest_tail"]["text"] for t in data["trials"]
            if t["rest_tail"] is not None and t["rest_tail"]["stalled"]]


def near_miss_texts(ident: Identification) -> list[str]:
    """One line per refit :func:`~.select.near_misses` lists for ``ident`` (as the command's
    summary prints them)."""
    return [near_miss_text(_near_miss(e, ident.final, ident.min_gain))
            for e in near_misses(ident)]


def _physical_ci(ev: Evaluation, c, x: np.ndarray) -> dict:
    """95 % intervals of the effect's physical values (the scalar ones) by the delta method:
    the fitted parameters' covariance through a finite-difference gradient of ``describe``."""
    idx = [ev.fit.names.index(p.name) for p in c.params]
    C = ev.fit.cov[np.ix_(idx, idx)]
    base = c.describe(x)
    out = {}
    for key, v in base.items():
        if not isinstance(v, float):
            continue
        g = np.zeros(x.size)
        for j in range(x.size):
            h = 1e-6 * max(abs(x[j]), c.params[j].scale)
            xp = x.copy()
            xp[j] += h
            g[j] = (c.describe(xp)[key] - v) / h
        var = float(g @ C @ g) if np.all(np.isfinite(C)) else math.inf
        sd = math.sqrt(max(var, 0.0))
        out[key] = [_num(v - 1.96 * sd), _num(v + 1.96 * sd)]
    return out


def _metrics(ev: Evaluation) -> dict:
    def t(m: TrialMetrics | None):
        return None if m is None else {k: (int(v) if k == "samples" else _num(v))
                                       for k, v in m.as_dict().items() if k != "trial"}
    return {
        "window_rmse_rad": _num(ev.fit.rmse),
        "heldout_window_rmse_rad": _num(ev.heldout_rmse),
        "simulation": {
            "pooled_fitted_rmse_rad_s": _num(pooled_rmse(ev.sim_fitted)),
            "pooled_heldout_rmse_rad_s": _num(pooled_rmse(ev.sim_heldout))
            if ev.sim_heldout else None,
            "per_trial": {name: {"fitted": t(m), "heldout": t(ev.sim_heldout.get(name))}
                          for name, m in ev.sim_fitted.items()},
        },
    }


def _diagnostics(d: Diagnostics | None) -> dict | None:
    if d is None:
        return None
    return {"whiteness_outside": _num(d.whiteness_outside), "band99": _num(d.band99),
            "input_correlation_max": _num(d.input_correlation_max),
            "rms_accel_rad_s2": _num(d.rms_accel),
            "structures": {k: {"p_value": _num(s.p_value), "amplitude_rad_s2": _num(s.amplitude)}
                           for k, s in d.structures.items()}}


def _prediction(pr: dict) -> dict:
    return {name: {"rms_rad": _num(p.rms), "normalised_rms": _num(p.normalised_rms),
                   "whiteness_outside": _num(p.whiteness_outside)} for name, p in pr.items()}


def _fit_status(ev: Evaluation) -> dict:
    return {"converged": bool(ev.fit.converged), "evaluations": int(ev.fit.nfev),
            "message": ev.fit.message}


def fit_status_text(ev: Evaluation, label: str) -> str:
    """One sentence on whether the fit of ``ev`` on all trials converged."""
    if ev.fit.converged:
        return f"The {label} fit converged after {ev.fit.nfev} evaluations."
    return (f"**The {label} fit did not converge**: it stopped at its limit of {ev.fit.nfev} "
            f"evaluations ({ev.fit.message}), so its values are where it stopped, not a "
            f"minimum.  A model that lacks an effect present in the data typically does this: "
            f"its force law drifts along a direction the data hardly determine while the "
            f"error falls slowly.")


def to_json(ident: Identification, figures: list[str], left_out: list[str]) -> dict:
    """The report as a JSON-ready dict (keys in the module docstring)."""
    nominal_names = ident.nominal.fit.names
    fr = ident.friction
    wheel = ident.nominal.fit.params
    chosen = []
    for cid in ident.chosen:
        c = BY_ID[cid]
        x = np.array([ident.final.fit.values[p.name] for p in c.params])
        chosen.append({"id": cid, "title": c.title,
                       "parameters": _params(ident.final, [p.name for p in c.params]),
                       "physical": c.describe(x),
                       "physical_ci95": _physical_ci(ident.final, c, x),
                       "wald_p": _num(effect_wald_p(ident.final.fit, c)),
                       "consistency": _consistency(c, ident.consistency.get(cid))})
    candidates, together = [], []
    for k, scs in enumerate(ident.screenings):
        rd = ident.rounds[k] if k < len(ident.rounds) else []
        one = min((len(e.effects) for e in rd), default=0)     # the current model + one
        evs = {e.effects[-1]: e for e in rd if len(e.effects) == one}
        together += [{"round": k + 1, "ids": list(e.effects[one - 1:]),
                      "window_rmse_rad": _num(e.fit.rmse),
                      "heldout_window_rmse_rad": _num(e.heldout_rmse), "wald_p": _num(e.wald_p),
                      "accepted": bool(e.accepted), "ran_on": e is ident.ran_on_from,
                      "reason": e.reason}
                     for e in rd if len(e.effects) > one]
        for s in scs:
            e = evs.get(s.candidate)
            candidates.append({
                "round": k + 1, "id": s.candidate, "score_statistic": _num(s.statistic),
                "score_dof": s.dof, "score_p": _num(s.p_value),
                "predicted_window_rmse_rad": _num(s.predicted_rmse), "refitted": e is not None,
                "converged": bool(e.fit.converged) if e else None,
                "window_rmse_rad": _num(e.fit.rmse) if e else None,
                "heldout_window_rmse_rad": _num(e.heldout_rmse) if e else None,
                "wald_p": _num(e.wald_p) if e else None,
                "parameters": (_params(e, [p.name for p in BY_ID[s.candidate].params])
                               if e else None),
                "physical": _physical(BY_ID[s.candidate], e) if e else None,
                "accepted": bool(e.accepted) if e else False,
                "ran_on": e is not None and e is ident.ran_on_from,
                "reason": e.reason if e else "score test not significant"
                if s.p_value >= 1e-6 else "significant, but others were more promising"})
    after = ident.diagnostics_after
    return {
        "schema": SCHEMA,
        "numerics": blas_in_use(),
        "trials": [{"name": tr.name, "source": tr.source, "duration_s": _num(tr.duration),
                    "samples": int(tr.t.shape[0]), "activations": len(tr.activations),
                    "coasts": len(find_coasts(tr)), "rest_tail": _rest_tail(tr)}
                   for tr in ident.trials],
        "friction": None if fr is None else {"tau_f_N_m": fr.tau_f,
                                             "ci95_N_m": list(fr.ci95), "segments": fr.segments},
        "nominal": {"parameters": _params(ident.nominal, nominal_names),
                    "wheel": {k: _num(getattr(wheel, k)) for k in
                              ("sigma1", "sigma2", "sigma3", "sigma4", "sigma5", "sigma6",
                               "tau_f", "brake_gain")}},
        "fits": {"nominal": _fit_status(ident.nominal), "final": _fit_status(ident.final)},
        "chosen_effects": list(ident.chosen),
        "effects": chosen,
        "candidates": candidates,
        "tried_together": together,
        "unexplained": [] if after is None else [
            {"axis": s.axis, "unit": s.unit, "period": _num(s.period),
             "amplitude_rad_s2": _num(s.amplitude), "torque_N_m": _num(s.torque),
             "p_value": _num(s.p_value), "text": s.text, "phase_rad": _num(s.phase),
             "torque_ci95_N_m": None if s.torque_ci95 is None else
             [_num(v) for v in s.torque_ci95],
             "actuator_factors": None if s.factors is None else [_num(v) for v in s.factors],
             "drift": s.drift,
             "drift_devices": {k: {n: _num(v) if n != "unit" else v for n, v in d.items()}
                               for k, d in s.devices.items()}}
            for s in after.signatures],
        "near_misses": [_near_miss(e, ident.final, ident.min_gain) for e in near_misses(ident)],
        "unconfirmed": [{"axis": s.axis, "period": _num(s.period),
                         "amplitude_rad_s2": _num(s.amplitude), "p_value": _num(s.p_value),
                         "torque_ci95_N_m": None if s.torque_ci95 is None else
                         [_num(v) for v in s.torque_ci95], "text": s.text}
                        for s in ident.unconfirmed],
        "metrics": {"before": dict(_metrics(ident.nominal),
                                   prediction=_prediction(ident.prediction_before)),
                    "after": dict(_metrics(ident.final),
                                  prediction=_prediction(ident.prediction_after))},
        "diagnostics": {"before": _diagnostics(ident.diagnostics_before),
                        "after": _diagnostics(after)},
        "paper_table3": {str(k): {"rmse_m_s": v[0], "r2": v[1], "ess_m_s": v[2]}
                         for k, v in TABLE_III.items()},
        "model_file": "model.yaml",
        "left_out_effects": left_out,
        "figures": figures,
    }


def _consistency(c: Candidate, con: Consistency | None) -> dict | None:
    """The effect refitted trial by trial and on the halves of each drive, for the JSON."""
    if con is None:
        return None
    speed = math.isfinite(con.exponent_sd)            # formed (see consistency._trend)
    drift = math.isfinite(con.drift_sd)
    return {"units": con.unit,
            "speed_exponent": _num(con.exponent) if speed else None,
            "speed_exponent_sd": _num(con.exponent_sd),
            "speed_trend_p": _num(con.trend_p) if speed else None,
            "drift_exponent": _num(con.drift) if drift else None,
            "drift_exponent_sd": _num(con.drift_sd),
            "drift_p": _num(con.drift_p) if drift else None,
            "beside_hv_loss": _beside(con.beside),
            "beside_on_lag": _beside(con.beside_lag),
            "caution": caution(c, con)}


def _beside(b: Beside | None) -> dict | None:
    """An effect refitted beside a measuring device, for the JSON (the device's value under
    the key its ``describe`` gives it); None when it was not."""
    if b is None:
        return None
    (key, value), = b.device.describe([b.value]).items()
    return {key: _num(value), "values": {k: _num(v) for k, v in b.values.items()},
            "wald_p": _num(b.p), "device_wald_p": _num(b.device_p),
            "sim_rmse_rad_s": _num(b.sim[0]),
            "sim_rmse_without_rad_s": _num(b.sim[1])}


def _ci(ci: list) -> str:
    """An interval for the Markdown; null ends (infinite variance) mean undetermined."""
    if ci[0] is None or ci[1] is None:
        return "not determined by the data"
    return f"{ci[0]:.5g} … {ci[1]:.5g}"


def _table3_rows(ev_before: Evaluation, ev_after: Evaluation, r: float) -> list[str]:
    rows = ["| trial | paper φa | paper RMSE [m/s] | paper R² | nominal RMSE fitted / held-out "
            "[m/s] | nominal R² (held-out) | identified RMSE fitted / held-out [m/s] | "
            "identified R² (held-out) | e_ss nominal / identified [m/s] |",
            "|---|---|---|---|---|---|---|---|---|"]
    for name, mb in ev_before.sim_fitted.items():
        ma = ev_after.sim_fitted[name]
        hb = ev_before.sim_heldout.get(name, mb)
        ha = ev_after.sim_heldout.get(name, ma)
        deg = _phi_a_deg(name)
        paper = TABLE_III.get(deg) if deg is not None else None
        pr = f"{paper[0]:.2f} | {paper[1]:.2f}" if paper else "– | –"
        rows.append(f"| {name} | {deg if deg is not None else '–'} | {pr} | "
                    f"{r * mb.rmse:.3f} / {r * hb.rmse:.3f} | {hb.r2:.3f} | "
                    f"{r * ma.rmse:.3f} / {r * ha.rmse:.3f} | {ha.r2:.3f} | "
                    f"{r * hb.steady_state_error:+.3f} / {r * ha.steady_state_error:+.3f} |")
    return rows


def _phi_a_deg(name: str) -> int | None:
    """The activation angle in a trial name like 'phi_a_3deg' (the synthetic trials')."""
    m = re.search(r"phi_a_(\d+)deg", name)
    return int(m.group(1)) if m else None


def to_markdown(ident: Identification, data: dict, closed_loop: dict | None = None) -> str:
    """The human-readable report (figures referenced by file name)."""
    r = ident.base.r
    nb, na = ident.nominal, ident.final
    L: list[str] = ["# Identification report", ""]
    L += [f"{len(ident.trials)} trials, {sum(t['duration_s'] for t in data['trials']):.0f} s in "
          f"all; held-out validation by trial over {len(ident.folds)} folds.", ""]
    stalls = stall_texts(data)
    if stalls:
        L += ["**Stalled** (the wheel stopped for good while driven):", ""]
        L += [f"* {text}" for text in stalls] + [""]
    blas = ", ".join(f"{b['library']} {b['version']} ({b['kernels']} kernels)"
                     for b in data["numerics"]["blas"]) or "not known (no threadpoolctl)"
    L += [f"Linear algebra: {blas}.", ""]
    L += ["## Result", ""]
    if ident.chosen:
        L += [f"**Chosen effect(s): {', '.join('`' + c + '`' for c in ident.chosen)}.**", ""]
        for e in data["effects"]:
            ps = ", ".join(f"{k} = {v['value']:.4g} {v['unit']} (95 % CI {_ci(v['ci95'])})"
                           for k, v in e["parameters"].items())
            phys = ", ".join(f"{k} = {v:.4g} (95 % CI {_ci(e['physical_ci95'][k])})"
                             if isinstance(v, float) else f"{k} = {v}"
                             for k, v in e["physical"].items() if k != "gains")
            L += [f"* `{e['id']}` ({e['title']}): {ps}; {phys}; Wald p = {e['wald_p']:.1e}"]
            k = e["consistency"]
            if k is not None:
                by = "trial by trial" if k["units"] == "trial" else "span by span"
                L += [f"  * refitted {by}: size ~ speed^k, k = "
                      f"{_fmt(k['speed_exponent'], '+.2f')} +- {_fmt(k['speed_exponent_sd'], '.2f')}"
                      f" (p = {_fmt(k['speed_trend_p'], '.1e')}); on the halves of each drive: "
                      f"size ~ hv^h, h = {_fmt(k['drift_exponent'], '+.2f')} +- "
                      f"{_fmt(k['drift_exponent_sd'], '.2f')} (p = {_fmt(k['drift_p'], '.1e')})"]
                if k["caution"]:
                    L += [f"  * **caution:** {k['caution']}"]
        L += [""]
    else:
        L += ["**No candidate effect passed every test; the paper's model is kept.**", ""]
    if data["near_misses"]:
        bar = 100 * data["near_misses"][0]["bar"]
        L += [f"Refused at the free-run bar (plausible values, Wald p < 1e-6, the held-out "
              f"windows fitted better, the free run better on the trials fitted to, and the "
              f"held-out simulation error lower by {bar / 2:.0f} % or more but by less than "
              f"{bar:.0f} %); not named, since look-alikes of an effect can do as much, but "
              f"worth a check with more varied data:", ""]
        L += [f"* {near_miss_text(m)}" for m in data["near_misses"]] + [""]
    if data["unexplained"]:
        L += ["Structure the model does **not** explain (no candidate in the library fits it):", ""]
        L += [f"* {u['text']} (p = {u['p_value']:.1e})" for u in data["unexplained"]] + [""]
    else:
        L += ["No significant structure is left in the residual.", ""]
    if data["unconfirmed"]:
        L += ["Periods the residual's periodograms showed but a refit with a torque at that "
              "period did not confirm (its Wald p not under 1e-6, or under the reporting "
              "floor):", ""]
        L += [f"* {u['text']}" for u in data["unconfirmed"]] + [""]
    if data["left_out_effects"]:
        L += [f"Not carried into `model.yaml` (the plant and the MPC have no such field): "
              f"{', '.join(data['left_out_effects'])}.", ""]
    L += ["## Error before and after", "",
          "Window error (multiple shooting, 1 s windows: RMS distance of the simulated angle "
          "from each reading, or from its count interval when the angles are encoder counts): "
          f"nominal {1e3 * nb.fit.rmse:.3f} "
          f"mrad fitted, {1e3 * nb.heldout_rmse:.3f} mrad held-out → identified "
          f"{1e3 * na.fit.rmse:.3f} / {1e3 * na.heldout_rmse:.3f} mrad.", "",
          f"Simulation error (free run with model switching, speed; the paper's Table III "
          f"metric), pooled: nominal {pooled_rmse(nb.sim_fitted):.4f} rad/s fitted, "
          f"{nb.sim_heldout_rmse:.4f} rad/s held-out → identified "
          f"{pooled_rmse(na.sim_fitted):.4f} / {na.sim_heldout_rmse:.4f} rad/s.", "",
          f"Per trial, as linear speed (× r = {r} m) next to the paper's Table III:", ""]
    L += _table3_rows(nb, na, r) + [""]
    L += ["![speed](speed_fit.png)", ""]
    L += ["## Friction and nominal force law", ""]
    if ident.friction:
        fr = ident.friction
        L += [f"τf = {fr.tau_f:.6f} N·m (95 % CI {fr.ci95[0]:.6f} … {fr.ci95[1]:.6f}) from "
              f"{fr.segments} coast-downs.", ""]
    else:
        L += ["No coast-down found: τf is fitted with the force law.", ""]
    L += [fit_status_text(nb, "nominal") + ("" if na is nb else
                                            "  " + fit_status_text(na, "identified")), ""]
    L += ["| parameter | nominal | 95 % CI | identified model |", "|---|---|---|---|"]
    for k, v in data["nominal"]["parameters"].items():
        after = na.fit.values.get(k, math.nan)
        L += [f"| {k} [{v['unit']}] | {v['value']:.5g} | {_ci(v['ci95'])} | {after:.5g} |"]
    L += ["", "The fit works in the coordinates the data determines (peak, centre, width, "
          "b = σ2/σ3, τf). σ1, σ4, σ6 trade off along one direction and σ2, σ3, σ6 along "
          "another (model-notes.md), so σ1 and σ3 stay at their reference values.", ""]
    if data.get("identifiability"):
        L += ["Identifiability (singular values of the data's sensitivity to the paper's "
              "parameters, relative):", "", "```"] + data["identifiability"] + ["```", ""]
    L += ["## Candidate effects", "",
          "Every candidate is added to the model and refitted by one Gauss-Newton step "
          "(score test); the most promising significant ones are refitted to convergence and "
          "cross-validated by trial. Accepted: held-out simulation error down ≥ 10 %, "
          "held-out window error down, and Wald p < 1e-6.",
          "", "| round | candidate | score χ² (dof) | p | refitted: window RMSE fitted / "
          "held-out [mrad] | fitted values | Wald p | verdict |",
          "|---|---|---|---|---|---|---|---|"]
    for c in data["candidates"]:
        ho = "–"
        if c["refitted"]:
            held = c["heldout_window_rmse_rad"]
            ho = (f"{1e3 * c['window_rmse_rad']:.3f} / " +
                  (f"{1e3 * held:.3f}" if held is not None else "not cross-validated"))
        wp = f"{c['wald_p']:.1e}" if c["wald_p"] is not None else "–"
        verdict = "**accepted**" if c["accepted"] else c["reason"]
        fitted = ", ".join(f"{k} {_fmt(v, '.4g')}" for k, v in (c["physical"] or {}).items())
        if c["ran_on"]:
            fitted = (fitted + " " if fitted else "") + RAN_ON_NOTE
        L += [f"| {c['round']} | `{c['id']}` | {c['score_statistic']:.1f} ({c['score_dof']}) | "
              f"{c['score_p']:.1e} | {ho} | {fitted or '–'} | {wp} | {verdict} |"]
    for c in data["tried_together"]:
        held = c["heldout_window_rmse_rad"]
        ho = (f"{1e3 * c['window_rmse_rad']:.3f} / " +
              (f"{1e3 * held:.3f}" if held is not None else "not cross-validated"))
        L += [f"| {c['round']} | " + " + ".join(f"`{i}`" for i in c["ids"]) + f" | – | – | {ho} | – "
              f"| {'–' if c['wald_p'] is None else format(c['wald_p'], '.1e')} | "
              f"{'**accepted**' if c['accepted'] else c['reason']}"
              f"{' ' + RAN_ON_NOTE if c['ran_on'] else ''} |"]
    L += ["", "![evidence](evidence.png)", ""]
    L += ["## Residual diagnostics", ""]
    for label, d in (("nominal", ident.diagnostics_before), ("identified", ident.diagnostics_after)):
        if d is None:
            continue
        L += [f"* {label}: {100 * d.whiteness_outside:.0f} % of autocorrelation lags outside "
              f"the 99 % band (whiteness); max |cross-correlation with q| "
              f"{d.input_correlation_max:.3f} (band {d.band99:.3f}); acceleration residual "
              f"RMS {d.rms_accel:.3f} rad/s²"]
        pr = ident.prediction_before if label == "nominal" else ident.prediction_after
        if pr:
            L += ["  * one-step prediction residual (observer innovations, first "
                  f"{PREDICTION_SPAN:.0f} s of each trial): normalised RMS "
                  + ", ".join(f"{p.normalised_rms:.2f}" for p in pr.values())
                  + " (1 = as predicted); lags outside the 99 % band "
                  + ", ".join(f"{100 * p.whiteness_outside:.0f} %" for p in pr.values())]
        for s in d.signatures:
            L += [f"  * {s.text}"]
    L += ["", "![correlation](correlation.png)", "", "![structure](structure.png)", "",
          "![spectra](spectra.png)", ""]
    if closed_loop:
        L += ["## Closed loop: nominal vs identified model in the controller", "",
              "| controller model | tracking RMSE [rad/s] | NRMSE |", "|---|---|---|"]
        for name, m in closed_loop.items():
            L += [f"| {name} | {m['rmse']:.4f} | {m['nrmse']:.4f} |"]
        L += [""]
    return "\n".join(L) + "\n"


def write_report(ident: Identification, out: Path | str, identifiability: list[str] | None = None,
                 closed_loop: dict | None = None, provenance: dict | None = None) -> dict:
    """Write report.md, report.json, the figures and model.yaml under ``out``; returns the
    JSON dict."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    figures = [plots.speed_fits(ident, out), plots.evidence(ident, out)]
    if ident.diagnostics_before is not None:
        figures += [plots.correlations(ident.diagnostics_before, ident.diagnostics_after, out),
                    plots.structure(ident.diagnostics_before, ident.diagnostics_after, out),
                    plots.spectra(ident.diagnostics_before, ident.diagnostics_after, out)]
    params, ext, left_out = ident.model()
    save_model(out / "model.yaml", params, ext,
               dict(provenance or {}, tool="hasel_wheel identify",
                    chosen_effects=list(ident.chosen), left_out_effects=left_out))
    data = to_json(ident, figures, left_out)
    if identifiability:
        data["identifiability"] = identifiability
    if closed_loop:
        data["closed_loop"] = {name: {"rmse_rad_s": _num(m["rmse"]), "nrmse": _num(m["nrmse"]),
                                      "segment_steady_error_percent":
                                          [_num(v) for v in m["segment_steady_error"]],
                                      "decisions": m["decisions"], "braking": m["braking"]}
                               for name, m in closed_loop.items()}
    (out / "report.json").write_text(json.dumps(data, indent=2, sort_keys=False) + "\n")
    (out / "report.md").write_text(to_markdown(ident, data, closed_loop))
    return data
