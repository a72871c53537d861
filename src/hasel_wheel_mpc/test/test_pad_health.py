"""PadHealth: pushes from known cycles, gains, and dead pads by its rule."""
import math

import numpy as np
import pytest

from hasel_wheel_mpc.pad_health import DEAD_CYCLES, MIN_PUSH, PadHealth

COAST = -0.36          # model's acceleration with no pad on [rad/s^2]
DT = 0.25              # cycle length [s]


def feed(h: PadHealth, pushes: dict[int, float], turns: int, t0: float = 0.0):
    """Turns of 16 cycles; pad i's cycle changes the speed by its push plus the coast."""
    found = []
    t = t0
    for _ in range(turns):
        for pad in range(16):
            t += DT
            v = h.cycle(pad, t, DT, pushes.get(pad, 0.1) + COAST * DT, COAST)
            if v is not None:
                found.append(v)
    return found, t


def test_the_push_is_the_speed_gained_beyond_coasting():
    h = PadHealth()
    h.cycle(3, 1.0, DT, 0.08 + COAST * DT, COAST)
    assert h.push[3] == pytest.approx(0.08, rel=1e-12)
    assert math.isnan(h.push[4])


def test_gains_are_pushes_over_the_median():
    h = PadHealth()
    pushes = {i: 0.1 for i in range(16)} | {2: 0.05, 7: 0.15}
    feed(h, pushes, 1)
    g = h.gains()
    assert g[2] == pytest.approx(0.5) and g[7] == pytest.approx(1.5) and g[0] == pytest.approx(1.0)


def test_a_pad_that_stops_pushing_is_found_dead_after_its_cycles_with_its_gain():
    h = PadHealth()
    found, t = feed(h, {}, 3)
    assert found == []
    found, t_dead = feed(h, {5: 0.0}, DEAD_CYCLES, t)
    assert [(v.pad, v.gain) for v in found] == [(5, pytest.approx(0.0, abs=1e-12))]
    assert found[0].t == pytest.approx(t + (DEAD_CYCLES - 1) * 16 * DT + 6 * DT)
    assert feed(h, {5: 0.0}, 2, t_dead)[0] == []           # said once


def test_a_weak_pad_above_the_dead_gain_is_not_dead():
    h = PadHealth()
    found, _ = feed(h, {5: 0.04}, 10)                       # 0.4 of the median
    assert found == [] and h.gains()[5] == pytest.approx(0.4)


def test_nothing_is_judged_while_the_pads_push_too_little_to_tell():
    h = PadHealth()
    pushes = {i: MIN_PUSH / 2 for i in range(16)} | {5: 0.0}
    assert feed(h, pushes, 5)[0] == []
    assert np.isnan(h.gains()).all()
