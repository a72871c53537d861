"""``hasel_wheel identify`` and ``hasel_wheel trials``: the identification from the command line.

    hasel_wheel trials --plant my_plant.yaml --out data/        # synthetic trials as CSV
    hasel_wheel identify data/*.csv --out report/               # or bag directories / .mcap

``identify`` writes report.md (+ PNG figures), report.json and model.yaml under ``--out``
and prints a summary.  Run as a command (``hasel_wheel identify ...``), it runs OpenBLAS's
Haswell kernels (:func:`.numerics.rerun_pinned`: the same report for the same recording on
every x86-64 machine; test_numerics.py).  With ``--compare-plant`` it also runs the
closed-loop demo profile on that plant twice, with the nominal and with the identified
model in the controller, and adds their tracking errors to the report.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

from hasel_wheel_sim.params import WheelParams, load_wheel_params
from hasel_wheel_sim.plant import PlantConfig, load_plant_config

from hasel_wheel_ident import candidates as C
from hasel_wheel_ident import synthetic as S
from hasel_wheel_ident.data import TrialError, load_trials, separate_wheels, write_csv
from hasel_wheel_ident.numerics import rerun_pinned


def _ids(text: str | None) -> list[str] | None:
    return [s.strip() for s in text.split(",") if s.strip()] if text else None


def cmd_identify(args: argparse.Namespace) -> int:
    """Identify, write the report, print a summary."""
    if sys.argv[1:2] == ["identify"]:        # this process is the command, not a caller's
        rerun_pinned()
    from hasel_wheel_ident.identifiability import identifiability    # (matplotlib only when needed)
    from hasel_wheel_ident.report import near_miss_text, stall_texts, write_report
    from hasel_wheel_ident.select import identify

    t0 = time.perf_counter()
    try:
        lib = C.library(_ids(args.only), _ids(args.exclude))      # before reading any data
        trials = load_trials(args.inputs)
    except (TrialError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for path in args.inputs:
        note = separate_wheels(path) if Path(path).suffix.lower() != ".csv" else None
        if note:
            print(f"warning: {note}", file=sys.stderr)
    base = load_wheel_params(args.wheel_params) if args.wheel_params else WheelParams()
    print(f"{len(trials)} trials, {sum(t.duration for t in trials):.0f} s; candidates: "
          f"{', '.join(c.id for c in lib)}")
    try:
        ident = identify(trials, base, library=lib, k_folds=args.folds,
                         max_effects=args.max_effects, threads=args.threads,
                         progress=None if args.quiet else print,
                         progress_bars=None if args.quiet else "identify")
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    ident_text = None
    if ident.problem_before is not None:
        prob = ident.problem_before
        ident_text = identifiability(prob, ident.nominal.fit.params,
                                     prob.window_starts(ident.nominal.fit.z)).text(tol=1e-4)
    closed = None
    if args.compare_plant:
        from hasel_wheel_ident.model_compare import compare_controllers
        params, ext, _ = ident.model()
        cfg = load_plant_config(args.compare_plant)
        closed = compare_controllers(base, cfg, {"nominal (paper model)": (base, None),
                                                 "identified": (params, ext)})
    data = write_report(ident, args.out, ident_text, closed,
                        {"inputs": [str(p) for p in args.inputs]})
    dt = time.perf_counter() - t0
    print(f"chosen effects: {', '.join(data['chosen_effects']) or 'none'}")
    for e in data["effects"]:
        print(f"  {e['id']}: " + ", ".join(f"{k} = {v:.4g}" for k, v in e["physical"].items()
                                             if isinstance(v, float)))
    for text in stall_texts(data):
        print(f"  stalled: {text}")
    for m in data["near_misses"]:
        print(f"  near miss, refused at the free-run bar: {near_miss_text(m)}")
    for u in data["unexplained"]:
        print(f"  unexplained: {u['text']}")
    if data["session"]["gain_step"]:
        print(f"  changed in the session: {data['session']['gain_step']['text']}")
    mb, ma = data["metrics"]["before"], data["metrics"]["after"]
    print(f"held-out simulation error {mb['simulation']['pooled_heldout_rmse_rad_s']:.4f} -> "
          f"{ma['simulation']['pooled_heldout_rmse_rad_s']:.4f} rad/s; held-out window error "
          f"{1e3 * mb['heldout_window_rmse_rad']:.3f} -> {1e3 * ma['heldout_window_rmse_rad']:.3f}"
          f" mrad")
    print(f"report: {Path(args.out) / 'report.md'} ({dt:.0f} s)")
    return 0


def cmd_trials(args: argparse.Namespace) -> int:
    """Record the paper's five open-loop trials on a plant and write them as CSV files (as one
    session with ``--session-gap``)."""
    cfg = load_plant_config(args.plant) if args.plant else PlantConfig(switching="tick")
    base = load_wheel_params(args.wheel_params) if args.wheel_params else None
    specs = tuple(S.SyntheticTrial(math.radians(a), drive=args.drive, coast=args.coast)
                  for a in args.phi_a_deg)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.session_gap is not None and not args.session_gap >= 0.0:
        print(f"error: --session-gap {args.session_gap!r}: expected seconds >= 0",
              file=sys.stderr)
        return 2
    trials = (S.record_set(specs, base, cfg, progress="trials") if args.session_gap is None
              else S.record_session(specs, args.session_gap, base, cfg, progress="trials"))
    for tr in trials:
        write_csv(tr, out / f"{tr.name}.csv")
        print(f"{out / (tr.name + '.csv')}: {tr.duration:.1f} s")
    return 0


def add_parsers(sub) -> None:
    """Add ``identify`` and ``trials`` to the ``hasel_wheel`` sub-command parser."""
    i = sub.add_parser("identify", help="fit the model to trials, find the missing effect, report")
    i.add_argument("inputs", nargs="+", help="CSV files, bag directories or .mcap files")
    i.add_argument("--out", default="out/identify", help="report directory")
    i.add_argument("--wheel-params", default=None,
                   help="wheel_params.yaml with the geometry and the reference force law")
    i.add_argument("--only", help="comma-separated candidate ids to try (default: all)")
    i.add_argument("--exclude", help="comma-separated candidate ids not to try")
    i.add_argument("--folds", type=int, default=5, help="k of the k-fold by trial (default 5)")
    i.add_argument("--max-effects", type=int, default=2)
    i.add_argument("--threads", type=int, default=2)
    i.add_argument("--quiet", action="store_true", help="no progress lines or bars")
    i.add_argument("--compare-plant", default=None,
                   help="plant yaml: run the closed loop with nominal vs identified controller")
    i.set_defaults(func=cmd_identify)
    t = sub.add_parser("trials", help="record the paper's open-loop trials on a plant, as CSV")
    t.add_argument("--plant", default=None,
                   help="plant yaml (seed, switching, effects; default: nominal, tick switching)")
    t.add_argument("--wheel-params", default=None)
    t.add_argument("--out", default="out/trials")
    t.add_argument("--phi-a-deg", type=float, nargs="+", default=[1.0, 3.0, 5.0, 7.0, 9.0])
    t.add_argument("--drive", type=float, default=50.0, help="[s] driven, then --coast [s]")
    t.add_argument("--coast", type=float, default=10.0)
    t.add_argument("--session-gap", type=float, default=None, metavar="S",
                   help="[s] record the trials back to back on one plant as a session, S s at "
                        "rest between them (the CSVs carry session_t); default: each trial "
                        "on a fresh plant")
    t.set_defaults(func=cmd_trials)
