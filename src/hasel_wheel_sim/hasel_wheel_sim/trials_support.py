"""Small helpers that run the model open loop (used by tests, benchmarks and tools)."""
from __future__ import annotations

import numpy as np

from hasel_wheel_sim import layout as L
from hasel_wheel_sim.model import Extensions
from hasel_wheel_sim.params import WheelParams
from hasel_wheel_sim.wheel import TICK, HybridWheel, SwitchMode


def open_loop_speed(params: WheelParams, ext: Extensions, phi_a: float, seconds: float,
                    phi_d: float = np.radians(22.0), w0: float = 1.0, mode: SwitchMode = "exact",
                    rule: str = "after_active", return_state: bool = False):
    """True speed [rad/s] after every tick of a sequential open-loop run, shape (n,).

    With ``return_state`` also the unwrapped actuator of interest after every tick, (n,).
    """
    w = HybridWheel(params, ext, mode, xi2=w0)
    w.open_loop(phi_a, phi_d, rule)  # type: ignore[arg-type]
    n = int(round(seconds / TICK))
    v = np.empty(n)
    eta = np.empty(n, dtype=np.int64)
    s = w.s
    for k in range(n):
        w.advance()
        v[k] = s[L.S_XI2]
        eta[k] = int(s[L.S_ETA])
    return (v, eta) if return_state else v


def braking_fall_time(params: WheelParams, brake: bool = True, w0: float = 2.6, w1: float = 2.0,
                      mode: SwitchMode = "exact", limit: float = 10.0) -> float:
    """Time [s] for the speed to fall from w0 to w1 [rad/s] (paper Fig. 11(c): 2.6 -> 2.0).

    With ``brake`` a braking input (III-D) is sent at every switch-on, decided from the contact
    sector as the controller does; without it the wheel coasts on friction alone.
    """
    from hasel_wheel_sim.model import braking_input

    w = HybridWheel(params, mode=mode, xi2=w0)
    if brake:
        w.command(*braking_input(w.s[L.S_XI1]))
    t = 0.0
    while w.s[L.S_XI2] > w1:
        ev = w.advance()
        t += TICK
        if brake and any(e[2] == L.EV_ON for e in ev):
            w.command(*braking_input(w.s[L.S_XI1]))
        if t > limit:
            raise RuntimeError(f"speed did not fall below {w1} rad/s within {limit} s")
    return t
