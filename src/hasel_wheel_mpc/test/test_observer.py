"""The observer on quantised data with a known true speed, against the finite difference's
closed-form error, with glitches, lost samples and the realistic plant."""
import math

import numpy as np
import pytest

from hasel_wheel_mpc.observer import COUNT, Observer, ObserverConfig, finite_difference_speed
from hasel_wheel_sim.effects import REALISTIC, effects_from_mapping
from hasel_wheel_sim.plant import Plant, PlantConfig
from hasel_wheel_sim.wheel import TICK

D = math.radians
ENCODER = {"encoder": {"enabled": True, "noise_std": {"value": 0.0, "unit": "rad"}}}


def run(effects, seconds=40.0, seed=1):
    """Open loop at phi_a = 9 deg (steady ~2 rad/s); last 10 s of truth, estimate, raw angle."""
    p = Plant(config=PlantConfig(seed=seed, effects=effects_from_mapping(effects)), xi2=1.0)
    p.open_loop(D(9), D(22))
    obs = Observer(config=ObserverConfig(default_phi_a=D(9)))
    rows = []
    for _ in range(int(seconds / TICK)):
        s = p.step()
        if s is not None:
            e = obs.step(s)
            rows.append((s.t, p.wheel.s[2], e.xi2, s.angle, e.quality))
    t, v, est, ang, qual = map(np.array, zip(*rows))
    keep = t > seconds - 10.0
    return t, v, est, ang, qual, keep, obs


def rmse(a, b):
    return float(np.sqrt(np.mean((a - b) ** 2)))


def test_observer_beats_the_finite_difference_on_a_10_bit_encoder():
    t, v, est, ang, _, keep, obs = run(ENCODER)
    assert np.mean(v[keep]) == pytest.approx(2.0, abs=0.1)            # steady ~2 rad/s
    fd = finite_difference_speed(t, ang)
    # a floor-quantised difference takes only the values k*COUNT/dt: with f the fractional
    # count advanced per sample its RMSE is (COUNT/dt) sqrt(f (1 - f))
    f = (np.mean(v[keep]) * TICK / COUNT) % 1.0
    expected_fd = COUNT / TICK * math.sqrt(f * (1 - f))
    assert rmse(fd[keep], v[keep]) == pytest.approx(expected_fd, rel=0.15)
    assert rmse(est[keep], v[keep]) <= 0.02                            # issue target
    assert rmse(est[keep], v[keep]) < rmse(fd[keep], v[keep]) / 20
    assert obs.rejected == 0


def test_glitches_are_rejected_and_counted():
    fx = {**ENCODER, "encoder_glitches": {"enabled": True, "probability": {"value": 0.01, "unit": "1"}}}
    t, v, est, ang, qual, keep, obs = run(fx)
    n = len(t)
    # glitches land anywhere on the revolution: all but the few within ~6 sigma are caught
    assert obs.rejected == pytest.approx(0.01 * n, rel=0.25)
    assert rmse(est[keep], v[keep]) <= 0.02
    assert 0.8 < np.mean(qual[keep]) < 1.0                             # quality notices them


def test_lost_samples_are_bridged_by_the_model():
    fx = {**ENCODER, "dropouts": {"enabled": True, "probability": {"value": 0.05, "unit": "1"}}}
    t, v, est, ang, _, keep, _ = run(fx)
    assert np.max(np.diff(t)) > 2.5 * TICK                             # there were gaps
    assert rmse(est[keep], v[keep]) <= 0.02


def test_realistic_plant_model_mismatch():
    # retention, actuator spread, COM offset, drag, rise lag, platform, noise, glitches,
    # dropouts, latency: the nominal model in the observer is not the plant
    t, v, est, ang, _, keep, _ = run(REALISTIC)
    assert rmse(est[keep], v[keep]) <= 0.02


def test_observer_recovers_a_known_off_centre_mass():
    # com_offset: torque -T sin(xi1 + phase), i.e. a_d = -(T/I)(sin(phase) cos xi1 + cos(phase) sin xi1)
    from hasel_wheel_sim.params import WheelParams
    torque, phase = 0.004, 0.5
    fx = dict(ENCODER, com_offset={"enabled": True, "torque": {"value": torque, "unit": "N*m"},
                                   "phase": {"value": phase, "unit": "rad"}})
    *_, obs = run(fx, seconds=60.0)
    amp = torque / WheelParams().inertia                   # 0.112 rad/s^2
    c, a, b = obs.x[2:5]
    assert abs(c) < 0.3 * amp                              # no constant part was added
    assert a == pytest.approx(-amp * math.sin(phase), abs=0.2 * amp)
    assert b == pytest.approx(-amp * math.cos(phase), abs=0.2 * amp)


def test_without_the_disturbance_state_the_coefficients_stay_zero():
    p = Plant(config=PlantConfig(seed=1, effects=effects_from_mapping(ENCODER)), xi2=1.0)
    p.open_loop(D(9), D(22))
    obs = Observer(config=ObserverConfig(default_phi_a=D(9), disturbance_rate=0.0,
                                         initial_disturbance_std=0.0))
    for _ in range(600):
        s = p.step()
        if s is not None:
            e = obs.step(s)
    assert e.accel_coefficients == (0.0, 0.0, 0.0)


@pytest.mark.parametrize("reacquire", [30, 0])
def test_an_observer_started_on_a_fast_wheel_locks_on(reacquire):
    """Started on a wheel already coasting at 20 rad/s (a node restarted on a rolling
    wheel): the first guess (0 rad/s, std 2) is 0.067 rad behind after one sample, far
    beyond the gate, so every sample looks like a glitch.  After ``reacquire_after`` such
    samples in a row the observer restarts from their line fit and then tracks the coasting
    wheel; without it (0) it never recovers."""
    p = Plant(config=PlantConfig(seed=3, effects=effects_from_mapping(ENCODER)), xi2=20.0)
    obs = Observer(config=ObserverConfig(reacquire_after=reacquire))
    rows = []
    for _ in range(int(1.0 / TICK)):
        s = p.step()
        if s is not None:
            rows.append((s.t, p.wheel.s[2], obs.step(s).xi2))
    t, v, est = map(np.array, zip(*rows))
    late = t > 0.3
    if reacquire:
        assert obs.reacquisitions == 1 and obs.rejected == reacquire
        assert rmse(est[late], v[late]) < 0.05
    else:
        assert obs.reacquisitions == 0 and obs.rejected > 0.9 * len(t)
        assert rmse(est[late], v[late]) > 5.0
