"""Benchmark of the identification on closed-loop recordings: the data a researcher running
our MPC records, rather than the paper's open-loop trials.

For each case, three runs of one wheel (``hasel_wheel demo --wheels 3 --same-wheel
--hold-scale 0.5``: the demo's reference profile at half length, 115 s each, the speed loop
closed by the observer, estimator and MPC) on a plant with one effect switched on, never
declared to the tool, through the 10-bit encoder with 1 mrad noise, switching on the
firmware's ticks, plant seed 3.  The runs are recorded to an MCAP bag and identified from
it, as ``hasel_wheel identify <bag>`` does but without the residual analysis (which runs
after the choice and does not change it).  Each line prints what was chosen against the
truth, the estimate, the held-out simulation error before and after, the error of the true
model (the plant's own parameters: where it is not 10 % below the nominal fit's held-out
error, the tool's bar, no fit could pass it either: "below the floor") and the wall time.

A closed loop answers a disturbance with its pushes: the recorded commands differ from
those an open-loop trial would hold, and the nominal force law can bend to take an effect up.
These recordings have no coast-down either (the wheel is driven to the end), so friction is
fitted with the force law.

Run: ``.venv/bin/python benchmarks/bench_ident_closed_loop.py [--only SUBSTRING]`` (minutes;
each line prints its own recording and identification times).
"""
from __future__ import annotations

import argparse
import math
import tempfile
import time
from pathlib import Path

from hasel_wheel_ident.numerics import pin_blas_kernels

pin_blas_kernels()  # before numpy loads: the kernels the printed figures come from (.numerics)
import numpy as np  # noqa: E402  (this and the imports below: after the pin)

from hasel_wheel_mpc.closed_loop import FIG11_DURATION  # noqa: E402
from hasel_wheel_bringup.demo import VARIANTS, run_variants  # noqa: E402
from hasel_wheel_ident import candidates as C  # noqa: E402
from hasel_wheel_ident import fit as F  # noqa: E402
from hasel_wheel_ident import metrics as M  # noqa: E402
from hasel_wheel_ident import report as R  # noqa: E402
from hasel_wheel_ident import select as SEL  # noqa: E402
from hasel_wheel_ident import verdict as V  # noqa: E402
from hasel_wheel_ident.data import read_bag  # noqa: E402
from hasel_wheel_mpc.recorder import Recorder  # noqa: E402
from hasel_wheel_sim.effects import effects_from_mapping  # noqa: E402
from hasel_wheel_sim.params import WheelParams  # noqa: E402
from hasel_wheel_sim.plant import PlantConfig  # noqa: E402

ENCODER = {"encoder": {"enabled": True, "noise_std": {"value": 0.001, "unit": "rad"}}}
SEED = 3
RUNS = 3
HOLD_SCALE = 0.5


def _on(effect: str, **values: tuple[float, str]) -> dict:
    return {effect: {"enabled": True, **{k: {"value": v, "unit": u} for k, (v, u) in values.items()}}}


#: label -> (plant effects, candidate id or None, the candidate's parameters at the plant's
#: values; the gain spread's come from the gains the plant drew)
CASES = {
    "nothing": ({}, None, {}),
    "off-centre mass 0.004 N*m at 1 rad": (
        _on("com_offset", torque=(0.004, "N*m"), phase=(1.0, "rad")), "com_offset",
        # -T sin(xi1 + phase) = A cos xi1 + B sin xi1
        {"A": -0.004 * math.sin(1.0), "B": -0.004 * math.cos(1.0)}),
    "platform torque 0.004 N*m at 0.5 rad": (
        _on("platform_disturbance", torque=(0.004, "N*m"), phase=(0.5, "rad")),
        "platform_periodic", {"P": 0.004 * math.cos(0.5), "Q": 0.004 * math.sin(0.5)}),
    "charge retention 0.2/s, recovery 300 s": (
        _on("charge_retention", rate=(0.2, "1/s"), recovery=(300.0, "s")), "charge_retention",
        {"rate": 0.2, "recovery": 300.0}),
    "angle sensor 20 mrad off at 0.3 rad": (
        _on("angle_eccentricity", amplitude=(0.02, "rad"), phase=(0.3, "rad")),
        "angle_eccentricity", {"E": 0.02 * math.sin(0.3), "F": 0.02 * math.cos(0.3)}),
    "gain spread std 0.1": (_on("gain_spread", std=(0.1, "1")), "gain_spread", {}),
    "viscous drag 1e-3 N*m*s/rad": (
        _on("viscous_drag", coefficient=(1e-3, "N*m*s/rad")), "viscous_drag", {"c": 1e-3}),
    "rise lag 40 ms": (_on("rise_lag", time_constant=(0.04, "s")), "rise_lag", {"tau": 0.04}),
}


def record(effects: dict, bag: Path) -> PlantConfig:
    """Record the three runs of one wheel to ``bag``; returns the plant's configuration."""
    cfg = PlantConfig(seed=SEED, switching="tick", effects=effects_from_mapping({**ENCODER,
                                                                                 **effects}))
    rec = Recorder(bag, custom_data={"tool": "bench_ident_closed_loop"})
    try:
        run_variants(cfg, HOLD_SCALE, VARIANTS[:1], rec, RUNS, same_wheel=True)
    finally:
        rec.close()
    return cfg


def true_values(cid: str, values: dict[str, float], cfg: PlantConfig) -> dict[str, float]:
    """Every parameter of the nominal model plus ``cid`` at the plant's values."""
    base = WheelParams()
    out = dict(F.force_coordinates(base), tau_f=base.tau_f, brake_gain=base.brake_gain,
               **values)
    if cid == "gain_spread":
        mean, logs = C.spread_values(cfg.effects.extensions(np.random.default_rng(cfg.seed)).gains)
        out["peak"] *= mean
        out.update(logs)
    return out


def estimate(cid: str, fit_values: dict[str, float], truth: dict[str, float]) -> str:
    """The fitted effect in words, beside the truth."""
    cand = C.BY_ID[cid]
    x = [fit_values[p.name] for p in cand.params]
    got = cand.describe(x)
    want = cand.describe([truth[p.name] for p in cand.params])
    return ", ".join(f"{k} {v:.4g} (true {want[k]:.4g})" for k, v in got.items()
                     if isinstance(v, float))


def run(label: str, effects: dict, cid: str | None, values: dict[str, float]) -> str:
    """Record and identify one case (``effects`` on the plant; ``cid`` the candidate that
    should be named, ``values`` its parameters at the plant's); print its line, return the
    verdict (:func:`~hasel_wheel_ident.verdict.verdict`)."""
    with tempfile.TemporaryDirectory() as tmp:
        bag = Path(tmp) / "bag"
        t0 = time.perf_counter()
        cfg = record(effects, bag)
        t_rec = time.perf_counter() - t0
        trials = read_bag(bag)
        t0 = time.perf_counter()
        res = SEL.identify(trials, k_folds=5, analyse_residuals=False)
        dt = time.perf_counter() - t0
    before, after = res.nominal.sim_heldout_rmse, res.final.sim_heldout_rmse
    line = (f"{label}: chosen {', '.join(res.chosen) or 'none'}; held-out simulation error "
            f"{before:.4f} -> {after:.4f} rad/s")
    if cid in res.chosen:
        line += f"; {estimate(cid, res.final.fit.values, true_values(cid, values, cfg))}"
    true = None
    if cid is not None:
        true = M.model_error(trials, WheelParams(), (C.BY_ID[cid],), true_values(cid, values, cfg))
        line += f"; true model {true:.4f} (x{before / true:.2f})"
    verdict = V.verdict(res.chosen, cid, before, true)
    if cid == "gain_spread":
        gains = cfg.effects.extensions(np.random.default_rng(cfg.seed)).gains
        line += f" (the gains drawn: std {np.std(gains):.4f} as drawn)"
    refits = "; ".join(f"{'+'.join(e.effects)} {'accepted' if e.accepted else 'refused'}"
                       for r in res.rounds for e in r)
    refits += "".join(f"; near miss {m}" for m in R.near_miss_texts(res))
    print(f"{line}; refits: {refits or 'none'}; {verdict.upper()}; recorded in {t_rec:.0f} s, "
          f"identified in {dt:.0f} s", flush=True)
    return verdict


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--only", default="", help="run only the cases whose label holds this")
    args = ap.parse_args()
    print(f"{RUNS} closed-loop runs of one wheel, {FIG11_DURATION * HOLD_SCALE:.0f} s each (the demo's "
          f"profile), plant seed {SEED}, 10-bit encoder with 1 mrad noise, tick switching",
          flush=True)
    t0 = time.perf_counter()
    tally: dict[str, int] = {}
    cases = [(k, v) for k, v in CASES.items() if args.only in k]
    for label, (effects, cid, values) in cases:
        v = run(label, effects, cid, values)
        tally[v] = tally.get(v, 0) + 1
    print(f"summary: {', '.join(f'{k} {n}' for k, n in sorted(tally.items()))} of {len(cases)} "
          f"({time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
