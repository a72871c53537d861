"""Benchmark of the start, stall and pad policies (embedded runner, realistic plant).

Prints:
* the Fig. 5 experiment (pad 3 in contact at 11.25 deg, 3 s on, from rest) with the
  realistic wheel's start push, next to the push's own closed form;
* from rest on plant seeds 0-15: the time until the wheel first reaches 1.0 rad/s, then the
  steady error and NRMSE of a 40 s hold at 1.0 rad/s (steady window: its last 10 s);
* an obstacle (0.2 N*m for 0.5 s at 20 s, seeds 0-3): restarts and the time from its end
  until the speed is back within 2 % of 1.0 rad/s; one that holds for good: the time until
  HV goes off, and the status;
* a pad that dies at 20 s at 1.5 rad/s (seeds 0-3): when it is named (s and turns after its
  death) and the steady error of the hold;
* the finite-difference loop from rest: decisions and the share of each 10 s it moves.

The figures, each beside its command, are in ``docs/benchmarks.md``.

Run: ``./dev bench`` or ``.venv/bin/python benchmarks/bench_start.py``.
"""
from __future__ import annotations

import dataclasses
import math

from hasel_wheel_ident.numerics import pin_blas_kernels

pin_blas_kernels()  # before numpy loads: the kernels the printed figures come from (.numerics)
import numpy as np  # noqa: E402  (this and the imports below: after the pin)

from hasel_wheel_mpc.closed_loop import (WheelLoop, controller_config, run_wheels,  # noqa: E402
                                         segment_metrics, start_time)
from hasel_wheel_sim import layout as L  # noqa: E402
from hasel_wheel_sim.effects import REALISTIC, effects_from_mapping  # noqa: E402
from hasel_wheel_sim.model import SECTOR, Extensions  # noqa: E402
from hasel_wheel_sim.params import WheelParams, packaged  # noqa: E402
from hasel_wheel_sim.plant import load_plant_config  # noqa: E402
from hasel_wheel_sim.wheel import TICK, HybridWheel  # noqa: E402

D = math.radians
PUSH = REALISTIC["start_push"]


def plant(seed: int, **events):
    config = load_plant_config(packaged("hasel_wheel_sim", "plant_realistic.yaml"))
    return dataclasses.replace(config, seed=seed,
                               effects=effects_from_mapping({**REALISTIC, **events}))


def run(pc, reference: float, seconds: float, w0: float = 0.0, **kw):
    loop = WheelLoop(controller_config(**kw), ((0.0, reference),), pc, w0=w0, clock=lambda: 0.0)
    log = run_wheels([loop], seconds)[0]
    return loop, log, np.asarray(log.t), np.asarray(log.true_speed)


def fig5() -> None:
    torque, stroke = PUSH["torque"]["value"], PUSH["stroke"]["value"]
    w = HybridWheel(WheelParams(), Extensions(start_torque=torque, start_stroke=stroke), "exact",
                    xi1=3 * SECTOR + D(11.25))
    x0 = w.s[L.S_XI1]
    w.drive(3, D(11.25))
    for _ in range(round(3.0 / TICK)):
        w.advance()
    w.drive(None)
    while w.s[L.S_XI2] != 0.0:
        w.advance()
    alone = torque * stroke / (2 * WheelParams().friction_torque)
    print(f"Fig. 5 experiment (start push {torque} N*m over {stroke} rad): the wheel rolls "
          f"{math.degrees(w.s[L.S_XI1] - x0):.1f} deg; the push alone, P Theta / (2 T_f): "
          f"{math.degrees(alone):.1f} deg")


def from_rest() -> None:
    print("\nFrom rest to 1.0 rad/s, 40 s hold (steady window: the last 10 s):")
    print("seed | first reaches 1.0 rad/s [s] | steady err [%] | NRMSE")
    rows = []
    for seed in range(16):
        _, log, _, _ = run(plant(seed), 1.0, 40.0)
        m = segment_metrics(log, ((0.0, 1.0),), 40.0)[0]
        rows.append((start_time(log, 1.0), m.steady_error, m.nrmse))
        print(f"{seed:4d} | {rows[-1][0]:6.2f} | {m.steady_error:6.3f} | {m.nrmse:.4f}")
    t, err, nrmse = (np.array(c) for c in zip(*rows))
    print(f"all 16: start {t.min():.2f}-{t.max():.2f} s (median {np.median(t):.2f}); "
          f"|err| <= 0.5 % in {(np.abs(err) <= 0.5).sum()}, NRMSE <= 0.04 in "
          f"{(nrmse <= 0.04).sum()}, both in {((np.abs(err) <= 0.5) & (nrmse <= 0.04)).sum()}")


def obstacles() -> None:
    print("\nObstacle 0.2 N*m for 0.5 s at 20 s, 1.0 rad/s from rest:")
    print("seed | restarts | back within 2 % after its end [s]")
    for seed in range(4):
        ob = {"enabled": True, "time": {"value": 20.0, "unit": "s"},
              "duration": {"value": 0.5, "unit": "s"}, "torque": {"value": 0.2, "unit": "N*m"}}
        loop, _, t, v = run(plant(seed, obstacle=ob), 1.0, 40.0)
        after = t > 20.5
        back = t[after][np.argmax(np.abs(v[after] - 1.0) <= 0.02)] - 20.5
        print(f"{seed:4d} | {loop.ctrl.core.stall.total_restarts} | {back:.2f}")
    ob = {"enabled": True, "time": {"value": 15.0, "unit": "s"},
          "duration": {"value": 1e6, "unit": "s"}, "torque": {"value": 0.2, "unit": "N*m"}}
    loop = WheelLoop(controller_config(), ((0.0, 1.0),), plant(1, obstacle=ob), w0=0.0,
                     clock=lambda: 0.0)
    core = loop.ctrl.core
    while core.gave_up is None and loop.plant.t < 120.0:
        loop.step()
    print(f"For good (seed 1, from 15 s): HV off {loop.plant.t - 15.0:.1f} s after it, status "
          f"level {core.status().level}: {core.status().text!r}")


def dead_pad() -> None:
    print("\nPad 5 dies at 20 s, hold at 1.5 rad/s (60 s; steady window: the last 10 s):")
    print("seed | named after [s] | turns | measured gain | steady err [%] | NRMSE")
    for seed in range(4):
        death = {"enabled": True, "pad": {"value": 5, "unit": "1"},
                 "time": {"value": 20.0, "unit": "s"}, "gain": {"value": 0.0, "unit": "1"}}
        loop, log, t, v = run(plant(seed, pad_death=death), 1.5, 60.0, w0=1.5)
        verdict = loop.ctrl.core.pads.dead.get(5)
        m = segment_metrics(log, ((0.0, 1.5),), 60.0)[0]
        if verdict is None:
            print(f"{seed:4d} | not named | - | - | {m.steady_error:.3f} | {m.nrmse:.4f}")
            continue
        sel = (t >= 20.0) & (t <= verdict.t)
        turns = np.sum(v[sel]) * TICK / (2 * math.pi)
        print(f"{seed:4d} | {verdict.t - 20.0:.2f} | {turns:.1f} | {verdict.gain:.2f} | "
              f"{m.steady_error:.3f} | {m.nrmse:.4f}")


def finite_difference() -> None:
    loop, log, t, v = run(plant(1), 1.0, 60.0, speed_source="finite_difference")
    moving = [float(np.mean(np.abs(v[(t >= a) & (t < a + 10)]) > 0.05)) for a in range(0, 60, 10)]
    print(f"\nFinite-difference speed from rest, 60 s at 1.0 rad/s (seed 1): {len(log.decisions)} "
          f"decisions, {loop.ctrl.core.stall.total_restarts} stalls restarted, gave up: "
          f"{loop.ctrl.core.gave_up is not None}; share of each 10 s moving: "
          + " ".join(f"{m:.2f}" for m in moving))


if __name__ == "__main__":
    fig5()
    from_rest()
    obstacles()
    dead_pad()
    finite_difference()
