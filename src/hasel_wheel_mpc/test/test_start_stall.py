"""The embedded runner from rest, through an obstacle and past a dead pad (issue scenarios).

The plant is the realistic one (``plant_realistic.yaml``: start push, gain spread, noise,
latency), the controller the default.  The bounds are the benchmark's
(``benchmarks/bench_start.py``, docs/benchmarks.md) with room for other seeds."""
import dataclasses
import math

import numpy as np
import pytest

from hasel_wheel_mpc.closed_loop import WheelLoop, controller_config, run_wheels, segment_metrics, start_time
from hasel_wheel_mpc.core import STALLED
from hasel_wheel_sim import layout as L
from hasel_wheel_sim.effects import REALISTIC, effects_from_mapping
from hasel_wheel_sim.model import SECTOR
from hasel_wheel_sim.params import packaged
from hasel_wheel_sim.plant import load_plant_config

pytestmark = pytest.mark.xdist_group("start_stall")


def plant(seed: int = 1, **events):
    config = load_plant_config(packaged("hasel_wheel_sim", "plant_realistic.yaml"))
    return dataclasses.replace(config, seed=seed, effects=effects_from_mapping({**REALISTIC, **events}))


def run(pc, reference: float, seconds: float, w0: float = 0.0, **kw):
    loop = WheelLoop(controller_config(**kw), ((0.0, reference),), pc, w0=w0,
                     clock=lambda: 0.0)
    log = run_wheels([loop], seconds)[0]
    return loop, log, np.asarray(log.t), np.asarray(log.true_speed)


def test_from_rest_the_wheel_starts_and_holds_its_reference():
    loop, log, t, v = run(plant(1), 1.0, 40.0)
    assert start_time(log, 1.0) < 10.0
    m = segment_metrics(log, ((0.0, 1.0),), 40.0)[0]
    assert abs(m.steady_error) <= 0.5 and m.nrmse <= 0.04
    assert loop.ctrl.core.status().code == "ok"


def test_an_obstacle_that_stops_the_wheel_is_driven_through_by_a_restart():
    obstacle = {"enabled": True, "time": {"value": 20.0, "unit": "s"},
                "duration": {"value": 0.5, "unit": "s"}, "torque": {"value": 0.2, "unit": "N*m"}}
    loop, log, t, v = run(plant(1, obstacle=obstacle), 1.0, 50.0)
    assert v[(t > 20.3) & (t < 20.5)].max() == 0.0                  # it stopped the wheel
    assert loop.ctrl.core.stall.total_restarts >= 1
    after = t > 20.5
    back = t[after][np.argmax(np.abs(v[after] - 1.0) <= 0.02)] - 20.5
    assert back < 12.0
    assert abs(v[t > 40.0].mean() - 1.0) <= 0.01                   # and holds it again


def test_an_obstacle_that_holds_for_good_ends_with_hv_off_and_the_pad_named():
    obstacle = {"enabled": True, "time": {"value": 15.0, "unit": "s"},
                "duration": {"value": 1e6, "unit": "s"}, "torque": {"value": 0.2, "unit": "N*m"}}
    loop, log, t, v = run(plant(1, obstacle=obstacle), 1.0, 45.0)
    core, wheel = loop.ctrl.core, loop.plant.wheel
    status = core.status()
    pad = math.floor(wheel.s[L.S_XI1] / SECTOR + 1e-9) % 16
    assert (status.level, status.code, status.pads) == (2, STALLED, (pad,))
    assert core.stall.restarts == core.config.start.max_restarts
    assert wheel.s[L.S_Q] == 0.0 and wheel.s[L.S_ARMED] == 0.0       # HV off: nothing latched
    assert loop.ctrl.step(loop.plant.step(), 1.0).command is None       # and nothing sent


def test_a_pad_that_dies_is_named_within_ten_turns_and_the_speed_held():
    death = {"enabled": True, "pad": {"value": 5, "unit": "1"}, "time": {"value": 10.0, "unit": "s"},
             "gain": {"value": 0.0, "unit": "1"}}
    loop, log, t, v = run(plant(1, pad_death=death), 1.5, 50.0, w0=1.5)
    core = loop.ctrl.core
    assert list(core.pads.dead) == [5]
    rolled = np.trapezoid(v[(t >= 10.0) & (t <= core.pads.dead[5].t)], dx=1 / 300.0)
    assert rolled / (2 * math.pi) <= 10.0
    assert core.status().pads == (5,) and 5 in core.mpc.skip
    m = segment_metrics(log, ((0.0, 1.5),), 50.0)[0]
    assert abs(m.steady_error) <= 1.0


def test_the_finite_difference_loop_does_not_stop_for_good():
    loop, log, t, v = run(plant(1), 1.0, 60.0, speed_source="finite_difference")
    assert loop.ctrl.core.gave_up is None
    for a in range(10, 60, 10):                 # it moves in every 10 s of the run
        assert np.abs(v[(t >= a) & (t < a + 10)]).max() > 0.1
