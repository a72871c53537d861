"""``report.json``, the identification report for machines (:func:`to_json`).

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
session                    {timed: the trials carried session times (then they are in
                            session order and effects with memory carry over, session.py),
                            warning: why not, or null, trials: [{name, start_s, gap_s,
                            duration_s}] (start_s, gap_s null when not timed; gap_s null
                            for the first), coast_friction: [{trial, session_t_s, tau_f_N_m,
                            ci95_N_m}] each coast-down in session order, friction_trend:
                            {tau_start_N_m, slope_N_m_per_s, slope_sd_N_m_per_s, p,
                            rate_per_s (slope / tau_start), span_s, significant, text} or
                            null (fewer than three timed coast-downs, friction_trend.py),
                            gain_step: {pad, trial (the first after it), previous, before,
                            after (gains relative to the median pad), before_ci95,
                            after_ci95, p, text} or null (steps.py)}
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
                            beside_hv_loss, beside_on_lag, caution, caution_codes} the
                            effect refitted trial by trial
                            (units "trial"), or span by span when the trials' speeds
                            differ by less than 1.2x ("span", each drive cut in up to
                            six), size ~ speed^k, and on the halves of each drive (size ~
                            hv^h), as checked when it was added (trial_refit.py);
                            caution: a sentence for each warning (its size leans on
                            the speed short of refusal, or changes within the
                            trials), else null; caution_codes the code of each
                            (reasons.Reason: leans_on_speed, drifts_within_trials,
                            holds_beside_hv_loss), [] when none; an exponent and its p
                            are null where they cannot be formed; beside_hv_loss
                            {rate_per_s, values, wald_p, device_wald_p, sim_rmse_rad_s,
                            sim_rmse_without_rad_s}: a
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
                            Identification.ran_on_from), reason, codes: [code, ...]
                            the verdict as reasons.Reason values (e.g. "accepted",
                            "sim_gain_below_bar", "implausible", "tie_not_named";
                            "score_not_significant" or "others_more_promising" when not
                            refitted)}]
tried_together             [{round, ids, window_rmse_rad, heldout_window_rmse_rad, wald_p,
                            accepted, ran_on, reason, codes (as for candidates)}] two effects refitted together because each
                            alone fitted the windows better but was refused
                            (refit_plan.supported_pair), or one alone was accepted and the
                            other, refused, fitted the held-out windows as well
                            (refit_plan.tied_pair); [] when none
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
                            shows it too: device_verdict.lead_device, residual.drift_along);
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
                            ratio), bar [1] (the cut the search asked for, 0.10), reason,
                            code: "near_miss", codes: the refit's verdict codes}]
                            refits turned away at the free-run bar with a cut of at least
                            half of it, that passed the other tests (acceptance.near_misses):
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

The stable effect identifiers are those of :mod:`.candidates` (docs/identification.md, "Candidate effects").
"""
from __future__ import annotations

import math

import numpy as np

from hasel_wheel_ident.acceptance import near_misses
from hasel_wheel_ident.candidates import BY_ID, Candidate
from hasel_wheel_ident.cautions import caution, cautions
from hasel_wheel_ident.consistency import Consistency
from hasel_wheel_ident.data import find_coasts
from hasel_wheel_ident.evaluation import Evaluation
from hasel_wheel_ident.fit import effect_wald_p, rest_tail
from hasel_wheel_ident.identification import Identification
from hasel_wheel_ident.measuring_devices import Beside
from hasel_wheel_ident.metrics import TrialMetrics, pooled_rmse
from hasel_wheel_ident.numerics import blas_in_use
from hasel_wheel_ident.reasons import Reason
from hasel_wheel_ident.residual import Diagnostics
from hasel_wheel_sim.paper import TABLE_III

SCHEMA = "hasel_wheel.identification/1"


def json_number(v):
    """JSON-safe number: nan and inf become null."""
    if v is None:
        return None
    v = float(v)
    return v if math.isfinite(v) else None


def _params(ev: Evaluation, names: list[str] | None = None) -> dict:
    fit = ev.fit
    out = {}
    for nm, unit in zip(fit.names, fit.units):
        if names is not None and nm not in names:
            continue
        out[nm] = {"value": json_number(fit.values[nm]), "unit": unit,
                   "ci95": [json_number(fit.ci95[nm][0]), json_number(fit.ci95[nm][1])]}
    return out


def _physical(c: Candidate, ev: Evaluation) -> dict[str, float | None]:
    """The scalar physical values (``Candidate.describe``) of ``c`` as ``ev`` fitted it."""
    d = c.describe(np.array([ev.fit.values[p.name] for p in c.params]))
    return {k: json_number(v) for k, v in d.items() if isinstance(v, float)}


def near_miss(e: Evaluation, final: Evaluation, bar: float) -> dict:
    """A refit :func:`~.acceptance.near_misses` lists, for report.json (``bar`` [1]: the
    search's ``min_gain``)."""
    added = e.effects[len(final.effects):]
    return {"ids": list(added),
            "physical": {i: _physical(BY_ID[i], e) for i in added},
            "wald_p": json_number(e.wald_p),
            "heldout_simulation_rmse_rad_s": json_number(e.sim_heldout_rmse),
            "final_heldout_simulation_rmse_rad_s": json_number(final.sim_heldout_rmse),
            "cut": json_number(1.0 - e.sim_heldout_rmse / final.sim_heldout_rmse),
            "bar": bar, "reason": e.reason, "code": str(Reason.NEAR_MISS),
            "codes": [str(c) for c in e.codes]}


def rest_tail_json(tr) -> dict | None:
    """report.json's ``rest_tail`` of a trial (:func:`~.fit.rest_tail`)."""
    rt = rest_tail(tr)
    if rt is None:
        return None
    return {"from_s": rt.from_s, "seconds": rt.seconds, "scheduled_share": rt.scheduled_share,
            "hv_share": rt.hv_share, "pad": rt.pad, "target": rt.target,
            "stalled": rt.stalled, "text": rt.text(tr.name) if rt.stalled else None}


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
        out[key] = [json_number(v - 1.96 * sd), json_number(v + 1.96 * sd)]
    return out


def _metrics(ev: Evaluation) -> dict:
    def t(m: TrialMetrics | None):
        return None if m is None else {k: (int(v) if k == "samples" else json_number(v))
                                       for k, v in m.as_dict().items() if k != "trial"}
    return {
        "window_rmse_rad": json_number(ev.fit.rmse),
        "heldout_window_rmse_rad": json_number(ev.heldout_rmse),
        "simulation": {
            "pooled_fitted_rmse_rad_s": json_number(pooled_rmse(ev.sim_fitted)),
            "pooled_heldout_rmse_rad_s": json_number(pooled_rmse(ev.sim_heldout))
            if ev.sim_heldout else None,
            "per_trial": {name: {"fitted": t(m), "heldout": t(ev.sim_heldout.get(name))}
                          for name, m in ev.sim_fitted.items()},
        },
    }


def _diagnostics(d: Diagnostics | None) -> dict | None:
    if d is None:
        return None
    return {"whiteness_outside": json_number(d.whiteness_outside), "band99": json_number(d.band99),
            "input_correlation_max": json_number(d.input_correlation_max),
            "rms_accel_rad_s2": json_number(d.rms_accel),
            "structures": {k: {"p_value": json_number(s.p_value), "amplitude_rad_s2": json_number(s.amplitude)}
                           for k, s in d.structures.items()}}


def _prediction(pr: dict) -> dict:
    return {name: {"rms_rad": json_number(p.rms), "normalised_rms": json_number(p.normalised_rms),
                   "whiteness_outside": json_number(p.whiteness_outside)} for name, p in pr.items()}


def _fit_status(ev: Evaluation) -> dict:
    return {"converged": bool(ev.fit.converged), "evaluations": int(ev.fit.nfev),
            "message": ev.fit.message}


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
                       "wald_p": json_number(effect_wald_p(ident.final.fit, c)),
                       "consistency": consistency_json(c, ident.consistency.get(cid))})
    candidates, together = [], []
    for k, scs in enumerate(ident.screenings):
        rd = ident.rounds[k] if k < len(ident.rounds) else []
        one = min((len(e.effects) for e in rd), default=0)     # the current model + one
        evs = {e.effects[-1]: e for e in rd if len(e.effects) == one}
        together += [{"round": k + 1, "ids": list(e.effects[one - 1:]),
                      "window_rmse_rad": json_number(e.fit.rmse),
                      "heldout_window_rmse_rad": json_number(e.heldout_rmse), "wald_p": json_number(e.wald_p),
                      "accepted": bool(e.accepted), "ran_on": e is ident.ran_on_from,
                      "reason": e.reason, "codes": [str(c) for c in e.codes]}
                     for e in rd if len(e.effects) > one]
        for s in scs:
            e = evs.get(s.candidate)
            candidates.append({
                "round": k + 1, "id": s.candidate, "score_statistic": json_number(s.statistic),
                "score_dof": s.dof, "score_p": json_number(s.p_value),
                "predicted_window_rmse_rad": json_number(s.predicted_rmse), "refitted": e is not None,
                "converged": bool(e.fit.converged) if e else None,
                "window_rmse_rad": json_number(e.fit.rmse) if e else None,
                "heldout_window_rmse_rad": json_number(e.heldout_rmse) if e else None,
                "wald_p": json_number(e.wald_p) if e else None,
                "parameters": (_params(e, [p.name for p in BY_ID[s.candidate].params])
                               if e else None),
                "physical": _physical(BY_ID[s.candidate], e) if e else None,
                "accepted": bool(e.accepted) if e else False,
                "ran_on": e is not None and e is ident.ran_on_from,
                "reason": e.reason if e else "score test not significant"
                if s.p_value >= 1e-6 else "significant, but others were more promising",
                "codes": [str(c) for c in e.codes] if e else [str(
                    Reason.SCORE_NOT_SIGNIFICANT if s.p_value >= 1e-6 else Reason.NOT_PROMISING)]})
    after = ident.diagnostics_after
    return {
        "schema": SCHEMA,
        "numerics": blas_in_use(),
        "trials": [{"name": tr.name, "source": tr.source, "duration_s": json_number(tr.duration),
                    "samples": int(tr.t.shape[0]), "activations": len(tr.activations),
                    "coasts": len(find_coasts(tr)), "rest_tail": rest_tail_json(tr)}
                   for tr in ident.trials],
        "friction": None if fr is None else {"tau_f_N_m": fr.tau_f,
                                             "ci95_N_m": list(fr.ci95), "segments": fr.segments},
        "session": session_json(ident),
        "nominal": {"parameters": _params(ident.nominal, nominal_names),
                    "wheel": {k: json_number(getattr(wheel, k)) for k in
                              ("sigma1", "sigma2", "sigma3", "sigma4", "sigma5", "sigma6",
                               "tau_f", "brake_gain")}},
        "fits": {"nominal": _fit_status(ident.nominal), "final": _fit_status(ident.final)},
        "chosen_effects": list(ident.chosen),
        "effects": chosen,
        "candidates": candidates,
        "tried_together": together,
        "unexplained": [] if after is None else [
            {"axis": s.axis, "unit": s.unit, "period": json_number(s.period),
             "amplitude_rad_s2": json_number(s.amplitude), "torque_N_m": json_number(s.torque),
             "p_value": json_number(s.p_value), "text": s.text, "phase_rad": json_number(s.phase),
             "torque_ci95_N_m": None if s.torque_ci95 is None else
             [json_number(v) for v in s.torque_ci95],
             "actuator_factors": None if s.factors is None else [json_number(v) for v in s.factors],
             "drift": s.drift,
             "drift_devices": {k: {n: json_number(v) if n != "unit" else v for n, v in d.items()}
                               for k, d in s.devices.items()}}
            for s in after.signatures],
        "near_misses": [near_miss(e, ident.final, ident.min_gain) for e in near_misses(ident)],
        "unconfirmed": [{"axis": s.axis, "period": json_number(s.period),
                         "amplitude_rad_s2": json_number(s.amplitude), "p_value": json_number(s.p_value),
                         "torque_ci95_N_m": None if s.torque_ci95 is None else
                         [json_number(v) for v in s.torque_ci95], "text": s.text}
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


def session_json(ident: Identification) -> dict:
    """The ``session`` key: the trials' order and gaps, friction per coast-down and its
    trend, a pad's gain step."""
    ses, tr, st = ident.session, ident.friction_trend, ident.gain_step
    entries = [] if ses is None else ses.entries
    return {
        "timed": bool(ses is not None and ses.timed),
        "warning": None if ses is None else ses.warning,
        "trials": [{"name": e.name, "start_s": json_number(e.start), "gap_s": json_number(e.gap),
                    "duration_s": json_number(e.duration)} for e in entries],
        "coast_friction": [{"trial": c.trial, "session_t_s": json_number(c.session_t),
                            "tau_f_N_m": json_number(c.tau_f),
                            "ci95_N_m": [json_number(v) for v in c.ci95]}
                           for c in ident.coast_friction],
        "friction_trend": None if tr is None else {
            "tau_start_N_m": json_number(tr.tau_start), "slope_N_m_per_s": json_number(tr.slope),
            "slope_sd_N_m_per_s": json_number(tr.slope_sd), "p": json_number(tr.p),
            "rate_per_s": json_number(tr.rate), "span_s": json_number(tr.span),
            "significant": tr.significant, "text": tr.text()},
        "gain_step": None if st is None else {
            "pad": st.pad, "trial": st.trial, "previous": st.previous,
            "before": json_number(st.before), "after": json_number(st.after),
            "before_ci95": [json_number(v) for v in st.before_ci95],
            "after_ci95": [json_number(v) for v in st.after_ci95], "p": json_number(st.p),
            "text": st.text()},
    }


def consistency_json(c: Candidate, con: Consistency | None) -> dict | None:
    """The effect refitted trial by trial and on the halves of each drive, for the JSON."""
    if con is None:
        return None
    speed = math.isfinite(con.exponent_sd)            # formed (see size_trends.speed_trend)
    drift = math.isfinite(con.drift_sd)
    return {"units": con.unit,
            "speed_exponent": json_number(con.exponent) if speed else None,
            "speed_exponent_sd": json_number(con.exponent_sd),
            "speed_trend_p": json_number(con.trend_p) if speed else None,
            "drift_exponent": json_number(con.drift) if drift else None,
            "drift_exponent_sd": json_number(con.drift_sd),
            "drift_p": json_number(con.drift_p) if drift else None,
            "beside_hv_loss": _beside(con.beside),
            "beside_on_lag": _beside(con.beside_lag),
            "caution": caution(c, con),
            "caution_codes": [f.code.value for f in cautions(c, con)]}


def _beside(b: Beside | None) -> dict | None:
    """An effect refitted beside a measuring device, for the JSON (the device's value under
    the key its ``describe`` gives it); None when it was not."""
    if b is None:
        return None
    (key, value), = b.device.describe([b.value]).items()
    return {key: json_number(value), "values": {k: json_number(v) for k, v in b.values.items()},
            "wald_p": json_number(b.p), "device_wald_p": json_number(b.device_p),
            "sim_rmse_rad_s": json_number(b.sim[0]),
            "sim_rmse_without_rad_s": json_number(b.sim[1])}
