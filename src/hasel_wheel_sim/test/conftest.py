"""Fixtures: the paper's wheel and helpers that run it (compiled core, exact events)."""
import math

import numpy as np
import pytest

from hasel_wheel_sim import layout as L
from hasel_wheel_sim.params import WheelParams
from hasel_wheel_sim.wheel import TICK, HybridWheel


@pytest.fixture(scope="session")
def params() -> WheelParams:
    return WheelParams()


def run_wheel(wheel: HybridWheel, seconds: float):
    """Advance ``wheel`` tick by tick; return times, speeds (n,) and all events (k, 4)."""
    n = int(round(seconds / TICK))
    t = np.empty(n)
    v = np.empty(n)
    events = []
    for k in range(n):
        ev = wheel.advance()
        events.extend(ev)
        t[k] = wheel.t
        v[k] = wheel.s[L.S_XI2]
    return t, v, np.array(events).reshape(-1, 4)


def deg(x: float) -> float:
    return math.radians(x)


@pytest.fixture(scope="session")
def run():
    """The ``run_wheel`` helper as a fixture (tests import nothing from conftest)."""
    return run_wheel
