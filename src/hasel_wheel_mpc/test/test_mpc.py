"""MPC core: the cost (59) on a hand-checkable case, braking selection, the fallback when no
candidate completes its cycle, and a short closed loop on the nominal plant."""
import math

import numpy as np
import pytest

from hasel_wheel_mpc.mpc import Mpc, MpcConfig, cost_59, costs_59
from hasel_wheel_sim.model import SECTOR

D = math.radians


def test_cost_59_by_hand():
    # current actuator on for 2 ticks, off for 3 (segment 0), candidate on for 3 (segment 1)
    q = np.array([1, 1, 0, 0, 0, 1, 1, 1, 0, 0], dtype=float)
    v = np.array([9, 9, 1.0, 2.0, 3.0, 2.5, 2.0, 1.5, 9, 9])
    ref = 2.0
    seg0 = ((1 - 2) ** 2 + 0 + (3 - 2) ** 2) / 3          # = 2/3
    seg1 = ((2.5 - 2) ** 2 + 0 + (1.5 - 2) ** 2) / 3      # = 1/6
    assert cost_59(v, q, ref) == pytest.approx(0.5 * (seg0 + seg1))
    out = np.stack([v, v, q], axis=-1)[None]
    c = np.empty(1)
    costs_59(out, ref, 0.0, c, 0.0)
    assert c[0] == pytest.approx(0.5 * (seg0 + seg1))
    costs_59(out, ref, 0.0, c, 2.0)                       # terminal term at the switch-off tick
    assert c[0] == pytest.approx(0.5 * (seg0 + seg1) + 2.0 * (1.5 - 2.0) ** 2)
    costs_59(out, ref, 0.5, c, 0.0)                       # d shifts the predicted speed
    assert c[0] == pytest.approx(0.5 * (((1.5 - 2) ** 2 + 0.25 + 2.25) / 3 + (1 + 0.25 + 0) / 3))
    assert cost_59(v[:6], q[:6], ref) == math.inf         # horizon too short: no full cycle


def test_braking_when_the_speed_is_above_the_reference_by_the_threshold():
    mpc = Mpc(config=MpcConfig(brake_threshold=0.3))
    xi1 = 20 * SECTOR + D(3)                               # pad 4 (2nd revolution) just on
    dec = mpc.decide(xi1, 2.6, 20, D(3), D(22), reference=2.0)
    assert dec.braking and dec.candidates == 0
    assert (dec.command.n_a, dec.command.phi_a, dec.command.phi_d) == (6, D(-22), D(-6))
    dec = mpc.decide(xi1, 2.25, 20, D(3), D(22), reference=2.0)   # 0.25 above: keep driving
    assert not dec.braking and dec.command.n_a == 5 and dec.command.phi_a >= 0


def test_no_complete_cycle_falls_back_to_the_strongest_push():
    mpc = Mpc(config=MpcConfig(max_horizon=0.05))
    dec = mpc.decide(1 * SECTOR + D(3), 1.0, 1, D(3), D(22), reference=2.0)
    assert (dec.command.phi_a, dec.command.phi_d) == (D(1), D(22)) and math.isinf(dec.cost)


def test_a_slow_wheel_is_pushed_towards_the_reference():
    mpc = Mpc()
    dec = mpc.decide(1 * SECTOR + D(3), 0.65, 1, D(3), D(22), reference=1.0)
    assert dec.command.phi_d >= D(20) and dec.predicted_speed > 0.65


def test_short_closed_loop_on_the_nominal_plant_settles_near_the_reference():
    from hasel_wheel_mpc.closed_loop import run_closed_loop, segment_metrics
    profile = ((0.0, 2.0),)
    log = run_closed_loop(profile=profile, duration=30.0)
    (ref, ss, nrmse, settle), = segment_metrics(log, profile, 30.0)
    assert ss < 3.0 and nrmse < 0.05 and settle < 10.0
