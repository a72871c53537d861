"""Benchmark of the identification (issue 5): the figures the README quotes.

* nominal plant, 5 trials x (50 s driven + 10 s coast) through the 10-bit encoder with 1 mrad
  noise: tau_f from the coast-downs and the force law's coordinates against the true values,
  and the wall time of the nominal fit;
* the same trials with an undeclared COM offset (0.004 N*m at 0.5 rad): the effect search
  over three candidates (viscous_drag, com_offset, rise_lag), k-fold by trial: what it chose,
  the estimate, the held-out error before and after, and the wall time.
  (The issue's target is the full library in <= 120 s; the full search is not yet that fast.)

Run: ``./dev bench`` or ``.venv/bin/python benchmarks/bench_ident.py``.
"""
from __future__ import annotations

import time

from hasel_wheel_mpc.ident import candidates as C
from hasel_wheel_mpc.ident import fit as F
from hasel_wheel_mpc.ident import select as SEL
from hasel_wheel_mpc.ident import synthetic as S
from hasel_wheel_sim.effects import effects_from_mapping
from hasel_wheel_sim.params import WheelParams
from hasel_wheel_sim.plant import PlantConfig

ENCODER = {"encoder": {"enabled": True, "noise_std": {"value": 0.001, "unit": "rad"}}}
COM = {"com_offset": {"enabled": True, "torque": {"value": 0.004, "unit": "N*m"},
                      "phase": {"value": 0.5, "unit": "rad"}}}


def main() -> None:
    true = WheelParams()
    trials = S.record_set(config=PlantConfig(seed=3, switching="tick",
                                             effects=effects_from_mapping(ENCODER)))
    fr = F.coastdown_friction(trials, true)
    print(f"tau_f from {fr.segments} coast-downs: {fr.tau_f:.6f} N*m (true {true.tau_f}), "
          f"error {100 * (fr.tau_f / true.tau_f - 1):+.2f} %, 95 % CI {fr.ci95[0]:.6f}..{fr.ci95[1]:.6f}")
    start = true.with_values(sigma6=true.sigma6 * 0.85, sigma2=true.sigma2 * 1.15,
                             sigma4=true.sigma4 * 0.97)
    t0 = time.perf_counter()
    res = F.Problem(trials, start).fit(start={"tau_f": fr.tau_f})
    dt = time.perf_counter() - t0
    ref = F.force_coordinates(true)
    errs = ", ".join(f"{k} {100 * (res.values[k] / ref[k] - 1):+.2f} %" for k in ref)
    print(f"nominal fit (5 x 60 s): {dt:.1f} s, {res.nfev} evaluations, RMSE "
          f"{1e3 * res.rmse:.3f} mrad; errors: {errs}")

    trials = S.record_set(config=PlantConfig(seed=3, switching="tick",
                                             effects=effects_from_mapping({**ENCODER, **COM})))
    lib = C.library(["viscous_drag", "com_offset", "rise_lag"])
    t0 = time.perf_counter()
    ident = SEL.identify(trials, library=lib, max_effects=1, analyse_residuals=False)
    dt = time.perf_counter() - t0
    print(f"effect search, undeclared COM offset (5 x 60 s, 3 candidates, 5 folds): {dt:.1f} s")
    print(f"  chosen: {ident.chosen}; held-out RMSE {1e3 * ident.nominal.heldout_rmse:.2f} -> "
          f"{1e3 * ident.final.heldout_rmse:.2f} mrad "
          f"(x{ident.nominal.heldout_rmse / ident.final.heldout_rmse:.1f} smaller)")
    if "com_offset" in ident.chosen:
        v = ident.final.fit.values
        d = C.BY_ID["com_offset"].describe([v["A"], v["B"]])
        print(f"  COM torque {d['torque_N_m']:.5f} N*m (true 0.004), phase {d['phase_rad']:.3f} rad "
              f"(true 0.5)")
    for ev in ident.rounds[0]:
        print(f"  {ev.effects[0]:>14}: {'accepted' if ev.accepted else 'refused '} {ev.reason}")


if __name__ == "__main__":
    main()
