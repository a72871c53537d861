"""``report.md``, the identification report for people (:func:`to_markdown`)."""
from __future__ import annotations

import math
import re

from hasel_wheel_ident.evaluation import Evaluation
from hasel_wheel_ident.identification import Identification
from hasel_wheel_ident.metrics import pooled_rmse
from hasel_wheel_ident.prediction import PREDICTION_SPAN
from hasel_wheel_ident.report_text import fmt_number, fit_status_text, near_miss_text, stall_texts
from hasel_wheel_sim.paper import TABLE_III

#: report.md's note on the refit that stopped at its limit and ran on into the final model
RAN_ON_NOTE = "(where its fit stopped; it ran on to the chosen values above)"


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
    L += _result(ident, data)
    L += _errors(ident, nb, na)
    L += _friction(ident, data, nb, na)
    L += _session(data["session"])
    L += _candidates(data)
    L += _residuals(ident)
    L += _closed_loop(closed_loop)
    return "\n".join(L) + "\n"


def _result(ident: Identification, data: dict) -> list[str]:
    """The chosen effects with their checks, near misses and unexplained structure."""
    L: list[str] = []
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
                      f"{fmt_number(k['speed_exponent'], '+.2f')} +- {fmt_number(k['speed_exponent_sd'], '.2f')}"
                      f" (p = {fmt_number(k['speed_trend_p'], '.1e')}); on the halves of each drive: "
                      f"size ~ hv^h, h = {fmt_number(k['drift_exponent'], '+.2f')} +- "
                      f"{fmt_number(k['drift_exponent_sd'], '.2f')} (p = {fmt_number(k['drift_p'], '.1e')})"]
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
    return L


def _errors(ident: Identification, nb: Evaluation, na: Evaluation) -> list[str]:
    """The window and simulation errors before and after, and the Table III rows."""
    L: list[str] = []
    r = ident.base.r
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
    return L


def _friction(ident: Identification, data: dict, nb: Evaluation, na: Evaluation) -> list[str]:
    """tau_f, the fits' status and the nominal force law."""
    L: list[str] = []
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
          "another (docs/model.md), so σ1 and σ3 stay at their reference values.", ""]
    if data.get("identifiability"):
        L += ["Identifiability (singular values of the data's sensitivity to the paper's "
              "parameters, relative):", "", "```"] + data["identifiability"] + ["```", ""]
    return L


def _session(ses: dict) -> list[str]:
    """The trials in session order, friction per coast-down and its trend, a gain step."""
    L = ["## Session", ""]
    if ses["warning"]:
        L += [f"Warning: {ses['warning']}.", ""]
    if ses["timed"]:
        L += ["| trial | starts [s] | gap before [s] | duration [s] |", "|---|---|---|---|"]
        L += [f"| {e['name']} | {e['start_s']:.1f} | {_or_dash(e['gap_s'])} | "
              f"{e['duration_s']:.1f} |" for e in ses["trials"]] + [""]
    if ses["coast_friction"]:
        L += ["| coast-down of | session time [s] | τf [N·m] | 95 % CI |", "|---|---|---|---|"]
        L += [f"| {c['trial']} | {_or_dash(c['session_t_s'])} | {c['tau_f_N_m']:.6f} | "
              f"{c['ci95_N_m'][0]:.6f} … {c['ci95_N_m'][1]:.6f} |"
              for c in ses["coast_friction"]] + [""]
    if ses["friction_trend"]:
        L += [ses["friction_trend"]["text"] + ".", ""]
    if ses["gain_step"]:
        L += [ses["gain_step"]["text"] + ".", ""]
    return L


def _or_dash(x: float | None) -> str:
    """``x`` to one decimal, or a dash for None."""
    return "–" if x is None else f"{x:.1f}"


def _candidates(data: dict) -> list[str]:
    """The candidates table: every screened candidate and pair with its verdict."""
    L: list[str] = []
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
        fitted = ", ".join(f"{k} {fmt_number(v, '.4g')}" for k, v in (c["physical"] or {}).items())
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
    return L


def _residuals(ident: Identification) -> list[str]:
    """The residual diagnostics of the nominal and the identified model."""
    L: list[str] = []
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
    return L


def _closed_loop(closed_loop: dict | None) -> list[str]:
    """The closed-loop comparison (with ``--compare-plant``), or nothing."""
    L: list[str] = []
    if closed_loop:
        L += ["## Closed loop: nominal vs identified model in the controller", "",
              "| controller model | tracking RMSE [rad/s] | NRMSE |", "|---|---|---|"]
        for name, m in closed_loop.items():
            L += [f"| {name} | {m['rmse']:.4f} | {m['nrmse']:.4f} |"]
        L += [""]
    return L
