"""Small helpers that run the model open loop (used by tests, benchmarks and tools)."""
from __future__ import annotations

import numpy as np

from . import layout as L
from .model import Extensions
from .params import WheelParams
from .wheel import TICK, HybridWheel, SwitchMode


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
