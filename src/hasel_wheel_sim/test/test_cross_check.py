"""Open-loop steady speed and t90 against docs/model.md's independent implementation
(phi_d = 22 deg, 1 rad/s at phi = 0, 60 s, sequential targets), within 2 %."""
import math

import numpy as np
import pytest

from hasel_wheel_sim.model import Extensions
from hasel_wheel_sim.trials_support import open_loop_speed
from hasel_wheel_sim.wheel import TICK

# phi_a [deg] -> exact w_ss [rad/s], exact t90 [s], tick w_ss [rad/s]   (docs/model.md)
NOTES = {1: (4.73, 26.6, 3.84), 5: (3.42, 22.5, 3.08), 9: (2.06, 16.1, 2.33), 11: (1.37, 9.8, 1.52)}


def steady_and_t90(v):
    t = np.arange(1, v.size + 1) * TICK
    ss = np.mean(v[t > t[-1] - 10.0])
    return ss, t[np.argmax(v > 0.9 * ss)]


@pytest.mark.parametrize("phi_a", sorted(NOTES))
def test_exact_switching_matches_the_cross_check(params, phi_a):
    ss, t90 = steady_and_t90(open_loop_speed(params, Extensions(), math.radians(phi_a), 60.0))
    assert ss == pytest.approx(NOTES[phi_a][0], rel=0.02)
    assert t90 == pytest.approx(NOTES[phi_a][1], rel=0.02)


@pytest.mark.parametrize("phi_a", sorted(NOTES))
def test_tick_switching_with_eq40_targets_matches_the_cross_check(params, phi_a):
    # the independent implementation counts "next actuator" from the sector measured at the
    # switch-off tick (eq. (40)); at 1 deg the tick after 22 deg lands past 22.5 deg and an
    # actuator is skipped, which is why 4.73 drops to 3.84 rad/s
    v = open_loop_speed(params, Extensions(), math.radians(phi_a), 60.0, mode="tick",
                        rule="after_measured")
    assert steady_and_t90(v)[0] == pytest.approx(NOTES[phi_a][2], rel=0.02)


def test_counting_from_the_actuator_of_interest_makes_ticks_faster_than_exact(params):
    # no skipped pad, and each actuator stays on until the tick after 22 deg: more push
    exact = open_loop_speed(params, Extensions(), math.radians(1), 60.0)
    tick = open_loop_speed(params, Extensions(), math.radians(1), 60.0, mode="tick",
                           rule="after_active")
    assert steady_and_t90(tick)[0] > steady_and_t90(exact)[0] + 0.3
