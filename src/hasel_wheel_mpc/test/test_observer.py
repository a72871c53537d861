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
    assert rmse(est[keep], v[keep]) <= 0.02                            # target [rad/s]
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
    c, a, b, e, f = obs.x[2:]
    assert abs(c) < 0.3 * amp                              # no constant part was added
    assert a == pytest.approx(-amp * math.sin(phase), abs=0.2 * amp)
    assert b == pytest.approx(-amp * math.cos(phase), abs=0.2 * amp)
    assert math.hypot(e, f) < 0.2 * amp                    # nor a once-per-lap part


def test_observer_recovers_a_known_platform_disturbance():
    # platform_disturbance: torque T sin(psi + phase), psi = (r/L) xi1 the pivot angle, i.e.
    # a_d = (T/I)(sin(phase) cos psi + cos(phase) sin psi); one lap is 4.1 turns, ~13 s here
    from hasel_wheel_sim.params import WheelParams
    torque, phase = 0.002, -1.0
    fx = dict(ENCODER, platform_disturbance={"enabled": True,
                                             "torque": {"value": torque, "unit": "N*m"},
                                             "phase": {"value": phase, "unit": "rad"}})
    *_, obs = run(fx, seconds=40.0)
    amp = torque / WheelParams().inertia                   # 0.056 rad/s^2
    c, a, b, e, f = obs.x[2:]
    assert e == pytest.approx(amp * math.sin(phase), abs=0.15 * amp)
    assert f == pytest.approx(amp * math.cos(phase), abs=0.15 * amp)
    assert math.hypot(a, b) < 0.3 * amp       # no once-per-turn part (c is not asserted: it
    # also carries the switching the observer sees only at samples, -0.02 to -0.05 rad/s^2 here)


def test_the_pivot_harmonic_as_a_constant_and_as_torques():
    from hasel_wheel_mpc.observer import disturbance_at, fold_pivot, set_disturbance
    from hasel_wheel_sim import layout as L
    from hasel_wheel_sim.model import external_torque, param_vector
    coef = (0.01, -0.02, 0.03, 0.04, -0.05)       # c, a, b, e, f [rad/s^2]
    ratio, xi1 = 0.25, 2.0                        # psi = 0.5 rad
    want = (0.01 - 0.02 * math.cos(2.0) + 0.03 * math.sin(2.0)
            + 0.04 * math.cos(0.5) - 0.05 * math.sin(0.5))
    assert disturbance_at(coef, xi1, ratio) == pytest.approx(want, rel=1e-12)
    folded = fold_pivot(coef, xi1, ratio)
    assert folded[1:] == coef[1:3]
    assert disturbance_at(folded, xi1) == pytest.approx(want, rel=1e-12)
    from hasel_wheel_sim.params import WheelParams
    base = param_vector(WheelParams())
    pv = set_disturbance(base.copy(), base, coef)
    torque = external_torque(xi1, 0.0, pv) * base[L.P_INV_INERTIA]
    assert torque == pytest.approx(disturbance_at(coef, xi1, base[L.P_PIVOT_RATIO]), rel=1e-12)
    # with a platform term of its own in the model, the pair adds to it
    from hasel_wheel_sim.model import Extensions
    own = param_vector(WheelParams(), Extensions(platform_torque=0.002, platform_phase=1.0))
    pv = set_disturbance(own.copy(), own, coef)
    psi = own[L.P_PIVOT_RATIO] * xi1
    want_torque = (0.002 * math.sin(psi + 1.0)
                   + disturbance_at(coef, xi1, own[L.P_PIVOT_RATIO]) / own[L.P_INV_INERTIA])
    assert external_torque(xi1, 0.0, pv) == pytest.approx(want_torque, rel=1e-12)
    assert set_disturbance(pv, own, coef[:3])[L.P_PLATFORM_TORQUE] == pytest.approx(0.002)
    with pytest.raises(ValueError, match=r"expected \(c, a, b\) or \(c, a, b, e, f\)"):
        set_disturbance(base.copy(), base, (0.0, 0.0))


def test_without_the_disturbance_state_the_coefficients_stay_zero():
    p = Plant(config=PlantConfig(seed=1, effects=effects_from_mapping(ENCODER)), xi2=1.0)
    p.open_loop(D(9), D(22))
    obs = Observer(config=ObserverConfig(default_phi_a=D(9), disturbance_rate=0.0,
                                         pivot_rate=0.0))
    for _ in range(600):
        s = p.step()
        if s is not None:
            e = obs.step(s)
    assert e.accel_coefficients == (0.0,) * 5


def test_without_the_pivot_harmonic_its_coefficients_stay_zero():
    p = Plant(config=PlantConfig(seed=1, effects=effects_from_mapping(ENCODER)), xi2=1.0)
    p.open_loop(D(9), D(22))
    obs = Observer(config=ObserverConfig(default_phi_a=D(9), pivot_rate=0.0))
    for _ in range(600):
        s = p.step()
        if s is not None:
            e = obs.step(s)
    assert e.accel_coefficients[3:] == (0.0, 0.0)
    assert e.accel_coefficients[0] != 0.0


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


def test_a_switch_on_seen_only_after_lost_samples_restarts_the_on_time():
    # every sample of one gap between two pads (q = 0) is lost: the next sample already
    # shows the next pad on, and the actuator's on-time (rise lag) must count from there
    p = Plant(config=PlantConfig(seed=1), xi2=2.0)
    p.open_loop(D(9), D(22))
    samples = [s for s in (p.step() for _ in range(600)) if s is not None]
    offs = [i for i in range(1, len(samples)) if samples[i].q == 0 and samples[i - 1].q == 1]
    a = offs[2]
    b = next(i for i in range(a, len(samples)) if samples[i].q == 1)
    assert samples[b].eta_unwrapped == samples[a - 1].eta_unwrapped + 1
    obs = Observer(config=ObserverConfig(default_phi_a=D(9)))
    for s in samples[:a] + samples[b:b + 1]:
        obs.step(s)
    assert obs.on_since == samples[b].t


def test_the_observer_and_the_mpc_work_on_readings_and_leave_the_eccentricity_out():
    # they see only readings, on which the firmware also switches: a model file's sensor
    # eccentricity must not move their switching angles off the readings
    from hasel_wheel_mpc.mpc import Mpc
    from hasel_wheel_sim import layout as L
    from hasel_wheel_sim.model import Extensions
    ext = Extensions(angle_eccentricity=0.02, angle_eccentricity_phase=0.4, viscous=1e-4)
    for pv in (Observer(extensions=ext).pv, Mpc(extensions=ext).pv):
        assert pv[L.P_READ_COS] == 0.0 and pv[L.P_READ_SIN] == 0.0
        assert pv[L.P_VISCOUS] == 1e-4                     # the rest of the model stays


def test_a_slow_wheel_teaches_the_disturbance_nothing():
    # a wheel coasting down from 0.45 rad/s past an off-centre mass: once the observer is sure
    # it is slower than learn_speed, a_d stays where it was; learning at every speed moves it
    effects = dict(ENCODER, com_offset={"enabled": True, "torque": {"value": 0.004, "unit": "N*m"},
                                        "phase": {"value": 0.5, "unit": "rad"}})

    def coefficients(learn_speed):
        p = Plant(config=PlantConfig(seed=1, effects=effects_from_mapping(effects)), xi2=0.45)
        obs = Observer(config=ObserverConfig(learn_speed=learn_speed))
        sure = []
        for _ in range(360):                     # to rest and beyond
            e = obs.step(p.step())
            if abs(e.xi2) + 3.0 * e.xi2_std < 0.5:
                sure.append(e.accel_coefficients)
        return sure

    held, learnt = coefficients(0.5), coefficients(1e-9)
    assert len(held) > 300 and len(set(held[3:])) == 1   # (the gate reads P before the update)
    assert len({c for c in learnt}) > 300
