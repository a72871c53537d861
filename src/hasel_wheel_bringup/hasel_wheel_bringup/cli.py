"""``hasel_wheel``: the embedded runner's command line (no ROS needed).

``hasel_wheel demo`` (the default) closes the speed loop on a Fig. 11-like profile on the
plant with realistic effects, records it to an MCAP bag, writes PNG plots and prints the
metrics next to the paper's, with comparison runs (no estimator, the paper's estimator, a
finite-difference speed).

``hasel_wheel table2`` runs the open-loop trials of ``config/demo_open_loop.yaml`` on the
paper's model, once with exact switching and once switching on 300 Hz firmware ticks,
records everything to an MCAP bag and prints the table next to the paper's Table II.
"""
from __future__ import annotations

import argparse
import dataclasses
import math
import shutil
import sys
import time
from pathlib import Path
from typing import Sequence

import numpy as np

from hasel_wheel_sim.params import ParameterError, load_wheel_params, load_yaml_file, packaged
from hasel_wheel_sim.plant import load_plant_config
from hasel_wheel_sim.trials_support import braking_fall_time, open_loop_speed
from hasel_wheel_sim.wheel import TICK

from hasel_wheel_bag.progress import progress_bar
from hasel_wheel_bringup import bag_cli
from hasel_wheel_ident import cli as ident_cli
from hasel_wheel_sim import paper
from hasel_wheel_mpc.recorder import Recorder, git_revision
from hasel_wheel_bringup.trials import TrialResult, run_trial, steady_speed, trials_from_mapping

#: Cross-check figures of an independent implementation of the model (the "reference" columns
#: of docs/benchmarks.md; hasel_wheel_sim's test_cross_check.py holds the model to them):
#: phi_a [deg] -> (exact w_ss [rad/s], exact t90 [s], tick w_ss [rad/s]).
NOTES_CROSS_CHECK = {1: (4.73, 26.6, 3.84), 5: (3.42, 22.5, 3.08), 9: (2.06, 16.1, 2.33),
                     11: (1.37, 9.8, 1.52)}


def _fmt(v: float | None, spec: str = "6.2f") -> str:
    return " " * len(format(0.0, spec)) if v is None or math.isnan(v) else format(v, spec)


def demo_table(exact: list[TrialResult], tick: list[TrialResult]) -> str:
    """The summary table of the demo as text."""
    lines = [
        "Open-loop trials, phi_d = 22 deg, 60 s from 1 rad/s (the cross-check's set-up).",
        "w_ss: mean speed over the last 10 s [rad/s]; t90: first time above 90 % of w_ss [s].",
        "paper: Table II, measured (m/s / 0.157 m); notes: independent cross-check (docs/benchmarks.md).",
        "",
        "        | model, exact switching | model, 300 Hz ticks | paper Table II  | ratio exact/paper | notes (exact)  | notes",
        " phi_a  |   w_ss      t90        |   w_ss      t90     |  w_ss     t_r   |  w_ss      t      |  w_ss    t90   | tick w_ss",
        "--------+------------------------+---------------------+-----------------+-------------------+----------------+----------",
    ]
    for e, k in zip(exact, tick):
        deg = int(round(math.degrees(e.spec.phi_a)))
        ps, pt = paper.table_ii_speed(deg), paper.table_ii_rise(deg)
        ns, nt, nk = NOTES_CROSS_CHECK.get(deg, (None, None, None))
        rs = e.steady_speed / ps if ps else None
        rt = e.t90 / pt if pt else None
        lines.append(
            f" {deg:3d} deg| {_fmt(e.steady_speed)}  {_fmt(e.t90, '7.2f')}        |"
            f" {_fmt(k.steady_speed)}  {_fmt(k.t90, '7.2f')}     |"
            f" {_fmt(ps, '5.2f')}  {_fmt(pt, '6.2f')}  |"
            f"  {_fmt(rs, '5.2f')}    {_fmt(rt, '5.2f')}    |"
            f"  {_fmt(ns, '5.2f')}  {_fmt(nt, '5.1f')}  |  {_fmt(nk, '5.2f')}")
    return "\n".join(lines)


def _fresh_bag_dir(out: Path) -> Path | None:
    """out/bag, ready to be written: removed first if it is an earlier bag of ours (it has a
    metadata.yaml) or empty (a run killed before it recorded anything).  None, with an error
    printed, if it holds anything else: that is left as it is."""
    bag_dir = out / "bag"
    if bag_dir.exists():
        if bag_dir.is_dir() and not any(bag_dir.iterdir()):
            bag_dir.rmdir()
        elif not (bag_dir / "metadata.yaml").exists():
            print(f"error: {bag_dir} exists but is not a bag written by this tool (no "
                  f"metadata.yaml: another file, or a recording cut off before it closed); "
                  f"it is left as it is: choose another --out or move it away", file=sys.stderr)
            return None
        else:
            shutil.rmtree(bag_dir)
    out.mkdir(parents=True, exist_ok=True)
    return bag_dir


def cmd_demo(args: argparse.Namespace) -> int:
    """Closed-loop demo: run, record, plot, print the metrics beside the paper's."""
    from hasel_wheel_mpc.closed_loop import controller_config
    from hasel_wheel_sim.effects import EFFECT_FIELDS

    from hasel_wheel_bringup.demo import VARIANTS, metrics_table, plot, run_variants

    plant_cfg = dataclasses.replace(load_plant_config(args.plant), switching="tick")
    if args.hold_scale <= 0.0:
        print(f"error: --hold-scale {args.hold_scale}: expected a positive factor", file=sys.stderr)
        return 2
    if args.wheels < 1:
        print(f"error: --wheels {args.wheels}: expected at least 1", file=sys.stderr)
        return 2
    if not 0.0 <= args.w0 <= 10.0:
        print(f"error: --w0 {args.w0}: expected a starting speed in [0, 10] rad/s",
              file=sys.stderr)
        return 2
    if args.same_wheel and args.wheels < 2:
        print(f"error: --same-wheel records several runs of one wheel: give --wheels 2 or "
              f"more (got --wheels {args.wheels})", file=sys.stderr)
        return 2
    controller_config().with_overrides(dict(args.set or []))     # refuse a bad --set early
    out = Path(args.out)
    bag_dir = _fresh_bag_dir(out)
    if bag_dir is None:
        return 2
    rec = Recorder(bag_dir, custom_data={"tool": "hasel_wheel demo", "git_revision": git_revision(),
                                         "seed": str(plant_cfg.seed),
                                         "plant.yaml": Path(args.plant).read_text(),
                                         "hold_scale": repr(args.hold_scale),
                                         "w0": repr(args.w0),
                                         "wheels": str(args.wheels),
                                         "same_wheel": str(args.same_wheel).lower(),
                                         "controller_overrides": repr(dict(args.set or []))})
    variants = VARIANTS if args.compare else VARIANTS[:1]
    t0 = time.perf_counter()
    try:
        results = run_variants(plant_cfg, args.hold_scale, variants, rec, args.wheels,
                               dict(args.set or []), args.same_wheel, args.w0, progress=True)
    finally:
        rec.close()
    wall = time.perf_counter() - t0
    print(metrics_table(results, [e for e in EFFECT_FIELDS if e in plant_cfg.effects.enabled]))
    pngs = plot(results, out)
    sim = results[0].log.t[-1] * len(results)
    print(f"Plots: {', '.join(str(p) for p in pngs)}")
    print(f"Bag: {bag_dir} ({rec.bag.metadata()['rosbag2_bagfile_information']['message_count']}"
          f" messages, first run). {sim:.0f} s simulated in {wall:.1f} s wall.")
    return 0


def cmd_table2(args: argparse.Namespace) -> int:
    """Run the open-loop demo, write the bag, print the table."""
    params = load_wheel_params(args.wheel_params)
    plant_cfg = load_plant_config(args.plant)
    trials = trials_from_mapping(load_yaml_file(args.trials).get("open_loop"),
                                 f"{args.trials}: open_loop")
    out = Path(args.out)
    bag_dir = _fresh_bag_dir(out)
    if bag_dir is None:
        return 2
    custom = {"tool": "hasel_wheel table2", "git_revision": git_revision(),
              "seed": str(plant_cfg.seed),
              "wheel_params.yaml": Path(args.wheel_params).read_text(),
              "plant.yaml": Path(args.plant).read_text(),
              "trials.yaml": Path(args.trials).read_text()}
    rec = Recorder(bag_dir, custom_data=custom)
    t0 = time.perf_counter()
    exact, tick = [], []
    try:
        for spec in progress_bar(trials, "table2", unit="trial", scale=False):
            exact.append(run_trial(spec, params, dataclasses.replace(plant_cfg, switching="exact"),
                                   rec, f"/exact/{spec.label}"))
            spec_t = dataclasses.replace(spec, rule="after_measured")
            tick.append(run_trial(spec_t, params, dataclasses.replace(plant_cfg, switching="tick"),
                                  rec, f"/tick/{spec.label}"))
    finally:
        rec.close()
    wall = time.perf_counter() - t0
    sim = sum(r.spec.duration for r in exact + tick)
    print(demo_table(exact, tick))
    print()
    first = trials[0]
    v_alt = open_loop_speed(params, plant_cfg.effects.extensions(), first.phi_a, first.duration,
                            first.phi_d, first.initial_speed, mode="tick", rule="after_active")
    t_brake = braking_fall_time(params)
    t_coast = braking_fall_time(params, brake=False)
    print(f"Priming: {first.priming} activations (the cross-check's set-up); the paper's trials used 6.")
    print("Ticks: switching on the first 300 Hz tick after the angle, next actuator counted from")
    print("the sector measured at switch-off (eq. (40)).  Counted from the actuator of interest")
    print(f"instead, phi_a = {math.degrees(first.phi_a):.0f} deg on ticks gives "
          f"{steady_speed(np.arange(1, v_alt.size + 1) * TICK, v_alt):.2f} rad/s (docs/benchmarks.md).")
    print(f"Braking 2.6 -> 2.0 rad/s (n_a = eta + 2, -22/-6 deg, brake_gain {params.brake_gain:g}): "
          f"{t_brake:.2f} s; friction alone {t_coast:.2f} s; paper Fig. 11(c) ~1.2 s.")
    print(f"Bag: {bag_dir} ({rec.bag.metadata()['rosbag2_bagfile_information']['message_count']}"
          f" messages). {sim:.0f} s simulated in {wall:.1f} s wall.")
    return 0


def cmd_link_run(args: argparse.Namespace) -> int:
    """Run the host stack over a real pty against the virtual Teensy (no ROS), record a bag."""
    import tempfile

    from hasel_wheel_driver.link import DriverCore, LinkConfig
    from hasel_wheel_common import protocol as P
    from hasel_wheel_sim.device_process import DeviceProcess
    from hasel_wheel_sim.pty_device import LinkFaults

    from hasel_wheel_bringup.sequencer import Sequencer

    out = Path(args.out)
    bag_dir = _fresh_bag_dir(out)
    if bag_dir is None:
        return 2
    link = Path(tempfile.mkdtemp(prefix="hasel-link-")) / "usb-Teensyduino_HASEL_wheel-if00"
    plant_cfg = dataclasses.replace(load_plant_config(args.plant), switching="tick")
    dev = DeviceProcess(link, plant_cfg, load_wheel_params(args.wheel_params), w0=args.initial_speed,
                        time_scale=args.time_scale, faults=LinkFaults(corrupt=args.corrupt, seed=1),
                        core_build=_core_build(args.device_core))
    rec = Recorder(bag_dir, custom_data={"tool": "hasel_wheel link-run", "git_revision": git_revision(),
                                         "plant.yaml": Path(args.plant).read_text()})
    seq = Sequencer(math.radians(args.phi_a_deg), math.radians(args.phi_d_deg))
    core = None

    def on_sample(s):
        rec.telemetry("/wheel0", s)
        cmd = seq.step(s)
        if cmd is not None and core.send_command(cmd) is None:
            rec.command("/wheel0", cmd, s.t)

    cfg = P.Config(watchdog_ms=int(min(1000, 100 * max(1.0, args.time_scale))))
    # bound before it starts: its reader thread may hand over the first sample at once, and
    # on_sample needs ``core`` to send the sequencer's first command
    # (test_demo.py::test_link_run_drives_the_wheel_over_a_pty_and_records)
    core = DriverCore(LinkConfig(str(link), enable_hv_on_connect=True, device_config=cfg),
                      on_sample=on_sample,
                      on_event=lambda e: print(f"  link: {e}", file=sys.stderr))
    core.start()
    try:
        t_end = time.monotonic() + args.seconds / args.time_scale
        while time.monotonic() < t_end:
            time.sleep(0.05)
    finally:
        acked = core.shutdown()
        rep = dev.stop()
        rec.close()
    d = core.decoder.stats
    print(f"link-run: {args.seconds:.0f} s simulated over a pty at x{args.time_scale:g}; "
          f"final speed {rep.speed:.2f} rad/s")
    print(f"  frames decoded {d.frames}, CRC errors {d.crc_errors}, framing errors "
          f"{d.framing_errors + d.oversize + d.length_errors}, sequence gaps {d.sequence_gaps}")
    print(f"  commands sent {core.stats.commands_sent}, device rejects {core.stats.rejects}, "
          f"watchdog trips {core.stats.watchdog_trips}, stale-link events "
          f"{core.stats.stale_events}, shutdown HV off {'confirmed' if acked else 'NOT confirmed'}")
    lt = core.last_telemetry
    if lt is not None:
        print(f"  last sample: HV {lt.hv_monitor:.0f} V, q {lt.q}, eta {lt.eta_unwrapped}, "
              f"latched command {lt.last_command_seq}, faults {lt.fault_flags}; "
              f"sequencer sent {seq.seq}")
    if rep.faults_seen:
        print(f"  device board errors (each reset the device, HV off): {rep.faults_seen[:3]}")
    print(f"  bag: {bag_dir}")
    return 0


def _core_build(core: str) -> Path | None:
    """The host build of the C++ firmware core for ``--device-core cpp`` (None: Python)."""
    if core == "python":
        return None
    from hasel_wheel_sim.device_cpp import default_build
    return default_build()


def cmd_virtual_teensy(args: argparse.Namespace) -> int:
    """Serve the virtual Teensy on a pty at ``args.link`` until SIGINT or SIGTERM."""
    import signal

    from hasel_wheel_sim.device_process import DeviceProcess

    plant_cfg = load_plant_config(args.plant)
    stop: list[int] = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda n, _f: stop.append(n))
    dev = DeviceProcess(args.link, plant_cfg, load_wheel_params(args.wheel_params),
                        w0=args.initial_speed, time_scale=args.time_scale,
                        core_build=_core_build(args.device_core))
    print(f"virtual Teensy ({args.device_core} device core) on {args.link}; Ctrl-C stops it",
          flush=True)
    while not stop:
        time.sleep(0.1)
    rep = dev.stop()
    print(f"virtual Teensy stopped after {rep.t:.1f} s of device time: HV "
          f"{'on' if rep.hv_enabled else 'off'}, frames sent {len(rep.sent)}, received "
          f"{len(rep.received)}, watchdog trips {rep.watchdog_trips}", flush=True)
    return 0


def _add_virtual_teensy(p: argparse.ArgumentParser, plant: str) -> None:
    """The virtual Teensy's options: its wheel, plant (default ``plant``), clock and core."""
    p.add_argument("--initial-speed", type=float, default=2.0, help="[rad/s]")
    p.add_argument("--time-scale", type=float, default=1.0, help="simulated seconds per wall second")
    p.add_argument("--wheel-params", default=str(packaged("hasel_wheel_sim", "wheel_params.yaml")))
    p.add_argument("--plant", default=str(packaged("hasel_wheel_sim", plant)))
    p.add_argument("--device-core", choices=("python", "cpp"), default="python",
                   help="the virtual Teensy's device logic: the Python reference or the C++ "
                        "firmware core built for this machine (needs cmake and g++)")


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="hasel_wheel", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="command")
    c = sub.add_parser("demo", help="closed speed loop vs. paper Fig. 11, recorded to a bag")
    c.add_argument("--out", default="out/demo", help="output directory (default: out/demo)")
    c.add_argument("--plant", default=str(packaged("hasel_wheel_sim", "plant_realistic.yaml")))
    c.add_argument("--hold-scale", type=float, default=1.0,
                   help="stretch every hold of the profile by this factor (default 1: 40 s holds)")
    c.add_argument("--wheels", type=int, default=1,
                   help="wheels run in lockstep, wheel i on the plant seed + i, each recorded "
                        "under /wheel<i> (default 1)")
    c.add_argument("--same-wheel", action="store_true",
                   help="with --wheels N: N runs of one wheel (its actuator gains drawn once, "
                        "from the plant seed, as `trials` records one wheel); each run still "
                        "draws its noise from seed + i")
    c.add_argument("--w0", type=float, default=0.0,
                   help="the wheel's speed at the start [rad/s] (default 0: from rest, started "
                        "by the start policy)")
    c.add_argument("--no-compare", dest="compare", action="store_false",
                   help="skip the comparison runs (no estimator, paper estimator, finite difference)")
    c.add_argument("--set", action="append", type=bag_cli.override_arg,
                   metavar="SECTION.FIELD=VALUE", help="change the controller of every run (repeatable), e.g. "
                        "mpc.brake_phi_a=-0.384 (rad) or mpc.brake_threshold=0.3 (rad/s)")
    c.set_defaults(func=cmd_demo)
    d = sub.add_parser("table2", help="open-loop trials vs. paper Table II, recorded to a bag")
    d.add_argument("--out", default="out/table2", help="output directory (default: out/table2)")
    d.add_argument("--wheel-params", default=str(packaged("hasel_wheel_sim", "wheel_params.yaml")))
    d.add_argument("--plant", default=str(packaged("hasel_wheel_sim", "plant.yaml")))
    d.add_argument("--trials", default=str(packaged("hasel_wheel_bringup", "demo_open_loop.yaml")))
    d.set_defaults(func=cmd_table2)
    r = sub.add_parser("link-run", help="host stack over a real pty against the virtual Teensy")
    r.add_argument("--out", default="out/link_run")
    r.add_argument("--seconds", type=float, default=60.0, help="simulated seconds")
    r.add_argument("--phi-a-deg", type=float, default=3.0)
    r.add_argument("--phi-d-deg", type=float, default=22.0)
    r.add_argument("--corrupt", type=float, default=0.0, help="byte corruption probability")
    _add_virtual_teensy(r, "plant.yaml")
    r.set_defaults(func=cmd_link_run)
    v = sub.add_parser("virtual-teensy", help="serve the virtual Teensy on a pty until Ctrl-C "
                                              "(point driver_node's port at LINK)")
    v.add_argument("link", type=Path, help="path of the symlink to create, e.g. "
                                           "/tmp/usb-Teensyduino_HASEL_wheel-if00")
    _add_virtual_teensy(v, "plant_realistic.yaml")
    v.set_defaults(func=cmd_virtual_teensy)
    ident_cli.add_parsers(sub)
    bag_cli.add_parsers(sub)
    return ap


def main(argv: Sequence[str] | None = None) -> int:
    ap = build_parser()
    args = ap.parse_args(argv)
    if args.command is None:
        args = ap.parse_args(["demo", *(argv or [])])
    try:
        return args.func(args)
    except ParameterError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
