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


@pytest.fixture(scope="session")
def firmware_build():
    """The C++ firmware core built for the host (skips where no compiler exists)."""
    from hasel_wheel_sim.device_cpp import compiler_missing, default_build
    missing = compiler_missing()
    if missing:
        pytest.skip(f"the C++ firmware core needs {missing}; install g++ and cmake to run it")
    return default_build()


@pytest.fixture(params=["python", "cpp"])
def make_core(request):
    """A factory of fresh device cores: the Python reference, then the C++ firmware core."""
    if request.param == "python":
        from hasel_wheel_sim.device_core import DeviceCore
        return DeviceCore
    from hasel_wheel_sim.device_cpp import CppDeviceCore, load_library
    lib = load_library(request.getfixturevalue("firmware_build"))
    return lambda: CppDeviceCore(lib)
