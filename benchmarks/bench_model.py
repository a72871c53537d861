"""Benchmark of the hybrid model and the plant.

Prints, on one core:
* one wheel through ``Plant.step`` (the embedded runner's loop), effects off and all on:
  simulated seconds per wall second (target >= 200x real time);
* N wheels / parameter sets advanced together by the compiled batch integrator:
  wheel-seconds per wall second (target >= 20,000 at N = 256);
* where a batch tick goes (bookkeeping against the force law), and the same batch compiled
  with plain ``numba.njit`` (reference counting on, tick not inlined) beside
  ``jit.jit_kernel``'s.

Run: ``./dev bench`` or ``.venv/bin/python benchmarks/bench_model.py``.
"""
from __future__ import annotations

import math
import os
import time

import numpy as np

from hasel_wheel_sim import layout as L
from hasel_wheel_sim.effects import REALISTIC, effects_from_mapping
from hasel_wheel_sim.integrator import simulate_batch, simulate_batch_parallel
from hasel_wheel_sim.model import param_vector
from hasel_wheel_sim.params import WheelParams
from hasel_wheel_sim.plant import Plant, PlantConfig
from hasel_wheel_sim.wheel import TICK, initial_state, set_open_loop

D = math.radians
SIM_SECONDS = 60.0


def single_wheel(config: PlantConfig, repeats: int = 3) -> float:
    """Best simulated-seconds-per-wall-second of a 60 s open-loop run through Plant.step."""
    best = 0.0
    for _ in range(repeats):
        plant = Plant(config=config, xi2=1.0)
        plant.open_loop(D(3), D(22), priming=6)
        n = int(round(SIM_SECONDS / TICK))
        t0 = time.perf_counter()
        for _ in range(n):
            plant.step()
        best = max(best, SIM_SECONDS / (time.perf_counter() - t0))
    return best


def batch(n_wheels: int, seconds: float = 20.0, repeats: int = 3, fn=simulate_batch,
          force_law: bool = True) -> float:
    """Best wheel-seconds per wall second for N parameter sets advanced together.

    ``force_law=False`` empties the force law's band, so the actuators never push: what is
    left is the integrator's bookkeeping (RK4 arithmetic, events, recording) without the
    log, exp and sin of the force law.
    """
    rng = np.random.default_rng(0)
    p = WheelParams()
    pvs = np.stack([param_vector(p.with_values(sigma6=p.sigma6 * rng.uniform(0.8, 1.2),
                                               tau_f=p.tau_f * rng.uniform(0.8, 1.2)))
                    for _ in range(n_wheels)])
    if not force_law:
        pvs[:, L.P_BAND_LO], pvs[:, L.P_BAND_HI] = math.inf, 0.0
    n_ticks = int(round(seconds / TICK))
    best = 0.0
    for _ in range(repeats):
        states = np.stack([initial_state(0.0, 1.0) for _ in range(n_wheels)])
        for i, s in enumerate(states):
            set_open_loop(s, D(1 + (i % 10)), D(22))
        out = np.empty((n_wheels, n_ticks, 3))
        t0 = time.perf_counter()
        fn(states, pvs, TICK, n_ticks, out)
        best = max(best, n_wheels * seconds / (time.perf_counter() - t0))
    return best


def refcounted_batch():
    """simulate_batch compiled with plain ``numba.njit`` instead of ``jit.jit_kernel``: the
    tick function with numba's reference counting on, called (not inlined) once per tick.
    The same arithmetic (bit-identical results); only the compilation differs."""
    import numba

    from hasel_wheel_sim import integrator

    tick = numba.njit(nogil=True)(integrator._advance)

    @numba.njit(nogil=True)
    def run(states, pvs, h, n_ticks, out):
        ev = np.zeros((L.EV_MAX_PER_TICK, 4))
        for i in range(states.shape[0]):
            s, pv, o = states[i], pvs[i], out[i]
            for k in range(n_ticks):
                tick(s, pv, h, ev)
                o[k, 0] = s[L.S_XI1]
                o[k, 1] = s[L.S_XI2]
                o[k, 2] = s[L.S_Q]
    return run


def libm_floor_ns(n: int = 5_000_000) -> float:
    """Measured cost [ns] of one log + exp + sin in compiled code (what one force-law call needs)."""
    from hasel_wheel_sim.jit import jit

    @jit
    def loop(n: int, x0: float) -> float:
        acc = 0.0
        for i in range(n):
            x = x0 + 1e-9 * i
            acc += math.log(x) + math.exp(-x) + math.sin(x)
        return acc
    loop(10, 0.3)
    best = math.inf
    for _ in range(3):
        t0 = time.perf_counter()
        loop(n, 0.3)
        best = min(best, (time.perf_counter() - t0) / n * 1e9)
    return best


def numpy_costs(n: int = 256) -> tuple[float, float]:
    """(numpy call overhead [us], per-element cost of log+exp+sin [ns]) at N wheels."""
    import timeit
    a = np.random.default_rng(0).random(n) + 0.1
    b = np.empty(n)
    call = min(timeit.repeat(lambda: np.add(a, a, out=b), number=20000, repeat=3)) / 20000
    big = np.random.default_rng(0).random(65536) + 0.1
    trio = min(timeit.repeat(lambda: (np.log(big), np.exp(big), np.sin(big)), number=50,
                             repeat=3)) / 50 / big.size
    return call * 1e6, trio * 1e9


def main() -> None:
    cores = os.sched_getaffinity(0)
    batch(4, 1.0, 1)                                            # compile outside the timing
    batch(4, 1.0, 1, simulate_batch_parallel)
    par = batch(256, fn=simulate_batch_parallel)
    os.sched_setaffinity(0, {min(cores)})                       # one core from here on
    nominal = PlantConfig(seed=1)
    realistic = PlantConfig(seed=1, switching="tick", effects=effects_from_mapping(REALISTIC))
    single_wheel(nominal, 1)                                    # warm-up
    single_wheel(realistic, 1)
    off = single_wheel(nominal)
    on = single_wheel(realistic)
    print("hasel_wheel_sim model benchmark (one core)")
    print(f"  one wheel, Plant.step, effects off : {off:8.0f} x real time   (target 200x: {off / 200:5.1f}x of target)")
    print(f"  one wheel, Plant.step, all effects : {on:8.0f} x real time   (target 200x: {on / 200:5.1f}x of target)")
    rates = {}
    for n in (1, 16, 64, 256, 1024):
        r = batch(n)
        rates[n] = r
        note = f"   (target 20,000 at N = 256: {r / 20000:5.1f}x of target)" if n == 256 else ""
        print(f"  batch N = {n:5d}                  : {r:8.0f} wheel-s per wall-s{note}")
    print(f"  batch N =   256, {len(cores)} cores (prange)   : {par:8.0f} wheel-s per wall-s"
          f"   (target 20,000: {par / 20000:5.1f}x of target)")
    bare = batch(256, force_law=False)
    before = refcounted_batch()
    batch(4, 1.0, 1, before)                                    # compile outside the timing
    before_rate = batch(256, fn=before)
    before_bare = batch(256, fn=before, force_law=False)
    ns = libm_floor_ns()
    tick_ns = 1e9 / rates[256] / 300
    bare_ns = 1e9 / bare / 300
    print(f"  where a tick goes at N = 256        : {tick_ns:8.0f} ns per wheel-tick in all; without the force")
    print(f"  law (bookkeeping only: {bare:6.0f} wheel-s per wall-s) {bare_ns:5.0f} ns; "
          f"one log + exp + sin costs {ns:.1f} ns,")
    print("  and an RK4 step evaluates the force law 4 times while an actuator is on (~half the time)")
    print(f"  the same batch compiled with plain njit (reference counting on, tick not inlined): "
          f"{before_rate:6.0f} wheel-s per wall-s, bookkeeping {1e9 / before_bare / 300:4.0f} ns per tick")
    call_us, elem_ns = numpy_costs()
    print(f"  numpy instead (why the batch is compiled): {call_us:.2f} us per call at N = 256, "
          f"{elem_ns:.1f} ns per element for log+exp+sin;")
    print(f"  an (N,)-array RK4 needs ~75 calls per step: >= {75 * call_us:.0f} us per step at N = 256, "
          f"<= {256 / (75 * call_us * 1e-6) / 300:.0f} wheel-s per wall-s before any event handling")


if __name__ == "__main__":
    main()
