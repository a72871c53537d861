"""Event-exact integration: jump instants against analytic crossings, RK4's order, tick
switching, stops, batch = single wheel, and bit-identical reruns."""
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from hasel_wheel_sim import layout as L
from hasel_wheel_sim.integrator import rk4, simulate_batch, simulate_batch_parallel
from hasel_wheel_sim.model import SECTOR, acceleration, jump_map, param_vector
from hasel_wheel_sim.params import WheelParams
from hasel_wheel_sim.wheel import TICK, HybridWheel, initial_state, set_open_loop

D = math.radians


def coast_time(theta, w0, a):
    """Time at which xi1 = w0 t - a t^2 / 2 reaches theta (constant deceleration a)."""
    return (w0 - math.sqrt(w0 * w0 - 2.0 * a * theta)) / a


def test_jump_instants_equal_analytic_crossings(params, run):
    # phi_d = 5 deg: the force law is < 1e-80 N there, so the wheel coasts under friction
    # alone and every switching angle k*pi/8 + phi is crossed at a closed-form instant.
    wheel = HybridWheel(params, xi2=5.0)
    wheel.open_loop(D(1), D(5))
    a = params.friction_torque / params.inertia
    t, v, ev = run(wheel, 14.5)
    sw = ev[(ev[:, 2] == L.EV_ON) | (ev[:, 2] == L.EV_OFF)]
    assert len(sw) > 150                                  # ~88 pads, several 15 -> 0 wraps
    assert int(sw[:, 3].max()) >= 80
    for time, xi1, kind, eta in sw:
        theta = eta * SECTOR + (D(1) if kind == L.EV_ON else D(5))
        assert abs(xi1 - theta) < 1e-9                     # jumps at the crossing angle
        assert time == pytest.approx(coast_time(theta, 5.0, a), abs=1e-9)
    # and the wheel stops exactly at t = w0 / a, xi1 = w0^2 / (2 a), and stays stopped
    stop = ev[ev[:, 2] == L.EV_STOP]
    assert len(stop) == 1
    assert stop[0, 0] == pytest.approx(5.0 / a, abs=1e-9)
    assert stop[0, 1] == pytest.approx(25.0 / (2 * a), abs=1e-9)
    assert np.all(v[t > stop[0, 0] + TICK] == 0.0)


def test_forced_switch_off_matches_a_tight_reference(params):
    # with the force on, compare the switch-off instant with DOP853 at rtol 1e-13
    pv = param_vector(params)
    wheel = HybridWheel(params, xi2=3.0)
    wheel.command(0, D(3), D(22))
    events = []
    while not any(e[2] == L.EV_OFF for e in events):
        events.extend(wheel.advance())
    on = next(e for e in events if e[2] == L.EV_ON)
    off = next(e for e in events if e[2] == L.EV_OFF)
    a = params.friction_torque / params.inertia
    t_on = coast_time(D(3), 3.0, a)
    assert on[0] == pytest.approx(t_on, abs=1e-12) and abs(on[1] - D(3)) < 1e-9

    def f(_t, y):
        return [y[1], acceleration(y[0], y[1], 1.0, 0.0, D(3), 1.0, 0.0, pv)]

    def reach(_t, y):
        return y[0] - D(22)
    reach.terminal = True
    sol = solve_ivp(f, (t_on, t_on + 1.0), [D(3), 3.0 - a * t_on], method="DOP853",
                    rtol=1e-13, atol=1e-14, events=reach)
    assert abs(off[1] - D(22)) < 1e-9
    # RK4 at h = 1/300 s: O(h^4) global error, a few 1e-9 s on this flow
    assert off[0] == pytest.approx(sol.t_events[0][0], abs=1e-7)


def test_rk4_is_fourth_order(params):
    # a flow inside the force bump (q = 1, xi_c from 17 deg): error ratio h -> h/2 ~ 2^4
    pv = param_vector(params)
    s = initial_state()
    s[L.S_Q] = 1.0
    s[L.S_PHI_A] = D(3)

    def integrate(h, n):
        x, v = D(17), 3.0
        for _ in range(n):
            x, v = rk4(x, v, h, s, 1.0, pv)
        return x, v
    T = 0.06
    ref = integrate(T / 1536, 1536)
    e1 = abs(integrate(T / 18, 18)[1] - ref[1])
    e2 = abs(integrate(T / 36, 36)[1] - ref[1])
    assert 12.0 < e1 / e2 < 20.0


def test_every_integrator_jump_is_the_jump_map(params):
    # 60 s open loop: every switch-on and switch-off the integrator applies equals (52) with
    # the unwrapped target, including every 15 -> 0 wrap (15 -> 16, 31 -> 32, ...)
    from hasel_wheel_sim.model import unwrap_target
    wheel = HybridWheel(params, xi2=1.0)
    wheel.open_loop(D(3), D(22))
    ons = offs = wraps = 0
    for _ in range(int(60 / TICK)):
        pre_eta = wheel.s[L.S_ETA]
        ev = wheel.advance()
        if len(ev) != 1:                      # compare single-event ticks (post-tick state known)
            continue
        t_ev, xi1_ev, kind, eta_ev = ev[0]
        st = wheel.state
        moved = st.xi1 - xi1_ev                # flow after the jump within the tick
        if kind == L.EV_OFF:
            n_a = (int(eta_ev) + 1) % 16
            n = unwrap_target(float(n_a), D(3), xi1_ev)
            x = jump_map(xi1_ev, 0.0, 1, eta_ev, n, D(3), D(22))
            assert eta_ev == pre_eta and st.eta == x[5] == n
            wraps += int(eta_ev) % 16 == 15
            offs += 1
        elif kind == L.EV_ON:
            x = jump_map(xi1_ev, 0.0, 0, eta_ev, eta_ev, D(3), D(22))
            assert st.eta == x[5] == eta_ev
            ons += 1
        else:
            continue
        assert st.q == x[2]
        assert st.act_counter + (0.0 if st.q else moved) == pytest.approx(x[3], abs=1e-12)
        assert st.deact_counter + moved == pytest.approx(x[4], abs=1e-12)
    assert ons > 300 and offs > 300 and wraps >= 20


def test_tick_switching_happens_on_the_first_tick_after_the_angle(params):
    wheel = HybridWheel(params, mode="tick", xi2=3.0)
    wheel.open_loop(D(3), D(22))
    prev_xi1 = wheel.s[L.S_XI1]
    checked = 0
    for _ in range(3000):
        theta_on, theta_off, q = wheel.s[L.S_THETA_ON], wheel.s[L.S_THETA_OFF], wheel.s[L.S_Q]
        ev = wheel.advance()
        for time, xi1, kind, _eta in ev:
            if kind in (L.EV_ON, L.EV_OFF):
                theta = theta_on if kind == L.EV_ON else theta_off
                assert round(time / TICK) * TICK == pytest.approx(time, abs=1e-12)  # on a tick
                assert prev_xi1 < theta <= xi1                                     # first one after
                checked += 1
        prev_xi1 = wheel.s[L.S_XI1]
    assert checked > 50


def test_batch_equals_single_wheels_bit_for_bit(params):
    cases = [(D(1), 1.0), (D(5), 2.0), (D(9), 0.5)]
    n = 900
    states = np.stack([initial_state(0.0, w0) for _, w0 in cases])
    for s, (pa, _) in zip(states, cases):
        set_open_loop(s, pa, D(22))
    pvs = np.stack([param_vector(params.with_values(sigma6=20.0 + i)) for i in range(3)])
    out = np.zeros((3, n, 3))
    out_par = np.zeros((3, n, 3))
    states_par = states.copy()
    simulate_batch(states, pvs, TICK, n, out)
    simulate_batch_parallel(states_par, pvs, TICK, n, out_par)
    assert np.array_equal(out, out_par) and np.array_equal(states, states_par)
    for i, (pa, w0) in enumerate(cases):
        w = HybridWheel(params.with_values(sigma6=20.0 + i), xi2=w0)
        w.open_loop(pa, D(22))
        for k in range(n):
            w.advance()
            assert out[i, k, 0] == w.s[L.S_XI1] and out[i, k, 1] == w.s[L.S_XI2]


def test_same_inputs_same_trajectory_bitwise(params, run):
    def once():
        w = HybridWheel(params, xi2=1.0)
        w.open_loop(D(5), D(22), priming=6)
        return run(w, 10.0)
    (t1, v1, e1), (t2, v2, e2) = once(), once()
    assert np.array_equal(v1, v2) and np.array_equal(e1, e2)


def test_idle_wheel_coasts_and_arms_when_a_command_arrives(params):
    w = HybridWheel(params, xi2=2.0)
    assert w.state.act_counter == math.inf            # no target: HV stays off
    for _ in range(30):
        assert w.advance().shape[0] == 0 and w.state.q == 0
    w.command(3, D(3), D(22), seq=7)
    ev = w.advance()
    assert ev[0, 2] == L.EV_ARM and ev[0, 3] == 3     # first future switch-on of pad 3
    assert w.s[L.S_CMD_SEQ] == 7


def test_a_command_replaces_a_target_that_has_not_switched_on(params):
    # a target one revolution ahead that a slow wheel will never reach must not block
    w = HybridWheel(params, xi1=D(30), xi2=0.5)          # past pad 1's switch-on at 25.5 deg
    w.command(1, D(3), D(22), seq=1)
    ev = w.advance()
    assert ev[0, 2] == L.EV_ARM and ev[0, 3] == 17        # first future switch-on: next turn
    w.command(2, D(3), D(22), seq=2)                      # q = 0: takes effect now
    ev = w.advance()
    assert ev[0, 2] == L.EV_ARM and ev[0, 3] == 2 and w.s[L.S_CMD_SEQ] == 2
    # while an actuator is on, a new command still waits for its switch-off
    w2 = HybridWheel(params, xi1=2 * SECTOR + D(1), xi2=2.0)
    w2.command(2, D(3), D(22), seq=1)
    for _ in range(20):
        w2.advance()
        if w2.s[L.S_Q] == 1.0:
            break
    assert w2.s[L.S_Q] == 1.0
    w2.command(3, D(3), D(22), seq=2)
    w2.advance()
    assert w2.s[L.S_CMD_SEQ] == 1 and w2.s[L.S_Q] == 1.0
