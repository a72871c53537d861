"""Benchmark of the identification against each effect the plant simulator can produce:
the figures the README quotes in "Identification", beyond ``bench_ident.py``.

For each effect, switched on alone in the plant and never declared to the tool, through the
10-bit encoder with 1 mrad noise:

* on the paper's five trials (5 x 60 s): what the whole-library search chose, its estimate
  against the truth, the held-out simulation error before and after, the error of the true
  model (the plant's own parameters: the floor that no identified model can go below, since
  a free run drifts from the recording once a switch falls on the other side of a tick), and
  the wall time of the full run (nominal fit, search and residual analysis: the issue's
  target is 120 s on 5 x 60 s);
* for the rise lag and charge retention also on three short trials (3 x 34 s), where they are
  harder to see; charge retention at two rates (0.01/s, below what the data can show, and
  0.05/s), with the 95 % interval of each estimate.

Then two effects that the nominal fit absorbs by bending its force law far (3 x 34 s, plant
seed 7): a weak off-centre mass and a 120 ms rise lag.  Then a rise lag plus viscous drag
named together, and viscous drag outside the library reported as a residual that is not
white (3 x 34 s, plant seeds 11 and 12).  Then an angle sensor off the axle, at 5 and 20 mrad,
with the whole library and with its candidate left out (3 x 34 s, plant seed 11).  Then effects
outside the library whose signature is not periodic: a gain spread (along the actuator index)
and the rise-lag/retention look-alikes on 5 x 60 s (``--outside-only`` runs just these).  Then a gain spread whose fit ends in a poorer optimum (the check that an effect's gain is its own,
select.optimum_not_effect).  Then every effect of the realistic plant at once (up to four chosen; REALISTIC in
hasel_wheel_sim.effects, with the link effects), as a real wheel would have them.
Then the closed loop on a COM plant: tracking RMSE with the nominal and with the true model in
the controller, with the default observer and with its disturbance state off.

Run: ``.venv/bin/python benchmarks/bench_ident_effects.py`` (about 15 minutes; also part of
``./dev bench``); ``--closed-loop-only`` runs only the last part (seconds).
"""
from __future__ import annotations

import math
import re
import time
from pathlib import Path

from hasel_wheel_ident.numerics import pin_blas_kernels

pin_blas_kernels()  # before numpy loads: the kernels the printed figures come from (.numerics)
import numpy as np  # noqa: E402  (this and the imports below: after the pin)

from hasel_wheel_ident import candidates as C  # noqa: E402
from hasel_wheel_ident import fit as F  # noqa: E402
from hasel_wheel_ident import metrics as M  # noqa: E402
from hasel_wheel_ident import report as R  # noqa: E402
from hasel_wheel_ident import select as SEL  # noqa: E402
from hasel_wheel_ident import unexplained as UNX  # noqa: E402
from hasel_wheel_ident.identification import Identification  # noqa: E402
from hasel_wheel_ident import synthetic as S  # noqa: E402
from hasel_wheel_ident import truth_cases as T  # noqa: E402
from hasel_wheel_ident import verdict as V  # noqa: E402
from hasel_wheel_ident.cautions import caution  # noqa: E402
from hasel_wheel_ident.consistency import leans  # noqa: E402
from hasel_wheel_ident.model_compare import compare_controllers  # noqa: E402
from hasel_wheel_mpc.observer import ObserverConfig  # noqa: E402
from hasel_wheel_sim.effects import REALISTIC, effects_from_mapping  # noqa: E402
from hasel_wheel_sim.model import Extensions  # noqa: E402
from hasel_wheel_sim.params import WheelParams  # noqa: E402
from hasel_wheel_sim.plant import PlantConfig  # noqa: E402

#: the encoder every case records through; the cases themselves are truth_cases'
ENCODER = S.ENCODER


def run(case: T.Case) -> None:
    """One effect in the library alone (truth_cases.IN_LIBRARY): its verdict, estimates
    against the plant's values, the held-out error before and after and the true model's."""
    label, cid, truth = case.label, case.cid, case.shown
    trials = S.encoder_trials(case.effects, seed=case.seed, specs=case.specs)
    t0 = time.perf_counter()
    res = SEL.identify(trials, k_folds=min(5, len(trials)))
    dt = time.perf_counter() - t0
    v = res.final.fit.values
    ci = res.final.fit.ci95
    est = ", ".join(f"{k} {v[k]:.4g} (95 % {ci[k][0]:.3g} to {ci[k][1]:.3g}; true {t:g})"
                    for k, t in truth.items() if k in v)
    if cid in res.chosen and cid in ("gain_spread", "platform_periodic", "com_offset"):
        d = C.BY_ID[cid].describe([v[p.name] for p in C.BY_ID[cid].params])
        est = ", ".join(f"{k} {x:.4g}" for k, x in d.items() if isinstance(x, float))
    before, after = res.nominal.sim_heldout_rmse, res.final.sim_heldout_rmse
    floor, ref = "", None
    if case.true_values is not None:
        ref = T.true_model_error(trials, cid, case.true_values)
        floor = f" (true model {ref:.4f}: x{before / ref:.2f} smaller than before)"
    verdict = V.verdict(res.chosen, cid, before, ref)
    refits = "; ".join(f"{'+'.join(e.effects)} {'accepted' if e.accepted else 'refused'} "
                       f"(Wald p {e.wald_p:.1e})" for r in res.rounds for e in r)
    refits += near(res)
    print(f"{label}, {case.tag}: chosen {res.chosen or 'none'} ({verdict}); "
          f"{est}; held-out simulation error {before:.4f} -> {after:.4f} rad/s "
          f"(x{before / after:.2f} smaller){floor}; refits: {refits or 'none'}; {dt:.0f} s")


def near(res: Identification) -> str:
    """The near misses of ``res`` (report.near_miss_texts) as "; near miss ..." each; every
    case's line ends with them."""
    return "".join(f"; near miss {m}" for m in R.near_miss_texts(res))


def _identify_short(effects: dict, seed: int, library=C.LIBRARY, analyse: bool = False):
    """(trials, identification, wall time [s], the refits in words) for ``effects`` on
    3 x 34 s with the candidates of ``library``, with the residual analysis if ``analyse``."""
    trials = S.encoder_trials(effects, seed=seed)
    t0 = time.perf_counter()
    res = SEL.identify(trials, k_folds=3, library=library, analyse_residuals=analyse)
    dt = time.perf_counter() - t0
    refits = "; ".join(f"{'+'.join(e.effects)} {'accepted' if e.accepted else 'refused'} "
                       f"({e.reason.split(';')[0]})" for r in res.rounds for e in r) + near(res)
    return trials, res, dt, refits


def run_two_and_outside() -> None:
    """Cases on 3 x 34 s: a 50 ms rise lag plus viscous drag of 1e-3 (plant seed 11), named
    together since select.further_refits / tied_pair; viscous drag of 1e-3 plus a gain
    spread of std 0.1 (plant seed 4), named together since select.supported_pair; and
    viscous drag of 1.5e-3 with its candidate left out (plant seed 12), reported as a
    residual that is not white
    (residual.autocorrelation_signature), then with the whole library."""
    visc = {"viscous_drag": {"enabled": True, "coefficient": {"value": 1e-3,
                                                             "unit": "N*m*s/rad"}}}
    rise = {"rise_lag": {"enabled": True, "time_constant": {"value": 0.05, "unit": "s"}}}
    trials, res, dt, refits = _identify_short({**visc, **rise}, seed=11)
    v = res.final.fit.values
    base = WheelParams()
    ref = M.model_error(trials, base, (C.BY_ID["viscous_drag"], C.BY_ID["rise_lag"]),
                        dict(F.force_coordinates(base), tau_f=base.tau_f, c=1e-3, tau=0.05))
    before, after = res.nominal.sim_heldout_rmse, res.final.sim_heldout_rmse
    print(f"rise lag 50 ms + viscous drag 1e-3, 3 x 34 s, plant seed 11: chosen "
          f"{res.chosen or 'none'}; c {v.get('c', math.nan):.4g} (true 0.001), tau "
          f"{v.get('tau', math.nan):.4g} (true 0.05); held-out simulation error {before:.4f}"
          f" -> {after:.4f} rad/s (x{before / after:.2f}; true model {ref:.4f}: "
          f"x{before / ref:.2f}); refits: {refits}; {dt:.0f} s")
    spread = {"gain_spread": {"enabled": True, "std": {"value": 0.1, "unit": "1"}}}
    _, res, dt, refits = _identify_short({**visc, **spread}, seed=4)
    v = res.final.fit.values
    std = (C.BY_ID["gain_spread"].describe([v[f"d{i}"] for i in range(1, 16)])["std"]
           if "gain_spread" in res.chosen else math.nan)
    print(f"viscous drag 1e-3 + gain spread std 0.1, 3 x 34 s, plant seed 4: chosen "
          f"{res.chosen or 'none'}; c {v.get('c', math.nan):.4g} (true 0.001), gain std "
          f"{std:.3f}; held-out simulation error {res.nominal.sim_heldout_rmse:.4f} -> "
          f"{res.final.sim_heldout_rmse:.4f} rad/s; refits: {refits}; {dt:.0f} s")
    trials = S.encoder_trials(T.DRAG_OUTSIDE, seed=T.DRAG_SEED)
    for label, lib in (("its candidate left out", C.library(exclude=["viscous_drag"])),
                       ("the whole library", C.LIBRARY)):
        t0 = time.perf_counter()
        res = SEL.identify(trials, library=lib, k_folds=3)
        dt = time.perf_counter() - t0
        d = res.diagnostics_after
        sigs = "; ".join(s.text for s in d.signatures) or "none"
        ok = not T.drag_failures(res, whole_library=lib is C.LIBRARY)
        print(f"viscous drag 1.5e-3, 3 x 34 s, plant seed 12, {label}: "
              f"{'right' if ok else 'WRONG'}; chosen "
              f"{res.chosen or 'none'}; held-out simulation error "
              f"{res.nominal.sim_heldout_rmse:.4f} -> {res.final.sim_heldout_rmse:.4f} rad/s;"
              f" mean autocorrelation over 0.2 s {d.correlated_share:.4f} (white sd "
              f"{d.correlated_share_sd:.4f}); lags outside the 99 % band "
              f"{100 * d.whiteness_outside:.0f} %; unexplained: {sigs}{near(res)}; {dt:.0f} s")


def run_sensor() -> None:
    """An angle sensor off the axle (reads xi1 + e sin(xi1 + 0.3)), 3 x 34 s, plant seed 11:
    at 5 and 20 mrad with the whole library (named, against the truth and the true model's
    error), and with its candidate left out (the off-centre mass refused as a stand-in,
    ident/consistency.py; the signature)."""
    for amp in (0.005, 0.02):
        ecc = T.eccentric(amp)
        trials, res, dt, refits = _identify_short(ecc, seed=11)
        got = ""
        if "angle_eccentricity" in res.chosen:
            v = res.final.fit.values
            d = C.BY_ID["angle_eccentricity"].describe([v["E"], v["F"]])
            got = (f"amplitude {1e3 * d['amplitude_rad']:.2f} mrad (true {1e3 * amp:.0f}), "
                   f"phase {d['phase_rad']:.3f} rad (true 0.3); ")
        floor = T.true_model_error(trials, "angle_eccentricity",
                                   {"E": amp * math.sin(0.3), "F": amp * math.cos(0.3)})
        print(f"sensor eccentricity {1e3 * amp:.0f} mrad, 3 x 34 s, plant seed 11: chosen "
              f"{res.chosen}; {got}held-out simulation error {res.nominal.sim_heldout_rmse:.4f}"
              f" -> {res.final.sim_heldout_rmse:.4f} rad/s (true model {floor:.4f}); "
              f"refits: {refits}; {dt:.0f} s")
        trials, res, dt, refits = _identify_short(
            ecc, seed=11, library=C.library(exclude=["angle_eccentricity"]), analyse=True)
        stand = [e.reason[e.reason.find("size ~"):].split(";")[0] for r in res.rounds
                 for e in r if "not the same in every trial" in e.reason]
        sigs = " | ".join(sig.text.split("; refitted to it")[0]
                          for sig in res.diagnostics_after.signatures)
        # the 5 mrad case (truth_cases.eccentricity_failures), and the off-centre mass
        # refused as a stand-in, its torque growing with the speed (J e xi2^2: k near 2)
        com = [e for r in res.rounds for e in r if e.effects == ("com_offset",)]
        k = re.search(r"speed\^k, k = ([+-][0-9.]+)", com[0].reason) if com else None
        ok = (not T.eccentricity_failures(res) and k is not None
              and 0.5 < float(k.group(1)) < 2.5
              and "not the same in every trial" in com[0].reason)
        verdict = ("right" if ok else "WRONG") if amp == 0.005 else "no verdict (not tested)"
        print(f"  its candidate left out: {verdict}; chosen "
              f"{res.chosen or 'none'}; refused as stand-ins: "
              f"{' / '.join(stand) or 'none'}; unexplained: {sigs or 'none'}{near(res)}; "
              f"{dt:.0f} s")


def run_outside_library() -> None:
    """Effects left out of the library, whose right signature is not periodic: a gain spread
    of std 0.1 (3 x 34 s, plant seed 11; reported along the actuator index, ident/actuator.py:
    its factors against the plant's gains), and the look-alike losses on the paper's
    protocol (5 x 60 s, plant seeds 11-13): a 40 ms rise lag and charge retention of 0.2/s
    and 0.05/s (each should leave a drift along its own axis, nothing named); and the first
    two on 3 x 34 s (seeds 11-13), where they are harder to tell apart."""
    spread = {"gain_spread": {"enabled": True, "std": {"value": 0.1, "unit": "1"}}}
    trials, res, dt, _ = _identify_short(spread, seed=11,
                                         library=C.library(exclude=["gain_spread"]), analyse=True)
    truth = np.array(effects_from_mapping({**ENCODER, **spread}).extensions(
        np.random.default_rng(11)).gains)
    truth /= np.exp(np.mean(np.log(truth)))
    line = f"gain spread std 0.1 outside the library, 3 x 34 s, seed 11: chosen {res.chosen or 'none'}"
    for sig in res.diagnostics_after.signatures:
        line += f"; unexplained along {sig.axis}"
        if sig.factors is not None:
            f = np.array(sig.factors)
            line += (f" (factors: r = {np.corrcoef(np.log(f), np.log(truth))[0, 1]:.3f} with the "
                     f"plant's gains, std {np.std(f):.3f} against {np.std(truth):.3f}, largest "
                     f"difference {np.max(np.abs(f - truth)):.3f})")
    print(line + f"; unconfirmed: {[u.axis for u in res.unconfirmed]}{near(res)}; {dt:.0f} s")
    wrong = 0
    for case in T.LOOK_ALIKES:
        label, cid, seed, specs = case.label, case.cid, case.seed, case.specs
        trials = S.encoder_trials(case.effects, seed=seed, specs=specs)
        t0 = time.perf_counter()
        res = SEL.identify(trials, k_folds=5 if specs is S.PAPER_SET else 3,
                           library=C.library(exclude=[cid]))
        dt = time.perf_counter() - t0
        tr = res.diagnostics_after.trend
        drift = ("no drift" if tr is None else
                 f"drift along {tr.axis} (p = {tr.p_value:.1e}; "
                 + ", ".join(f"{k} {v:.1e}" for k, v in tr.p_values.items() if k != tr.axis)
                 + ")")
        cautions = [f"{i}: k = {c.exponent:+.2f} +- {c.exponent_sd:.2f} (p = {c.trend_p:.1e}"
                    f"{', leans on the speed: caution' if leans(c) else ''}), h = {c.drift:+.2f} "
                    f"+- {c.drift_sd:.2f} (p = {c.drift_p:.1e})"
                    for i, c in res.consistency.items()]
        others = [f"{s.axis} {s.period:.3g}" if s.period is not None else s.axis
                  for s in res.diagnostics_after.signatures if not UNX.drift_signature(s)]
        # each measuring device beside the final model, for the drift left
        devices = [f"{k} {d['value']:.3g} {d['unit']}, free run {d['sim_rmse_rad_s']:.4f} "
                   f"rad/s (model {d['sim_rmse_model_rad_s']:.4f})"
                   for s in res.diagnostics_after.signatures if UNX.drift_signature(s)
                   for k, d in s.devices.items()]
        if devices:
            drift += " measured beside the model by " + "; ".join(devices)
        moved = [s.axis for s in res.diagnostics_after.signatures
                 if UNX.drift_signature(s) and tr is not None and s.axis != tr.axis]
        if moved:
            drift += f"; reported along {moved[0]} (the device that takes up the most)"
        # the look-alikes refused beside a device (consistency.drift_stand_in, lag_stand_in)
        beside = ["+".join(e.effects) + " " + e.reason[e.reason.index("refitted beside"):
                                                        e.reason.index(": there")]
                  for r in res.rounds for e in r if ": there it no longer holds" in e.reason]
        code, figures = T.look_alike_code(res, case)
        verdict = {"right": "right", "moved by the devices": "right, moved by the devices"}.get(
            code, f"WRONG: {figures}")
        wrong += verdict.startswith("WRONG")
        print(f"{label} outside the library, {len(specs)} x {specs[0].drive + specs[0].coast:.0f}"
              f" s, seed {seed}: {verdict}; chosen "
              f"{res.chosen or 'none'} ({'; '.join(cautions) or 'no checks'}); held-out "
              f"simulation error {res.nominal.sim_heldout_rmse:.4f} -> "
              f"{res.final.sim_heldout_rmse:.4f} rad/s; {drift}; other signatures "
              f"{others or 'none'}; unconfirmed {len(res.unconfirmed)}"
              + "".join(f"; refused {b}" for b in beside)
              + near(res) + f"; {dt:.0f} s")
    print(f"look-alikes outside the library: {len(T.LOOK_ALIKES) - wrong} of "
          f"{len(T.LOOK_ALIKES)} right")


def run_restarted() -> None:
    """A gain spread of std 0.15 on 3 x 34 s (plant seed 4), up to two effects: the gain
    spread's fit ends in a poorer optimum, from which a rise lag offers a way out; the check
    of select.optimum_not_effect refuses the rise lag and refits the gain spread instead."""
    eff = {"gain_spread": {"enabled": True, "std": {"value": 0.15, "unit": "1"}}}
    trials = S.encoder_trials(eff, seed=4)
    t0 = time.perf_counter()
    res = SEL.identify(trials, k_folds=3, max_effects=2, analyse_residuals=False)
    dt = time.perf_counter() - t0
    refits = "; ".join(f"{'+'.join(e.effects)} {'accepted' if e.accepted else 'refused'}"
                       + ("" if e.accepted else f" ({e.reason.split('refused: ')[-1]})")
                       for r in res.rounds for e in r)
    refits += near(res)
    print(f"gain spread std 0.15, 3 x 34 s, plant seed 4, up to 2 effects: chosen "
          f"{res.chosen or 'none'}; final model: {res.final.reason}; held-out simulation error "
          f"{res.nominal.sim_heldout_rmse:.4f} -> {res.final.sim_heldout_rmse:.4f} rad/s; "
          f"refits: {refits}; {dt:.0f} s")


def run_realistic() -> None:
    """Every effect of the realistic plant at once (what a real wheel has), up to 4 effects."""
    trials = S.record_set(S.PAPER_SET, config=PlantConfig(seed=3, switching="tick",
                                                          effects=effects_from_mapping(REALISTIC)))
    t0 = time.perf_counter()
    res = SEL.identify(trials, k_folds=5, max_effects=4)
    dt = time.perf_counter() - t0
    v = res.final.fit.values
    found = []
    for cid in res.chosen:
        c = C.BY_ID[cid]
        d = c.describe([v[p.name] for p in c.params])
        found.append(f"{cid} " + ", ".join(f"{k} {x:.4g}" for k, x in d.items()
                                           if isinstance(x, float)))
    refits = "; ".join(f"{'+'.join(e.effects)} {'accepted' if e.accepted else 'refused'} "
                       f"({e.reason})" for r in res.rounds for e in r)
    refits += near(res)
    unexplained = "; ".join(s.text for s in res.diagnostics_after.signatures) or "none"
    print(f"all effects of the realistic plant at once (REALISTIC, 5 x 60 s, up to 4 effects): "
          f"chosen {res.chosen or 'none'}: {'; '.join(found)}; tau_f "
          f"{v['tau_f'] / WheelParams().tau_f - 1:+.1%} of the paper's (viscous drag 5e-4 on "
          f"top); held-out simulation error {res.nominal.sim_heldout_rmse:.4f} -> "
          f"{res.final.sim_heldout_rmse:.4f} rad/s; unexplained: {unexplained}; refits: "
          f"{refits}; {dt:.0f} s")
    # each chosen effect as it was checked when added: trial by trial, and on the halves
    # of each drive (a drift is a caution, not a refusal)
    for cid, con in res.consistency.items():
        print(f"  {cid}: size ~ speed^k, k = {con.exponent:+.2f} +- {con.exponent_sd:.2f} "
              f"(p = {con.trend_p:.1e}); size ~ hv^h, h = {con.drift:+.2f} +- "
              f"{con.drift_sd:.2f} (p = {con.drift_p:.1e})"
              + "".join(f"; {b.text(cid)}" for b in (con.beside, con.beside_lag) if b)
              + ("; caution" if caution(C.BY_ID[cid], con) else ""))


def run_sessions() -> None:
    """Sessions of the five paper trials (order 5, 1, 9, 3, 7 deg, 20 s at rest between
    them, plant seed 3) whose effects carry from one trial to the next, read from CSVs with
    their session_t column and from one bag of the whole session: charge retention at two
    rates (recovery 300 s), friction rising 25 % per 7 min, and one pad whose force falls to
    0.15 between the second and the third trial; then a clean session."""
    import tempfile
    from hasel_wheel_ident.session import as_session
    ret = lambda rate: {"charge_retention": {"enabled": True,                 # noqa: E731
                                             "rate": {"value": rate, "unit": "1/s"},
                                             "recovery": {"value": 300.0, "unit": "s"}}}
    cases = [(f"retention {r:g}/s carried over", ret(r), S.SessionChanges(), ("rate", r))
             for r in (0.02, 0.05)]
    cases += [("friction +25 % per 7 min", {}, S.SessionChanges(friction_rate=0.25 / 420), None),
              ("pad 5 falls to 0.15 before trial 3", {},
               S.SessionChanges(step_pad=5, step_trial=2, step_factor=0.15), None),
              ("clean session", {}, S.SessionChanges(), None)]
    for label, effects, changes, truth in cases:
        for via in ("csv", "bag"):
            with tempfile.TemporaryDirectory() as tmp:
                trials = S.session_trials(effects, changes, via=via, directory=Path(tmp))
            t0 = time.perf_counter()
            res = SEL.identify(trials, k_folds=5)
            dt = time.perf_counter() - t0
            before, after = res.nominal.sim_heldout_rmse, res.final.sim_heldout_rmse
            line = (f"session, {label}, {via}: chosen {res.chosen or 'none'}; held-out "
                    f"simulation error {before:.4f} -> {after:.4f} rad/s")
            if truth is not None:
                v = res.final.fit.values
                ref = T.true_model_error(as_session(trials).trials, "charge_retention",
                                         {"rate": truth[1], "recovery": 300.0})
                line += (f" (true model {ref:.4f}); rate {v.get('rate', math.nan):.4g} (true "
                         f"{truth[1]:g}), recovery {v.get('recovery', math.nan):.4g} (true 300)")
            ft = res.friction_trend
            if ft is not None and ft.significant:
                line += f"; friction rate {ft.rate:.4g}/s (true {changes.friction_rate:.4g}/s)"
            if res.gain_step is not None:
                g = res.gain_step
                line += (f"; step: pad {g.pad} before {g.trial}, gain {g.before:.3f} -> "
                         f"{g.after:.3f} (true 1 -> {changes.step_factor:g})")
            unx = [u.axis for u in (res.diagnostics_after.signatures
                                    if res.diagnostics_after else [])]
            print(line + f"; unexplained along {unx or 'nothing'}; {dt:.0f} s", flush=True)


def main() -> None:
    import argparse
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--closed-loop-only", action="store_true",
                    help="run only the closed loop on a COM plant (about a minute)")
    ap.add_argument("--outside-only", action="store_true",
                    help="run only the effects outside the library (about five minutes)")
    ap.add_argument("--session-only", action="store_true",
                    help="run only the sessions whose effects carry over (about 20 minutes)")
    args = ap.parse_args()
    if args.session_only:
        run_sessions()
        return
    if args.outside_only:
        run_outside_library()
        return
    if not args.closed_loop_only:
        for case in T.IN_LIBRARY:
            run(case)
        run_two_and_outside()
        run_sensor()
        run_outside_library()
        run_restarted()
        run_realistic()
        run_sessions()
    closed_loop_on_com()


def closed_loop_on_com() -> None:
    """Tracking RMSE [rad/s] of the loop with the nominal and the true model on a COM plant,
    with the default observer and with the observer's disturbance state off."""
    com = {"com_offset": {"enabled": True, "torque": {"value": 0.004, "unit": "N*m"},
                          "phase": {"value": 0.5, "unit": "rad"}}}
    plant = PlantConfig(seed=1, switching="tick", effects=effects_from_mapping({**ENCODER,
                                                                                **com}))
    models = {"nominal": (WheelParams(), None),
              "true": (WheelParams(), Extensions(com_torque=0.004, com_phase=0.5))}
    profile, duration = ((0.0, 1.0), (20.0, 1.5)), 40.0
    for label, kw in (("default observer", {}),
                      ("observer without its disturbance state",
                       {"observer_config": ObserverConfig(disturbance_rate=0.0, pivot_rate=0.0)})):
        m = compare_controllers(None, plant, models, profile, duration, **kw)
        ratio = m["true"]["rmse"] / m["nominal"]["rmse"]
        print(f"closed loop on a COM plant, {label}: tracking RMSE nominal "
              f"{m['nominal']['rmse']:.4f}, true model {m['true']['rmse']:.4f} rad/s "
              f"(ratio {ratio:.2f})")


if __name__ == "__main__":
    main()
