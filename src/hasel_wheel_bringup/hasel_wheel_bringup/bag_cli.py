"""``hasel_wheel bag``: offline tools on recorded bags (no ROS needed).

    hasel_wheel bag info out/demo/demo_bag         # topics, counts, rates, gaps, configuration
    hasel_wheel bag info killed_run/ --json        # the same as JSON
    hasel_wheel bag metrics out/demo/bag           # per wheel and reference segment
    hasel_wheel bag observer out/demo/bag          # observer speed error vs the true speed
    hasel_wheel bag observer replay_bag --truth run_bag   # a replay's estimates vs the run's truth
    hasel_wheel bag export out/demo/bag --out csv/ --topics /wheel0/telemetry   # CSV per topic
    hasel_wheel bag export out/demo/bag --out pq/ --format parquet              # Parquet
    hasel_wheel bag plot out/demo/bag --out plots/ # speed, raster, force, observer (PNG)
    hasel_wheel bag replay out/demo/bag            # re-run observer + MPC, compare (exact)
    hasel_wheel bag replay out/demo/bag --set mpc.brake_threshold=0.3   # what would change

Under ROS 2 the same tools are ``ros2 run hasel_wheel_mpc hasel_wheel_bag <tool> ...``.

Bags are rosbag2 directories (``metadata.yaml`` + ``*.mcap``) or single ``.mcap`` files,
from the embedded runner or from ``ros2 bag record -s mcap``; a recording that was killed is
read up to its last finished chunk, and the tool says what was lost.
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import asdict

import yaml

from hasel_wheel_bag.layout import BagError
from hasel_wheel_bag.export import FORMATS, export
from hasel_wheel_bag.info import bag_info


def _json(obj):
    """``obj`` with non-finite floats as null (standard JSON has no NaN or Infinity)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _json(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_json(v) for v in obj]
    return obj


def cmd_info(args: argparse.Namespace) -> int:
    """Print what a bag holds."""
    try:
        info = bag_info(args.bag, progress=True)
    except BagError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(_json(asdict(info)), indent=1, allow_nan=False))
    else:
        print(info.text())
    return 0


def cmd_metrics(args: argparse.Namespace) -> int:
    """Print the closed-loop metrics of every wheel in a bag."""
    from hasel_wheel_bringup.bag_metrics import bag_metrics
    try:
        wheels = bag_metrics(args.bag, window=args.window,
                             warn=lambda text: print(f"warning: {text}", file=sys.stderr),
                             progress=True)
    except BagError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(_json([asdict(w) for w in wheels]), indent=1, allow_nan=False))
    else:
        for w in wheels:
            print(w.text())
    if not wheels:
        print(f"error: {args.bag}: no wheel with a reference_speed topic and a speed "
              f"(sim/true_state or state_estimate)", file=sys.stderr)
        return 1
    return 0


def cmd_completeness(args: argparse.Namespace) -> int:
    """Print, per wheel, whether the bag holds every telemetry sample its device published;
    exit 1 when samples are missing or no wheel could be checked."""
    from hasel_wheel_bringup.bag_completeness import bag_completeness
    try:
        wheels = bag_completeness(args.bag)
    except BagError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(_json([asdict(w) | {"missing": w.missing} for w in wheels]), indent=1))
    else:
        for w in wheels:
            print(w.text())
    return 0 if wheels and all(w.missing == 0 for w in wheels) else 1


def cmd_observer(args: argparse.Namespace) -> int:
    """Print the observer's speed error against the simulator's true speed."""
    from hasel_wheel_bringup.observer_error import observer_error
    try:
        wheels = observer_error(args.bag, args.truth, args.skip)
    except BagError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for w in wheels:
        print(w.text())
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    """Write chosen topics as CSV or Parquet files, one per topic."""
    topics = [t.strip() for t in args.topics.split(",") if t.strip()] if args.topics else None
    try:
        report = export(args.bag, args.out, topics, args.format,
                        warn=lambda text: print(f"warning: {text}", file=sys.stderr),
                        progress=True)
    except BagError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for topic, r in report.items():
        extra = f" ({r['misfits']} rows with other array lengths)" if r["misfits"] else ""
        print(f"{topic}: {r['rows']} rows -> {r['file']}{extra}")
    return 0 if report else 1


def override_arg(text: str) -> tuple[str, object]:
    """argparse type of ``--set SECTION.FIELD=VALUE``: (key, YAML-parsed value)."""
    key, sep, value = text.partition("=")
    if not sep or not key.strip():
        raise argparse.ArgumentTypeError(f"{text!r}: expected SECTION.FIELD=VALUE, e.g. "
                                         f"mpc.brake_threshold=0.3 or estimator.gain=null")
    return key.strip(), yaml.safe_load(value)


def cmd_plot(args: argparse.Namespace) -> int:
    """Write the PNG figures of every wheel in a bag."""
    from hasel_wheel_bringup.bag_plot import plot_bag
    try:
        files = plot_bag(args.bag, args.out, args.namespace, progress=True)
    except BagError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for f in files:
        print(f)
    return 0


def cmd_replay(args: argparse.Namespace) -> int:
    """Replay a bag's telemetry through the controller; print what differs."""
    from hasel_wheel_sim.params import ParameterError

    from hasel_wheel_bringup.replay import replay_bag
    try:
        reports = replay_bag(args.bag, dict(args.set or []), args.namespace,
                             warn=lambda text: print(f"warning: {text}", file=sys.stderr),
                             progress=True)
    except (BagError, ParameterError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for r in reports:
        print(r.text())
    return 1 if args.check and not all(r.identical for r in reports) else 0


def add_parsers(sub) -> None:
    """Add ``bag`` (``info``, ``metrics``, ``completeness``, ``observer``, ``plot``, ``export``,
    ``replay``) to the ``hasel_wheel`` sub-command parser."""
    b = sub.add_parser("bag", help="offline tools on recorded bags (info, metrics, completeness, "
                                    "observer, plot, export, replay)")
    add_tools(b.add_subparsers(dest="bag_command", required=True))


def add_tools(tools) -> None:
    """Add the tools (``info``, ``metrics``, ``completeness``, ``observer``, ``plot``, ``export``,
    ``replay``) to a sub-command parser."""
    i = tools.add_parser("info", help="topics, counts, rates, gaps, duration, configuration")
    i.add_argument("bag", help="bag directory or .mcap file")
    i.add_argument("--json", action="store_true", help="print JSON instead of text")
    i.set_defaults(func=cmd_info)
    m = tools.add_parser("metrics", help="per wheel and reference segment: steady error, NRMSE, "
                                         "rise/fall and settling times, deadline misses")
    m.add_argument("bag", help="bag directory or .mcap file")
    m.add_argument("--window", type=float, default=10.0,
                   help="[s] steady window at the end of each segment (default 10)")
    m.add_argument("--json", action="store_true", help="print JSON instead of text")
    m.set_defaults(func=cmd_metrics)
    c = tools.add_parser("completeness", help="per wheel: the telemetry recorded against the "
                                              "count the device node reported publishing")
    c.add_argument("bag", help="bag directory or .mcap file")
    c.add_argument("--json", action="store_true", help="print JSON instead of text")
    c.set_defaults(func=cmd_completeness)
    o = tools.add_parser("observer", help="the observer's speed error against the simulator's "
                                          "true speed, estimates paired by stamp")
    o.add_argument("bag", help="bag with state_estimate (directory or .mcap file)")
    o.add_argument("--truth", default=None,
                   help="bag with sim/true_state (default: the same bag; e.g. the original run "
                        "of a replay)")
    o.add_argument("--skip", type=float, default=2.0,
                   help="[s] left out after the first paired estimate (acquisition; default 2)")
    o.set_defaults(func=cmd_observer)
    e = tools.add_parser("export", help="chosen topics as CSV or Parquet, one file per topic")
    e.add_argument("bag", help="bag directory or .mcap file")
    e.add_argument("--out", required=True, help="directory for the files")
    e.add_argument("--format", choices=sorted(FORMATS), default="csv",
                   help="csv (default) or parquet (needs pyarrow)")
    e.add_argument("--topics", default=None, help="comma-separated topics (default: all)")
    e.set_defaults(func=cmd_export)
    p = tools.add_parser("plot", help="PNG figures per wheel: speed vs reference (Fig. 11), "
                                      "actuator raster, force vs contact angle, observer vs "
                                      "raw encoder")
    p.add_argument("bag", help="bag directory or .mcap file")
    p.add_argument("--out", required=True, help="directory for the PNG files")
    p.add_argument("--namespace", action="append", default=None,
                   help="wheel namespace, e.g. /wheel0 (repeatable; default: all)")
    p.set_defaults(func=cmd_plot)
    r = tools.add_parser("replay", help="feed the telemetry through observer, estimator and MPC "
                                        "again; compare with the recorded estimates and decisions")
    r.add_argument("bag", help="bag directory or .mcap file")
    r.add_argument("--namespace", action="append", default=None,
                   help="wheel namespace to replay, e.g. /wheel0 (repeatable; default: all)")
    r.add_argument("--set", action="append", type=override_arg, metavar="SECTION.FIELD=VALUE",
                   help="change the recorded controller configuration (repeatable), e.g. "
                        "mpc.brake_threshold=0.3, observer.accel_noise=0.1, estimator.gain=null, "
                        "model.wheel.tau_f=1.2")
    r.add_argument("--check", action="store_true",
                   help="exit 1 when anything differs from the recording")
    r.set_defaults(func=cmd_replay)


def main(argv=None) -> int:
    """``hasel_wheel_bag <tool> ...`` (the ``ros2 run hasel_wheel_mpc hasel_wheel_bag`` entry)."""
    ap = argparse.ArgumentParser(prog="hasel_wheel_bag", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    add_tools(ap.add_subparsers(dest="bag_command", required=True))
    args = ap.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
