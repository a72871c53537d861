"""A sweep of the identification over effects, sizes and plant seeds drawn at random: how it
does on data it was never tuned on, the way the issue's acceptance will test it.

Each run draws one of the plant's dynamic effects (or none), a size from a band where the
effect should be visible (log-uniform; phases uniform), and a plant seed from 100-9999, none
of which the tests or the other benchmarks use.  The trials are the paper's protocol (5 x 60 s,
``--short``: 3 x 34 s) through the 10-bit encoder with 1 mrad noise (``--defects``: plus 0.2 %
encoder glitches and 0.2 % lost samples).  The tool gets the whole library and is told
nothing.  Each run prints what was chosen against the truth:

* ``right``: exactly the effect switched on (nothing on data with none);
* ``missed``: nothing named where an effect was on.  The true model's simulation error
  (the plant's own parameters, nothing fitted but each trial's start:
  ``metrics.model_error``) is printed beside it: where it does not cut the nominal fit's
  held-out error by the tool's 10 % either, the data cannot show the effect (``below the
  floor``; an approximation of the tool's own gate, which compares held-out errors);
* ``wrong``: any other name.  This must never happen.

The estimate is printed against the truth (for the gain spread: the std of the fitted gains
against the std of the gains the plant drew).  The sweep is deterministic: the same
``--seed`` draws the same runs.

Run: ``.venv/bin/python benchmarks/sweep_ident.py [--runs 16] [--seed 0] [--short] [--defects]``
(about a minute per run on 5 x 60 s, half that on 3 x 34 s).
"""
from __future__ import annotations

import argparse
import math
import time
from dataclasses import dataclass

from hasel_wheel_ident.numerics import pin_blas_kernels

pin_blas_kernels()  # before numpy loads: the kernels the printed figures come from (.numerics)
import numpy as np  # noqa: E402  (this and the imports below: after the pin)

from hasel_wheel_ident import candidates as C  # noqa: E402
from hasel_wheel_ident import fit as F  # noqa: E402
from hasel_wheel_ident import metrics as M  # noqa: E402
from hasel_wheel_ident import select as SEL  # noqa: E402
from hasel_wheel_ident import synthetic as S  # noqa: E402
from hasel_wheel_ident import verdict as V  # noqa: E402
from hasel_wheel_sim.effects import effects_from_mapping  # noqa: E402
from hasel_wheel_sim.params import WheelParams  # noqa: E402
from hasel_wheel_sim.plant import PlantConfig  # noqa: E402

#: plant effect -> (candidate id, {plant parameter: (unit, low, high)}) with sizes drawn
#: log-uniform in [low, high]; "phase" is drawn uniform in [-pi, pi)
BANDS: dict[str, tuple[str, dict[str, tuple[str, float, float]]]] = {
    "viscous_drag": ("viscous_drag", {"coefficient": ("N*m*s/rad", 4e-4, 2e-3)}),
    "rise_lag": ("rise_lag", {"time_constant": ("s", 0.03, 0.1)}),
    "charge_retention": ("charge_retention", {"rate": ("1/s", 0.05, 0.3),
                                              "recovery": ("s", 100.0, 600.0)}),
    "gain_spread": ("gain_spread", {"std": ("1", 0.06, 0.12)}),
    "com_offset": ("com_offset", {"torque": ("N*m", 0.0015, 0.005), "phase": ("rad", 0, 0)}),
    "platform_disturbance": ("platform_periodic", {"torque": ("N*m", 0.0015, 0.005),
                                                   "phase": ("rad", 0, 0)}),
    "angle_eccentricity": ("angle_eccentricity", {"amplitude": ("rad", 0.005, 0.03),
                                                  "phase": ("rad", 0, 0)}),
}
#: the order the runs cycle through (each effect once per cycle, then again with new draws)
ORDER = ("none",) + tuple(BANDS)
DEFECTS = {"encoder_glitches": {"enabled": True, "probability": {"value": 0.002, "unit": "1"}},
           "dropouts": {"enabled": True, "probability": {"value": 0.002, "unit": "1"}}}


@dataclass(frozen=True)
class Draw:
    """One run: the plant effect (or "none"), its parameters (SI) and the plant seed."""

    effect: str
    values: dict[str, float]
    seed: int

    def mapping(self) -> dict:
        """The plant's ``effects`` entry for this draw (empty for "none")."""
        if self.effect == "none":
            return {}
        units = BANDS[self.effect][1]
        return {self.effect: {"enabled": True, **{k: {"value": v, "unit": units[k][0]}
                                                  for k, v in self.values.items()}}}

    def label(self) -> str:
        return self.effect + "".join(f" {k} {v:.4g}" for k, v in self.values.items())


def draws(n: int, seed: int) -> list[Draw]:
    """``n`` runs cycling through :data:`ORDER`, sizes and seeds from ``seed``."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        effect = ORDER[i % len(ORDER)]
        values = {}
        if effect != "none":
            for name, (_, lo, hi) in BANDS[effect][1].items():
                values[name] = (float(rng.uniform(-math.pi, math.pi)) if name == "phase" else
                                float(math.exp(rng.uniform(math.log(lo), math.log(hi)))))
        out.append(Draw(effect, values, int(rng.integers(100, 10000))))
    return out


def candidate_truth(draw: Draw, gains: tuple[float, ...], base: WheelParams) -> dict[str, float]:
    """The plant's values in the candidate's parameters (for the true model's error), with
    the force law's coordinates of ``base`` (the gain spread's geometric mean scales its
    peak: the candidate's gains have a geometric mean of 1)."""
    v = draw.values
    coords = dict(F.force_coordinates(base), tau_f=base.tau_f)
    if draw.effect == "viscous_drag":
        return {**coords, "c": v["coefficient"]}
    if draw.effect == "rise_lag":
        return {**coords, "tau": v["time_constant"]}
    if draw.effect == "charge_retention":
        return {**coords, "rate": v["rate"], "recovery": v["recovery"]}
    if draw.effect == "com_offset":       # -T sin(xi1 + phase) = A cos xi1 + B sin xi1
        return {**coords, "A": -v["torque"] * math.sin(v["phase"]),
                "B": -v["torque"] * math.cos(v["phase"])}
    if draw.effect == "platform_disturbance":
        return {**coords, "P": v["torque"] * math.cos(v["phase"]),
                "Q": v["torque"] * math.sin(v["phase"])}
    if draw.effect == "angle_eccentricity":
        return {**coords, "E": v["amplitude"] * math.sin(v["phase"]),
                "F": v["amplitude"] * math.cos(v["phase"])}
    if draw.effect == "gain_spread":
        mean, logs = C.spread_values(gains)
        return {**coords, "peak": coords["peak"] * mean, **logs}
    return coords


def estimate(cid: str, values: dict[str, float], draw: Draw, gains: tuple[float, ...]) -> str:
    """The fitted effect in the plant's terms, beside the truth."""
    cand = C.BY_ID[cid]
    got = cand.describe([values[p.name] for p in cand.params])
    if cid == "gain_spread":
        return f"gain std {got['std']:.3f} (drawn {np.std(np.array(gains) / np.exp(np.mean(np.log(gains)))):.3f})"
    if cid in ("com_offset", "platform_periodic"):
        return f"torque {got['torque_N_m']:.4g} N*m at {got['phase_rad']:.3f} rad"
    if cid == "angle_eccentricity":
        return f"{1e3 * got['amplitude_rad']:.2f} mrad at {got['phase_rad']:.3f} rad"
    return ", ".join(f"{p.name} {values[p.name]:.4g}" for p in cand.params)


def run(draw: Draw, specs, defects: bool) -> str:
    """Identify one draw; return its verdict ("right", "missed", "wrong") after printing it."""
    effects = effects_from_mapping({**S.ENCODER, **(DEFECTS if defects else {}), **draw.mapping()})
    cfg = PlantConfig(seed=draw.seed, switching="tick", effects=effects)
    trials = S.record_set(specs, config=cfg)
    gains = tuple(effects.extensions(np.random.default_rng(draw.seed)).gains)
    t0 = time.perf_counter()
    res = SEL.identify(trials, k_folds=min(5, len(trials)), analyse_residuals=False)
    dt = time.perf_counter() - t0
    before, after = res.nominal.sim_heldout_rmse, res.final.sim_heldout_rmse
    cid = BANDS[draw.effect][0] if draw.effect != "none" else None
    line = f"held-out simulation error {before:.4f} -> {after:.4f} rad/s (x{before / after:.2f})"
    for c in res.chosen:
        line += f"; {c}: {estimate(c, res.final.fit.values, draw, gains)}"
    true = None
    if cid is not None:
        base = WheelParams()
        true = M.model_error(trials, base, (C.BY_ID[cid],), candidate_truth(draw, gains, base))
        line += f"; true model {true:.4f} (x{before / true:.2f}"
        line += ", below the floor)" if V.below_floor(before, true) else ")"
    # one verdict, printed and counted (a miss below the floor says so in both)
    verdict = V.verdict(res.chosen, cid, before, true)
    print(f"{draw.label()}, plant seed {draw.seed}: chosen {', '.join(res.chosen) or 'none'} "
          f"-> {verdict}; {line}; {dt:.0f} s", flush=True)
    return verdict


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=16, help="number of runs (default 16)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the draws (default 0)")
    ap.add_argument("--short", action="store_true", help="3 x 34 s instead of 5 x 60 s")
    ap.add_argument("--defects", action="store_true",
                    help="add 0.2 %% encoder glitches and 0.2 %% lost samples")
    args = ap.parse_args()
    specs = S.SHORT_SET if args.short else S.PAPER_SET
    print(f"{args.runs} runs, draws seed {args.seed}, "
          f"{len(specs)} x {specs[0].drive + specs[0].coast:.0f} s"
          + (", with glitches and lost samples" if args.defects else ""), flush=True)
    t0 = time.perf_counter()
    tally: dict[str, int] = {}
    for draw in draws(args.runs, args.seed):
        v = run(draw, specs, args.defects)
        tally[v] = tally.get(v, 0) + 1
    print(f"summary: {', '.join(f'{k} {n}' for k, n in sorted(tally.items()))} of {args.runs} "
          f"({time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    main()
