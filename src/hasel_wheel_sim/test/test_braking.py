"""Braking (III-D) with our braking-force model: faster than friction alone, and calibrated
to the paper's Fig. 11(c) fall from 2.6 to 2.0 rad/s in about 1.2 s."""
import math

import pytest

from hasel_wheel_sim.trials_support import braking_fall_time
from hasel_wheel_sim.wheel import TICK


def fall_time(params, brake, mode="exact"):
    return braking_fall_time(params, brake=brake, mode=mode)


def test_friction_alone_matches_the_closed_form(params):
    a = params.friction_torque / params.inertia
    assert fall_time(params, brake=False) == pytest.approx(0.6 / a, abs=TICK)
    assert 0.6 / a == pytest.approx(1.66, abs=0.01)          # docs/model.md: "about 1.7 s"


def test_braking_is_faster_and_scales_with_brake_gain(params):
    t0 = fall_time(params.with_values(brake_gain=0.0), brake=True)
    t1 = fall_time(params.with_values(brake_gain=1.0), brake=True)
    t3 = fall_time(params, brake=True)
    assert fall_time(params, brake=False) == pytest.approx(t0, abs=2 * TICK)  # no force, no gain
    assert t3 < t1 < t0


@pytest.mark.parametrize("mode", ["exact", "tick"])
def test_default_brake_gain_reproduces_the_papers_fall_time(params, mode):
    # calibration target (paper Sec. V-C, Fig. 11(c)): ~1.2 s from 2.6 to 2.0 rad/s
    assert fall_time(params, brake=True, mode=mode) == pytest.approx(1.2, abs=0.06)
