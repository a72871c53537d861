"""The start push (model.start_push) and START (HybridWheel.start_now): closed forms and rules."""
import math

import numpy as np
import pytest

from hasel_wheel_common import protocol as P
from hasel_wheel_sim import layout as L
from hasel_wheel_sim.model import SECTOR, Extensions, acceleration, param_vector
from hasel_wheel_sim.params import WheelParams
from hasel_wheel_sim.wheel import TICK, CommandError, HybridWheel

D = math.radians
FRICTION = WheelParams().friction_torque       # T_f at the axle [N*m]


def fig5_travel(torque: float, stroke: float, rolling_law: bool = True, contact: float = D(11.25),
                seconds: float = 3.0) -> float:
    """Paper Fig. 5(d): pad 3 in contact at ``contact`` from vertical, switched on for
    ``seconds`` on a standing wheel; the angle [rad] the wheel has rolled once it stops."""
    w = HybridWheel(WheelParams(), Extensions(start_torque=torque, start_stroke=stroke), "exact",
                    xi1=3 * SECTOR + contact)
    if not rolling_law:
        w.pv[L.P_SIGMA6] = 0.0             # (43) off: the push alone
    x0 = w.s[L.S_XI1]
    w.drive(3, contact)
    for _ in range(round(seconds / TICK)):
        w.advance()
    w.drive(None)
    while w.s[L.S_XI2] != 0.0:
        w.advance()
    return float(w.s[L.S_XI1] - x0)


@pytest.mark.parametrize("torque, stroke", [(0.05, 0.2), (0.1, 0.1), (0.03, 0.3)])
def test_a_strong_push_rolls_the_wheel_as_far_as_its_work_allows(torque, stroke):
    # P >= 2 T_f: the push ends with the wheel rolling; its work P Theta / 2 equals
    # friction's T_f x travel
    assert torque >= 2 * FRICTION
    assert fig5_travel(torque, stroke, rolling_law=False) == pytest.approx(
        torque * stroke / (2 * FRICTION), rel=1e-4)


@pytest.mark.parametrize("torque", [0.015, 0.02, 0.025])
def test_a_weak_push_stops_the_wheel_within_its_stroke(torque):
    # T_f < P <= 2 T_f: an undamped spring push against constant friction stops at twice its
    # balance point, 2 Theta (1 - T_f / P), where static friction holds it
    stroke = 0.1
    assert FRICTION < torque <= 2 * FRICTION
    assert fig5_travel(torque, stroke, rolling_law=False) == pytest.approx(
        2 * stroke * (1 - FRICTION / torque), rel=1e-4)


def test_without_the_push_a_standing_wheel_does_not_start():
    # the paper's model: (43) gives no force at rest (its rise term is 0 at switch-on)
    assert fig5_travel(0.0, 0.1) == 0.0
    assert fig5_travel(FRICTION * 0.99, 0.1) == 0.0      # weaker than static friction


def test_the_fig5_experiment_of_the_realistic_wheel_rolls_further_than_its_push_alone():
    # with (43) on, the pad is still on when the wheel reaches (43)'s bump (17-25 deg of
    # contact), so it rolls further than the push's closed form; the paper's model alone
    # (no push) does not move at all.  The angle itself is printed by benchmarks/bench_start.py.
    push_alone = 0.05 * 0.2 / (2 * FRICTION)
    assert math.degrees(push_alone) + 11.25 > 17.0          # the push reaches the bump
    assert fig5_travel(0.05, 0.2) > 1.5 * push_alone
    assert fig5_travel(0.0, 0.2) == 0.0


@pytest.mark.parametrize("on_speed, share", [(0.0, 1.0), (0.25, 0.5), (0.5, 0.0), (2.0, 0.0)])
def test_the_push_fades_with_the_speed_at_switch_on(on_speed, share):
    pv = param_vector(WheelParams(), Extensions(start_torque=0.05, start_stroke=0.2, start_speed=0.5))
    xi_c, phi_a = D(10), D(8)                 # 2 deg rolled since switch-on, (43) ~ 0 there
    base = acceleration(5 * SECTOR + xi_c, 0.1, 1.0, 5.0, phi_a, 1.0, 1.0, pv, 1.0, math.inf)
    a = acceleration(5 * SECTOR + xi_c, 0.1, 1.0, 5.0, phi_a, 1.0, 1.0, pv, 1.0, on_speed)
    expected = share * 0.05 * (1 - D(2) / 0.2) * pv[L.P_INV_INERTIA]
    assert a - base == pytest.approx(expected, rel=1e-12, abs=1e-15)


def table2_trial(ext: Extensions) -> np.ndarray:
    """A Table II trial: 1 rad/s, six priming pads at 3 deg, then phi_a 5 deg, 20 s."""
    w = HybridWheel(WheelParams(), ext, "tick", xi2=1.0)
    w.open_loop(D(5), D(22), priming=6)
    out = []
    for _ in range(round(20 / TICK)):
        w.advance()
        out.append((w.s[L.S_XI1], w.s[L.S_XI2]))
    return np.array(out)


def test_at_rolling_speeds_the_model_is_unchanged():
    # every pad of a Table II trial switches on faster than start_speed: bit for bit the same
    on = table2_trial(Extensions(start_torque=0.05, start_stroke=0.2, start_speed=0.5))
    off = table2_trial(Extensions())
    assert np.array_equal(on, off)


def standing(contact: float) -> HybridWheel:
    return HybridWheel(WheelParams(), Extensions(start_torque=0.05, start_stroke=0.2), "tick",
                       xi1=5 * SECTOR + contact)


def test_start_now_switches_the_pad_in_contact_on_at_once_and_off_at_phi_d():
    w = standing(D(10))
    w.command(6, D(3), D(22), 7)             # pending: forgotten by the START
    assert w.start_now(5, 0.0, D(20), 9) == 0
    assert (w.s[L.S_Q], w.s[L.S_ETA], w.s[L.S_CMD_SEQ], w.s[L.S_PEND]) == (1.0, 5.0, 9.0, 0.0)
    assert w.s[L.S_PHI_A] == pytest.approx(D(10), abs=1e-12)    # the rise starts where it is
    while w.s[L.S_Q]:
        w.advance()
    assert w.s[L.S_XI1] - 5 * SECTOR >= D(20)                  # off at the first tick past phi_d
    assert w.s[L.S_XI1] - 5 * SECTOR < D(20) + w.s[L.S_XI2] * TICK + 1e-12


@pytest.mark.parametrize("contact, n_a, window, reason", [
    (D(10), 5, (D(12), D(20)), P.R_NOT_IN_CONTACT),          # not yet at phi_a
    (D(21), 5, (0.0, D(20)), P.R_NOT_IN_CONTACT),            # past phi_d
    (D(10), 6, (0.0, SECTOR), P.R_NOT_IN_CONTACT),           # another pad in contact
])
def test_start_now_outside_its_window_is_refused_and_changes_nothing(contact, n_a, window, reason):
    w = standing(contact)
    before = w.s.copy()
    assert w.start_now(n_a, *window) == reason
    assert np.array_equal(w.s, before)


def test_start_now_while_a_pad_is_on_is_refused():
    w = standing(D(10))
    assert w.start_now(5, 0.0, SECTOR) == 0
    assert w.start_now(5, 0.0, SECTOR) == P.R_ACTUATOR_ON


def test_start_now_refuses_what_a_command_refuses():
    with pytest.raises(CommandError, match="n_a = 16") as e:
        standing(D(10)).start_now(16, 0.0, SECTOR)
    assert e.value.code == P.R_N_A
