"""Each real-wheel effect moves the trajectory the way its documentation says: closed forms
where they exist (viscous coast-down, energy balance of position torques), directions and
statistics otherwise."""
import math

import numpy as np
import pytest

from hasel_wheel_common.samples import Command
from hasel_wheel_sim import layout as L
from hasel_wheel_sim.effects import REALISTIC, effects_from_mapping
from hasel_wheel_sim.model import Extensions
from hasel_wheel_sim.params import ParameterError
from hasel_wheel_sim.plant import COUNT, Plant, PlantConfig, run_configs
from hasel_wheel_sim.trials_support import open_loop_speed
from hasel_wheel_sim.wheel import TICK, HybridWheel

D = math.radians


def coast(params, ext, w0, seconds, xi1=0.0):
    """Idle wheel (no commands, HV off): angle and speed after every tick."""
    w = HybridWheel(params, ext, xi1=xi1, xi2=w0)
    n = int(round(seconds / TICK))
    x, v = np.empty(n), np.empty(n)
    for k in range(n):
        w.advance()
        x[k], v[k] = w.s[L.S_XI1], w.s[L.S_XI2]
    return (np.arange(n) + 1) * TICK, x, v


def test_viscous_drag_follows_the_closed_form_coast_down(params):
    b, J, Tf = 0.002, params.inertia, params.friction_torque
    t, _, v = coast(params, Extensions(viscous=b), 3.0, 3.0)
    expected = (3.0 + Tf / b) * np.exp(-b * t / J) - Tf / b
    assert np.max(np.abs(v - expected)) < 1e-9
    _, _, v0 = coast(params, Extensions(), 3.0, 3.0)
    assert np.all(v < v0)                               # drag: faster coast-down


@pytest.mark.parametrize("ext, work", [
    (Extensions(com_torque=0.004, com_phase=0.5),
     lambda a, b: 0.004 * (math.cos(b + 0.5) - math.cos(a + 0.5))),
    (Extensions(platform_torque=0.003, platform_phase=-1.0),
     lambda a, b: -(0.003 / (0.157 / 0.642)) * (math.cos(0.157 / 0.642 * b - 1.0)
                                                 - math.cos(0.157 / 0.642 * a - 1.0))),
])
def test_position_torques_obey_the_energy_balance(params, ext, work):
    # (J/L)/2 (w^2 - w0^2) = -T_f (x - x0) + integral of the torque over the angle
    J, Tf = params.inertia, params.friction_torque
    _, x, v = coast(params, ext, 4.0, 8.0)
    moving = v > 0
    lhs = 0.5 * J * (v[moving] ** 2 - 16.0)
    rhs = np.array([-Tf * xb + work(0.0, xb) for xb in x[moving]])
    assert np.max(np.abs(lhs - rhs)) < 1e-10


def test_com_offset_rolls_a_wheel_at_rest_towards_its_low_point(params):
    # COM torque above friction, offset at +90 deg: torque -A sin(pi/2) < 0 -> rolls backwards
    ext = Extensions(com_torque=3 * params.friction_torque, com_phase=math.pi / 2)
    _, x, v = coast(params, ext, 0.0, 0.3)
    assert v[-1] < 0.0 and x[-1] < 0.0
    weak = Extensions(com_torque=0.5 * params.friction_torque, com_phase=math.pi / 2)
    _, x, v = coast(params, weak, 0.0, 0.3)
    assert np.all(v == 0.0) and np.all(x == 0.0)      # held by static friction


def test_charge_retention_slows_the_wheel_more_and_more(params):
    base = open_loop_speed(params, Extensions(), D(3), 60.0)
    ret = open_loop_speed(params, Extensions(retention_rate=0.02, retention_recovery=300.0),
                          D(3), 60.0)
    t = np.arange(1, base.size + 1) * TICK
    early = (t > 20) & (t < 30)
    late = t > 50
    gap_early = np.mean(base[early] - ret[early])
    gap_late = np.mean(base[late] - ret[late])
    assert gap_early > 0 and gap_late > 1.5 * gap_early


def test_charge_retention_state_follows_its_ode(params):
    # one actuator held on (long activation window) then off: Q = tau (1 - e^-t/tau), then decays
    tau = 2.0
    w = HybridWheel(params, Extensions(retention_rate=0.01, retention_recovery=tau), xi2=0.2)
    w.command(0, D(0.1), D(22.4))
    on_time = None
    for _ in range(3000):
        ev = w.advance()
        if on_time is None and any(e[2] == L.EV_ON for e in ev):
            on_time = next(e[0] for e in ev if e[2] == L.EV_ON)
        if any(e[2] == L.EV_OFF for e in ev) or w.s[L.S_XI2] == 0.0:
            break
    held = w.s[L.S_ACT_TIME]
    assert held > 0.2
    # Q_0 after `held` seconds on (the rest of the tick after switch-off decays it slightly)
    q0 = w.s[L.S_RET + 0]
    assert q0 == pytest.approx(tau * (1 - math.exp(-held / tau)), rel=2e-2)


@pytest.mark.parametrize("ext", [Extensions(gains=(0.8,) * 16), Extensions(rise_time=0.02)])
def test_weaker_or_slower_actuators_lower_the_steady_speed(params, ext):
    base = open_loop_speed(params, Extensions(), D(5), 40.0)
    slow = open_loop_speed(params, ext, D(5), 40.0)
    assert np.mean(slow[-3000:]) < np.mean(base[-3000:]) - 0.05


def test_gain_spread_draws_from_the_seed_and_makes_a_16_pad_ripple(params):
    fx = effects_from_mapping({"gain_spread": REALISTIC["gain_spread"]})
    g1 = fx.extensions(np.random.default_rng(3)).gains
    g2 = fx.extensions(np.random.default_rng(3)).gains
    assert g1 == g2 and np.std(g1) > 0.02
    speed, eta = open_loop_speed(params, Extensions(gains=g1), D(5), 40.0, return_state=True)
    # speed gained during each actuator's cycle, averaged per pad, over the last 20 s
    starts = np.nonzero(np.diff(eta))[0] + 1
    gain_by_pad = [[] for _ in range(16)]
    for a, b in zip(starts[:-1], starts[1:]):
        if a > speed.size // 2:
            gain_by_pad[eta[a] % 16].append(speed[b - 1] - speed[a])
    dv = np.array([np.mean(x) for x in gain_by_pad])
    assert np.corrcoef(dv, g1)[0, 1] > 0.9          # stronger pads push harder


def test_runs_of_one_wheel_share_its_gains_and_draw_their_own_noise():
    """Runs of one wheel hold the gains drawn from the first seed; separate wheels draw their
    own.  Either way run i's plant has seed + i, so its encoder noise is its own."""
    cfg = PlantConfig(seed=7, effects=effects_from_mapping(
        {"gain_spread": REALISTIC["gain_spread"], "encoder": REALISTIC["encoder"]}))
    drawn = cfg.effects.extensions(np.random.default_rng(7)).gains
    one = run_configs(cfg, 3, same_wheel=True)
    assert [c.seed for c in one] == [7, 8, 9]
    assert all(Plant(config=c).extensions.gains == drawn for c in one)
    apart = run_configs(cfg, 3, same_wheel=False)
    assert [c.seed for c in apart] == [7, 8, 9]
    assert Plant(config=apart[0]).extensions.gains == drawn
    assert len({Plant(config=c).extensions.gains for c in apart}) == 3
    plants = [Plant(config=c, xi2=2.0) for c in one]
    readings = {tuple(p.step().angle for _ in range(300)) for p in plants}
    assert len(readings) == 3                       # same wheel, same start, its own noise
    for bad in (0, 2.5, True):
        with pytest.raises(ParameterError, match=f"runs = {bad!r}"):
            run_configs(cfg, bad, same_wheel=True)


def _plant(effects, seed=1):
    return Plant(config=PlantConfig(seed=seed, effects=effects_from_mapping(effects)), xi2=2.0)


def test_encoder_quantises_to_10_bits():
    p = _plant({"encoder": {"enabled": True, "noise_std": {"value": 0.0, "unit": "rad"}}})
    for _ in range(600):
        s = p.step()
        xi1 = p.wheel.s[L.S_XI1]
        assert 0.0 <= xi1 - s.angle < COUNT
        assert s.angle / COUNT == pytest.approx(round(s.angle / COUNT), abs=1e-9)
        assert 0 <= s.encoder_raw < 1024 and s.encoder_raw == round(s.angle / COUNT) % 1024


def test_encoder_noise_has_its_standard_deviation():
    p = _plant({"encoder": {"enabled": True, "noise_std": {"value": 0.01, "unit": "rad"}}})
    err = []
    for _ in range(6000):
        s = p.step()
        err.append(s.angle - p.wheel.s[L.S_XI1])
    # quantisation (floor) adds a uniform [-COUNT, 0) part: mean -COUNT/2, var COUNT^2/12
    assert np.mean(err) == pytest.approx(-COUNT / 2, abs=4 * 0.01 / math.sqrt(6000))
    assert np.std(err) == pytest.approx(math.sqrt(0.01**2 + COUNT**2 / 12), rel=0.05)


ECCENTRIC = {"angle_eccentricity": {"enabled": True, "amplitude": {"value": 0.03, "unit": "rad"},
                                   "phase": {"value": 0.7, "unit": "rad"}}}


def test_eccentric_sensor_reads_its_first_harmonic_error():
    p = _plant(ECCENTRIC)
    err, xs = [], []
    for _ in range(900):                        # ~1 turn at 2 rad/s
        s = p.step()
        xs.append(p.wheel.s[L.S_XI1])
        err.append(s.angle - xs[-1])
    np.testing.assert_allclose(err, 0.03 * np.sin(np.asarray(xs) + 0.7), atol=1e-12)


@pytest.mark.parametrize("switching", ["exact", "tick"])
def test_firmware_switches_where_its_reading_reaches_the_switching_angle(params, switching):
    """The firmware sees only the reading m = xi1 + e sin(xi1 + phase): each switch-on is
    where m reaches N pi/8 + phi_a (exactly, or on the first tick after), not where xi1 does."""
    cfg = PlantConfig(switching=switching, effects=effects_from_mapping(ECCENTRIC))
    p = Plant(params, cfg, xi2=2.0)
    p.open_loop(D(5), D(20))
    ons, top = [], 0.0
    for _ in range(1500):
        p.step()
        top = max(top, p.wheel.s[L.S_XI2])
        ons += [(x, eta) for _, x, kind, eta in p.last_events if kind == L.EV_ON]
    assert len(ons) > 16                       # more than a turn
    reading = np.array([x + 0.03 * math.sin(x + 0.7) for x, _ in ons])
    target = np.array([eta * math.pi / 8 + D(5) for _, eta in ons])
    true_at_target = np.array([x - (m - t) / (1 + 0.03 * math.cos(x + 0.7))
                               for (x, _), m, t in zip(ons, reading, target)])
    if switching == "exact":
        np.testing.assert_allclose(reading, target, atol=1e-9)
    else:                                       # late by at most one tick of travel
        assert np.all(reading >= target - 1e-12)
        assert np.all(reading - target <= top * TICK * 1.04)   # (reading slope <= 1.03)
    # the error is not negligible: where xi1 itself reaches the angle is up to 30 mrad away
    assert np.max(np.abs(true_at_target - target)) > 0.02


def test_at_its_switch_on_an_eccentric_wheel_moves_as_an_exact_one_commanded_at_the_true_angle(
        params):
    # the firmware switches on the reading; the pad's force grows with the true travel from
    # where it switched on, so the force law's rise term must start at 0 there
    from hasel_wheel_sim.integrator import rk4
    from hasel_wheel_sim.model import SECTOR, angle_at_reading, param_vector
    from hasel_wheel_sim.wheel import initial_state
    pv_e = param_vector(params, Extensions(angle_eccentricity=0.03, angle_eccentricity_phase=0.7))
    pv_0 = param_vector(params)
    n, phi_a = 3, D(5)
    theta = angle_at_reading(n * SECTOR + phi_a, pv_e)
    assert abs(theta - (n * SECTOR + phi_a)) > 0.02            # the reading is 28 mrad off here
    s = initial_state(theta, 2.0)
    s[L.S_Q], s[L.S_ETA], s[L.S_PHI_A] = 1.0, n, phi_a
    s0 = s.copy()
    s0[L.S_PHI_A] = theta - n * SECTOR
    for h in (1e-4, TICK):
        np.testing.assert_allclose(rk4(theta, 2.0, h, s, 1.0, pv_e),
                                   rk4(theta, 2.0, h, s0, 1.0, pv_0), rtol=0, atol=1e-13)


def test_angle_reading_inverse_and_range():
    from hasel_wheel_sim.model import angle_at_reading, angle_reading, param_vector
    from hasel_wheel_sim.params import ParameterError, WheelParams
    pv = param_vector(WheelParams(), Extensions(angle_eccentricity=0.2, angle_eccentricity_phase=-2.0))
    for m in np.linspace(-7.0, 30.0, 97):
        assert angle_reading(angle_at_reading(m, pv), pv) == pytest.approx(m, abs=1e-13)
    with pytest.raises(ParameterError, match="angle_eccentricity.*0.3"):
        Extensions(angle_eccentricity=0.3)
    with pytest.raises(ParameterError, match="amplitude"):
        effects_from_mapping({"angle_eccentricity": {"enabled": True,
                                                     "amplitude": {"value": 0.5, "unit": "rad"},
                                                     "phase": {"value": 0.0, "unit": "rad"}}})


@pytest.mark.parametrize("effect", ["dropouts", "encoder_glitches"])
def test_sample_faults_happen_at_their_rate(effect):
    p = _plant({effect: {"enabled": True, "probability": {"value": 0.05, "unit": "1"}}})
    n, hits, seqs = 6000, 0, []
    for _ in range(n):
        s = p.step()
        if s is None:
            hits += 1
            continue
        seqs.append(s.sequence)
        if abs(s.angle - p.wheel.s[L.S_XI1]) > 2 * COUNT:
            hits += 1
    sd = math.sqrt(n * 0.05 * 0.95)
    # a glitch may by chance land within 2 counts of the truth (2/1024 of them)
    assert abs(hits - 0.05 * n) < 4 * sd
    if effect == "dropouts":
        assert seqs[-1] == n and len(seqs) == n - hits          # gaps show in the sequence


def test_serial_latency_delays_commands_and_samples():
    fx = {"serial_latency": {"enabled": True, "command": {"value": 0.02, "unit": "s"},
                             "telemetry": {"value": 0.01, "unit": "s"}}}
    p = _plant(fx)
    out = [p.step(Command(1, D(3), D(22), 5) if k == 0 else None) for k in range(12)]
    assert out[0] is None and out[1] is None and out[2] is None   # 10 ms = 3 ticks in flight
    assert out[3].sequence == 1
    p2 = _plant(fx)
    armed_at = None
    for k in range(20):
        p2.step(Command(1, D(3), D(22), 5) if k == 0 else None)
        if armed_at is None and p2.wheel.s[L.S_ARMED]:
            armed_at = p2.t
    assert armed_at == pytest.approx(0.02 + TICK, abs=1e-9)     # latched on the tick after 20 ms


def test_realistic_plant_is_bit_identical_for_a_seed_and_differs_across_seeds():
    def run(seed):
        p = Plant(config=PlantConfig(seed=seed, switching="tick",
                                     effects=effects_from_mapping(REALISTIC)), xi2=1.0)
        p.open_loop(D(5), D(22), priming=6)
        return [(s.angle, s.sequence) if s else None for s in (p.step() for _ in range(3000))]
    assert run(7) == run(7)
    assert run(7) != run(8)


def event_plant(w0=2.0, **events) -> Plant:
    """The exact plant (no noise) with only the given event effects, rolling at ``w0``."""
    return Plant(config=PlantConfig(effects=effects_from_mapping(events)), xi2=w0)


def test_a_pad_dies_at_its_time():
    p = event_plant(pad_death={"enabled": True, "pad": {"value": 5, "unit": "1"},
                               "time": {"value": 0.5, "unit": "s"},
                               "gain": {"value": 0.1, "unit": "1"}})
    while p.t < 0.5 - 1e-9:
        p.step()
        assert p.wheel.pv[L.P_GAINS + 5] == 1.0
    p.step()
    assert p.wheel.pv[L.P_GAINS + 5] == pytest.approx(0.1)
    assert np.all(np.delete(p.wheel.pv[L.P_GAINS:L.P_GAINS + 16], 5) == 1.0)


def test_an_obstacle_stops_the_wheel_for_its_duration(params):
    # 0.2 N*m more friction than T_f: the wheel stops within w0 J / (T_f + 0.2) and stays
    # (it holds the wheel up to that torque), then the extra friction is gone
    torque, start, duration = 0.2, 0.5, 1.0
    p = event_plant(obstacle={"enabled": True, "time": {"value": start, "unit": "s"},
                              "duration": {"value": duration, "unit": "s"},
                              "torque": {"value": torque, "unit": "N*m"}})
    stop = start + 2.0 * params.inertia / (params.friction_torque + torque)
    while p.t < start + duration - 1e-9:
        p.step()
        if p.t > stop + TICK:
            assert p.wheel.s[L.S_XI2] == 0.0
    p.step()
    assert p.wheel.pv[L.P_FRICTION] == pytest.approx(params.friction_torque, rel=1e-15)


def test_a_pad_index_that_is_not_whole_is_refused():
    with pytest.raises(ParameterError, match="pad_death.pad = 2.5"):
        event_plant(pad_death={"enabled": True, "pad": {"value": 2.5, "unit": "1"},
                               "time": {"value": 1.0, "unit": "s"}, "gain": {"value": 0.0, "unit": "1"}})


def test_a_pad_on_for_the_maximum_on_time_is_switched_off():
    # protocol rule 5 on the plant: a standing wheel's pad goes off after 2 s, fault bit 8
    p = Plant(xi1=5 * math.pi / 8 + D(10))
    assert p.wheel.start_now(5, 0.0, math.pi / 8) == 0
    faults = 0
    for _ in range(round(2.0 / TICK) + 1):
        s = p.step()
        faults |= s.fault_flags
    assert p.wheel.s[L.S_Q] == 0.0 and faults & 8
    assert p.wheel.s[L.S_XI1] == 5 * math.pi / 8 + D(10)          # the paper's wheel: no push


def test_a_refused_start_sets_the_rejected_command_fault_bit():
    p = Plant(xi1=5 * math.pi / 8 + D(10))
    s = p.step(Command(6, 0.0, math.pi / 8, 3, now=True))        # pad 5 is in contact
    assert s.fault_flags & 32 and p.starts_refused == 1 and p.wheel.s[L.S_Q] == 0.0
    assert p.step().fault_flags == 0
