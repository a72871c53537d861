"""The model's pieces against hand-derived numbers: force law, jump map (52), jump set (53),
target unwrapping (15 -> 0) and the braking rules (III-D)."""
import math

import numpy as np
import pytest

from hasel_wheel_sim import layout as L
from hasel_wheel_sim.model import (SECTOR, Extensions, accelerating_input, acceleration,
                                   braking_input, force_law, in_jump_set, jump_map, param_vector,
                                   unwrap_target)
from hasel_wheel_sim.params import ParameterError, WheelParams

D = math.radians


@pytest.fixture(scope="module")
def pv():
    return param_vector(WheelParams())


def test_force_law_is_equation_43(pv):
    p = WheelParams()
    xi_c, xi2, phi_a = 0.36, 3.0, D(3)
    expected = (1 / xi_c**p.sigma1) / (p.sigma2 * xi2 + p.sigma3) \
        * math.exp(-(math.log(xi_c) - p.sigma4) ** 2 / p.sigma5**2) * p.sigma6 * (xi_c - phi_a)
    assert force_law(xi_c, xi2, phi_a, pv) == pytest.approx(expected, rel=1e-13)
    assert force_law(phi_a, xi2, phi_a, pv) == 0.0           # rises from 0 at switch-on


def test_force_bump_peaks_near_exp_sigma4(pv):
    # docs/model.md: with sigma4 = -1.004 the bump peaks near exp(-1.004) = 0.37 rad
    xs = np.linspace(0.25, 0.45, 20001)
    f = np.array([force_law(x, 0.0, 0.0, pv) / x for x in xs])  # divide out the rise term
    peak = xs[np.argmax(f)]
    # d/dx of -s1 ln x - (ln x - s4)^2/s5^2 = 0  ->  ln x = s4 - s1 s5^2 / 2
    p = WheelParams()
    assert peak == pytest.approx(math.exp(p.sigma4 - p.sigma1 * p.sigma5**2 / 2), abs=2e-5)
    # "practically zero below 17 deg" (docs/model.md): 1.6 % of the peak there, falling fast
    assert force_law(D(17), 0.0, 0.0, pv) / D(17) < 0.02 * f.max()
    assert force_law(D(14), 0.0, 0.0, pv) / D(14) < 1e-4 * f.max()


def test_braking_force_is_the_mirrored_law_times_brake_gain(pv):
    p = WheelParams()
    x, xi2 = D(20), 2.5
    # mirror: contact angle -x, activation at -22 deg -> rise term (-x + 22 deg)
    mirrored = force_law(x, xi2, x - (-x + D(22)), pv)
    assert force_law(-x, xi2, D(-22), pv) == pytest.approx(p.brake_gain * mirrored, rel=1e-12)
    # it decelerates: torque r F sin(xi_c) < 0 with xi_c < 0
    a_on = acceleration(0.0 + 22 * SECTOR - x, xi2, 1.0, 22.0, D(-22), 1.0, 0.0, pv)
    a_off = acceleration(0.0, xi2, 0.0, 0.0, 0.0, 1.0, 0.0, pv)
    assert a_on < a_off < 0.0


def test_friction_alone_and_static_friction(pv):
    p = WheelParams()
    a = p.friction_torque / p.inertia
    assert acceleration(1.0, 2.0, 0.0, 0.0, 0.0, 1.0, 0.0, pv) == pytest.approx(-a, rel=1e-14)
    assert acceleration(1.0, -2.0, 0.0, 0.0, 0.0, 1.0, 0.0, pv) == pytest.approx(a, rel=1e-14)
    # at rest with no drive: held
    assert acceleration(1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, pv) == 0.0
    # at rest with a COM torque below friction: still held; above friction: moves
    weak = param_vector(p, Extensions(com_torque=0.5 * p.friction_torque, com_phase=math.pi / 2))
    strong = param_vector(p, Extensions(com_torque=2.0 * p.friction_torque, com_phase=math.pi / 2))
    assert acceleration(0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, weak) == 0.0
    assert acceleration(0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, strong) == pytest.approx(
        -p.friction_torque / p.inertia, rel=1e-12)


def test_jump_map_switch_off_with_wrap_from_15_to_0():
    # actuator 15 of the second revolution (eta = 31) switches off at 22 deg; u = (0, 3, 22 deg)
    xi1, xi2 = 31 * SECTOR + D(22), 3.3
    n = unwrap_target(0.0, D(3), xi1)
    assert n == 32                              # actuator 0, next revolution: 15 -> 16, not 0
    x = jump_map(xi1, xi2, 1, 31.0, n, D(3), D(22))
    assert x[0] == xi1 and x[1] == xi2           # xi1, xi2 unchanged
    assert x[2] == 0                             # q+ = 1 - q
    assert x[3] == pytest.approx(D(22.5) - D(22) + D(3), abs=1e-12)   # Delta+ = q(N pi/8 + phi_a - xi1)
    assert x[4] == pytest.approx(D(22.5), abs=1e-12)                  # delta+ = N pi/8 + phi_d - xi1
    assert x[5] == 32 and int(x[5]) % 16 == 0    # eta+ = q N + (1 - q) eta


def test_jump_map_switch_on():
    xi1 = 32 * SECTOR + D(3)
    x = jump_map(xi1, 2.0, 0, 32.0, 32.0, D(3), D(22))
    assert x[2] == 1 and x[3] == 0.0             # Delta+ = q (...) = 0
    assert x[4] == pytest.approx(D(19), abs=1e-12)
    assert x[5] == 32.0                          # eta unchanged at switch-on


def test_jump_set():
    assert in_jump_set(0, 0.0, 0.1)       # switch-on due
    assert in_jump_set(1, 0.0, 0.0)       # switch-off due
    assert not in_jump_set(0, 0.1, 0.2)   # flowing, off
    assert not in_jump_set(1, 0.0, 0.2)   # flowing, on
    assert not in_jump_set(0, 0.0, 0.0)   # (Delta = 0, delta = 0, q = 0) is in neither part


@pytest.mark.parametrize("n_a, phi_a, xi1, expected", [
    (1, D(3), 0.0, 1),                          # next pad
    (0, D(3), 15 * SECTOR + D(22), 16),         # wrap 15 -> 0 is 15 -> 16
    (5, D(3), 5 * SECTOR + D(22), 21),          # same pad again: one revolution later
    (5, D(3), 5 * SECTOR + D(3), 5),            # exactly at the switch-on angle: Delta+ = 0
    (3, D(-22), 1 * SECTOR + D(22), 3),         # braking: two pads ahead
])
def test_unwrap_target_is_first_future_switch_on(n_a, phi_a, xi1, expected):
    n = unwrap_target(float(n_a), phi_a, xi1)
    assert n == expected
    assert n * SECTOR + phi_a >= xi1 - 1e-15
    assert (n - 16) * SECTOR + phi_a < xi1


def test_braking_target_selection_with_negative_angles():
    # actuator 4 of the second revolution (eta = 20) switches off at +22 deg
    xi1 = 20 * SECTOR + D(22)
    n_a, phi_a, phi_d = braking_input(xi1)
    assert (n_a, phi_a, phi_d) == (6, D(-22), D(-6))     # (20 + 2) mod 16, III-D / V-A angles
    n = unwrap_target(float(n_a), phi_a, xi1)
    assert n == 22
    x = jump_map(xi1, 2.6, 1, 20.0, n, phi_a, phi_d)
    assert x[3] == pytest.approx(D(1.0), abs=1e-12)      # switch-on 1 deg later, at xi_c = -22 deg
    assert x[4] == pytest.approx(D(17.0), abs=1e-12)     # switch-off at xi_c = -6 deg
    assert xi1 + x[3] - x[5] * SECTOR == pytest.approx(D(-22), abs=1e-12)
    with pytest.raises(ValueError, match="phi_a < phi_d <= 0"):
        braking_input(xi1, D(-6), D(-22))


def test_accelerating_input_is_next_pad():
    assert accelerating_input(15 * SECTOR + D(10), D(3), D(22))[0] == 0
    with pytest.raises(ValueError, match="0 <= phi_a < phi_d"):
        accelerating_input(0.0, D(-3), D(22))


def test_param_vector_layout():
    p = WheelParams()
    gains = tuple(0.5 * (i + 1) for i in range(16))
    pv = param_vector(p, Extensions(gains=gains))
    assert pv.shape == (L.P_SIZE,)
    assert pv[L.P_INV_INERTIA] == pytest.approx(1 / p.inertia)
    assert tuple(pv[L.P_GAINS:L.P_GAINS + 16]) == gains


@pytest.mark.parametrize("kwargs, match", [
    ({"gains": (1.0,)}, r"'gains'.*1.*16.*\(0, 10\]"),
    ({"gains": (1.0,) * 15 + (0.0,)}, r"'gains\[15\]' = 0.0.*\(0, 10\]"),
    ({"retention_recovery": 0.0}, r"'retention_recovery' = 0.0.*\(0, 1e\+06\] s"),
    ({"viscous": -1e-4}, r"'viscous' = -0.0001.*\[0, 1\] N\*m\*s/rad"),
    ({"rise_time": math.nan}, r"'rise_time' = nan"),
    ({"com_phase": 4.0}, r"'com_phase' = 4.0"),
    ({"retention_rate": "0.01"}, r"'retention_rate' = '0.01'"),
])
def test_extensions_refuse_values_the_core_cannot_use(kwargs, match):
    # e.g. a zero recovery time would divide by zero in the core and give inf silently
    with pytest.raises(ParameterError, match=match):
        Extensions(**kwargs)


def test_force_band_edges_are_negligible(pv):
    # the law is skipped outside the band: there it is < 1e-25 of its peak
    from hasel_wheel_sim.model import force_band
    lo, hi = force_band(WheelParams())
    assert math.radians(9) < lo < math.radians(11) and hi > SECTOR
    peak = max(force_law(x, 0.0, 0.0, pv) for x in np.linspace(0.3, 0.42, 2000))
    slack = pv.copy()
    slack[L.P_BAND_LO], slack[L.P_BAND_HI] = 1e-12, 10.0      # evaluate everywhere
    assert force_law(lo * (1 - 1e-9), 0.0, 0.0, slack) < 1e-25 * peak
    assert force_law(lo * (1 - 1e-9), 0.0, 0.0, pv) == 0.0
    assert force_law(lo * (1 + 1e-9), 0.0, 0.0, pv) > 0.0
