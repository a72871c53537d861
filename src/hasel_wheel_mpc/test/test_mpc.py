"""MPC core: the cost (59) on a hand-checkable case, braking selection, the fallback when no
candidate completes its cycle, and a short closed loop on the nominal plant."""
import dataclasses
import gc
import math

import numpy as np
import pytest

from hasel_wheel_mpc.mpc import (Mpc, MpcConfig, braking_command, cost_59, earliest_phi_a,
                                  next_pad)
from hasel_wheel_sim import layout as L
from hasel_wheel_sim.model import SECTOR
from hasel_wheel_sim.wheel import HybridWheel

D = math.radians
TICK_S = 1.0 / 300.0


def test_cost_59_by_hand():
    # current actuator on for 2 ticks, off for 3 (segment 0), candidate on for 3 (segment 1)
    q = np.array([1, 1, 0, 0, 0, 1, 1, 1, 0, 0], dtype=float)
    v = np.array([9, 9, 1.0, 2.0, 3.0, 2.5, 2.0, 1.5, 9, 9])
    ref = 2.0
    seg0 = ((1 - 2) ** 2 + 0 + (3 - 2) ** 2) / 3          # = 2/3
    seg1 = ((2.5 - 2) ** 2 + 0 + (1.5 - 2) ** 2) / 3      # = 1/6
    assert cost_59(v, q, ref) == pytest.approx(0.5 * (seg0 + seg1))
    assert cost_59(v, q, ref, terminal_weight=2.0) == pytest.approx(    # last q = 1 sample
        0.5 * (seg0 + seg1) + 2.0 * (1.5 - 2.0) ** 2)
    assert cost_59(v, q, ref, d=0.5) == pytest.approx(                  # d shifts the speed
        0.5 * (((1.5 - 2) ** 2 + 0.25 + 2.25) / 3 + (1 + 0.25 + 0) / 3))
    everything = (1 + 0 + 1 + 0.25 + 0 + 0.25) / 6                       # all six samples
    assert cost_59(v, q, ref, time_weighted=True) == pytest.approx(everything)
    assert cost_59(v[:6], q[:6], ref) == math.inf         # horizon too short: no full cycle


def test_cost_over_two_cycles_by_hand():
    # current actuator on for 2 ticks; candidate: off 2, on 2; the pad after: off 3, on 2
    q = np.array([1, 1, 0, 0, 1, 1, 0, 0, 0, 1, 1, 0], dtype=float)
    v = np.array([9, 9, 1.0, 3.0, 2.0, 2.0, 2.5, 2.0, 1.5, 1.0, 3.0, 9])
    ref = 2.0
    seg = [(1 + 1) / 2, 0.0, (0.25 + 0 + 0.25) / 3, (1 + 1) / 2]     # the four segment means
    assert cost_59(v, q, ref, pads=2) == pytest.approx(np.mean(seg))     # = 7/12
    assert cost_59(v, q, ref, pads=2, time_weighted=True) == pytest.approx(
        (1 + 1 + 0 + 0 + 0.25 + 0 + 0.25 + 1 + 1) / 9)
    # the terminal term is the last sample of the horizon (3.0), not of the first cycle (2.0)
    assert cost_59(v, q, ref, pads=2, terminal_weight=1.0) == pytest.approx(np.mean(seg) + 1.0)
    assert cost_59(v, q, ref, terminal_weight=1.0) == pytest.approx(0.5 * (1 + 0) + 0.0)
    assert cost_59(v[:11], q[:11], ref, pads=2) == math.inf   # the 2nd cycle has not ended


def test_braking_when_the_speed_is_above_the_reference_by_the_threshold():
    mpc = Mpc(config=MpcConfig(brake_threshold=0.3, brake_phi_a=D(-22)))
    xi1 = 20 * SECTOR + D(3)                               # pad 4 (2nd revolution) just on
    dec = mpc.decide(xi1, 2.6, 20, D(3), D(22), reference=2.0)
    assert dec.braking and dec.candidates == 0
    assert (dec.command.n_a, dec.command.phi_a, dec.command.phi_d) == (6, D(-22), D(-6))
    dec = mpc.decide(xi1, 2.25, 20, D(3), D(22), reference=2.0)   # 0.25 above: keep driving
    assert not dec.braking and dec.command.n_a == 5 and dec.command.phi_a >= 0


def test_braking_pad_switches_on_no_earlier_than_it_still_can():
    # pad 20 on, off at 22 deg: pad 21 is then at -0.5 deg (no braking window left), pad 22
    # at 22 - 45 = -23 deg; the firmware may switch off up to a tick late, so 2 ticks of
    # rotation are kept in hand: -23 deg + 2/300 s x 2.6 rad/s
    mpc = Mpc(config=MpcConfig(brake_phi_a=D(-22.4)))
    xi1 = 20 * SECTOR + D(3)
    dec = mpc.decide(xi1, 2.6, 20, D(3), D(22), reference=2.0)
    assert dec.command.n_a == 6
    # 2 ticks at 2.6 rad/s: 0.01733 rad = 0.993 deg, so -23 + 0.993 = -22.007 deg
    assert dec.command.phi_a == pytest.approx(D(-22.007), abs=D(0.001))
    # pad 22 braking (on at -22.4 deg), off at -6 deg: pad 23 is at -28.5 deg there, so
    # -22.4 deg is allowed as it is
    xi1 = 22 * SECTOR - D(22.4)
    dec = mpc.decide(xi1, 2.4, 22, D(-22.4), D(-6), reference=2.0)
    assert (dec.command.n_a, dec.command.phi_a) == (7, D(-22.4))
    # between pads (none on) at 22.2 deg into sector 21: the command latches on arrival, a
    # tick and the command's way (4 ms) later, 1.09 deg on, so 0.79 deg into sector 22; pad 23
    # is at -21.71 deg there, soon enough (before the middle of [-22.4, -6] deg)
    xi1 = 21 * SECTOR + D(22.2)
    dec = mpc.brake_now(xi1, 2.6, 0.0, act_counter=D(5))
    arrival = xi1 + 2.6 * (TICK_S + mpc.config.deadline_margin)
    assert dec.braking and dec.command.n_a == 7
    # arrival: 2.6 rad/s x (3.33 + 4) ms = 0.01907 rad = 1.093 deg; 22.2 + 1.093 - 45 + 0.993
    assert arrival == pytest.approx(22 * SECTOR + D(0.793), abs=D(0.001))
    assert dec.command.phi_a == pytest.approx(D(-20.714), abs=D(0.001))
    assert dec.deadline_slack == pytest.approx(D(5) / 2.6 - mpc.config.deadline_margin
                                               - dec.compute_time)
    # an idle wheel whose telemetry names a pending target less than a sector ahead: no pad
    # is on, so the command latches on arrival too (not at that target's switch-off)
    dec = mpc.decide(xi1, 2.6, 22, D(10), D(22), reference=2.0, pad_on=False)
    assert dec.command.n_a == 7 and dec.command.phi_a < D(-20.5)


@pytest.mark.parametrize("speed", [0.5, 2.6, 8.0, 20.0, 40.0])
@pytest.mark.parametrize("phi_a, phi_d", [(D(-22.4), D(-6)), (D(-22), D(-20)), (D(-3), D(-1))])
def test_braking_command_is_valid_and_still_ahead_at_any_latch_angle(speed, phi_a, phi_d):
    # over a whole sector of latch angles: phi_a within [brake_phi_a, phi_d), and the pad's
    # switch-on at least the 2 ticks' margin ahead of the latch (never one that has passed)
    for latch in np.linspace(5 * SECTOR, 6 * SECTOR, 181):
        pad, pa = braking_command(latch, speed, phi_a, phi_d)
        assert phi_a <= pa < phi_d
        assert pad * SECTOR + pa >= latch + 2 * TICK_S * speed - 1e-12
        assert earliest_phi_a(pad, speed, latch) <= 0.5 * (phi_a + phi_d)


def test_next_pad_is_the_first_whose_switch_on_is_still_ahead():
    # at 10 deg into sector 3 with a command arriving 0.05 rad (2.86 deg) later
    xi1, v, lead = 3 * SECTOR + D(10), 1.0, 0.05
    assert next_pad(xi1, v, D(15), lead) == 3            # 15 deg of pad 3 is still ahead
    assert next_pad(xi1, v, D(12), lead) == 4            # passed by the time it arrives
    assert next_pad(xi1, v, D(5), lead) == 4
    assert next_pad(xi1, v, D(-22), lead) == 5           # braking: two pads ahead
    assert next_pad(15 * SECTOR + D(20), 0.0, D(3), 0.0) == 0     # wraps from 15 to 0


def test_no_complete_cycle_falls_back_to_the_strongest_push():
    mpc = Mpc(config=MpcConfig(max_horizon=0.05, phi_d=(D(20), D(22))))
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
    (ref, ss, nrmse, _, settle), = segment_metrics(log, profile, 30.0)
    assert ss < 0.5 and nrmse < 0.03 and settle < 10.0


def _state_after_switch_on(mpc, w, eta=5, pa=D(8), pd=D(22)):
    from hasel_wheel_sim import layout as L
    s = mpc._base.copy()
    s[L.S_XI1], s[L.S_XI2], s[L.S_Q], s[L.S_ETA], s[L.S_ARMED] = eta * SECTOR + pa, w, 1, eta, 1
    s[L.S_PHI_A], s[L.S_PHI_D] = pa, pd
    s[L.S_THETA_ON], s[L.S_THETA_OFF] = eta * SECTOR + pa, eta * SECTOR + pd
    s[L.S_PEND], s[L.S_PEND_NA] = 1, eta + 1
    return s


@pytest.mark.parametrize("w", [0.7, 1.0, 2.0, 4.46])
def test_shared_prefix_predictor_equals_the_full_horizon_simulation(w):
    """predict_cycle_costs (prefix once, each candidate stops at its switch-off) gives the
    costs of cost_59 on every candidate simulated over the whole horizon."""
    from hasel_wheel_mpc.mpc import predict_cycle_costs
    from hasel_wheel_sim import layout as L
    from hasel_wheel_sim.integrator import simulate_batch
    from hasel_wheel_sim.wheel import TICK
    cfg = MpcConfig(phi_a=tuple(D(x) for x in np.arange(1, 15.01, 1.0)),
                    phi_d=(D(18), D(20), D(22)))
    mpc = Mpc(config=cfg)
    s = _state_after_switch_on(mpc, w)
    n, ticks = len(mpc.cands), int(2.3 * SECTOR / w / TICK)
    states = np.tile(s, (n, 1))
    states[:, L.S_PEND_PHI_A], states[:, L.S_PEND_PHI_D] = mpc.cands[:, 0], mpc.cands[:, 1]
    out = np.empty((n, ticks, 3))
    simulate_batch(states, np.tile(mpc.pv, (n, 1)), TICK, ticks, out)
    for tw in (False, True):
        full = np.array([cost_59(out[i, :, 1], out[i, :, 2], 1.5, 0.1, 1.0, tw) for i in range(n)])
        fast, means = np.empty(n), np.empty(n)
        k = predict_cycle_costs(s, mpc.pv, mpc.cands, TICK, ticks, 1.5, 0.1, 1.0, tw, fast, means,
                                1)
        assert np.array_equal(np.isfinite(full), np.isfinite(fast)) and np.isfinite(fast).sum() > 20
        ok = np.isfinite(full)
        assert np.allclose(fast[ok], full[ok], rtol=1e-12, atol=0.0)
        # the prefix is the time to the current switch-off: (22 - 8) deg at ~w, in ticks
        assert k * TICK == pytest.approx(D(14) / w, rel=0.15)
    # time-weighted: the mean over the cycle's samples of (v + d - ref)^2, plus the terminal term
    i = int(np.flatnonzero(np.isfinite(fast))[0])
    q = out[i, :, 2]
    a = int(np.flatnonzero((q[:-1] == 1) & (q[1:] == 0))[0]) + 1
    c = int(np.flatnonzero((q[a:-1] == 1) & (q[a + 1:] == 0))[0]) + a + 1
    e = out[i, a:c, 1] + 0.1 - 1.5
    assert fast[i] == pytest.approx(np.mean(e ** 2) + 1.0 * e[-1] ** 2, rel=1e-12)
    assert means[i] == pytest.approx(np.mean(out[i, a:c, 1]), rel=1e-12)

@pytest.mark.parametrize("w", [0.7, 1.0, 2.0, 4.46])
def test_two_cycle_predictor_equals_a_step_by_step_simulation(w):
    """With horizon_pads = 2 the pad after the candidate is queued, with the candidate's
    angles, when the candidate switches on; the predictor's costs and first-cycle means equal
    cost_59 on a HybridWheel stepped tick by tick that is commanded the same way."""
    from hasel_wheel_mpc.mpc import predict_cycle_costs
    from hasel_wheel_sim.wheel import TICK
    cfg = MpcConfig(phi_a=tuple(D(x) for x in np.arange(1, 15.01, 2.0)), phi_d=(D(20), D(22)))
    mpc = Mpc(config=cfg)
    s = _state_after_switch_on(mpc, w)
    n, ticks = len(mpc.cands), int(3.3 * SECTOR / w / TICK)
    ref, d = 1.5, 0.1
    fast, means = np.empty(n), np.empty(n)
    predict_cycle_costs(s, mpc.pv, mpc.cands, TICK, ticks, ref, d, 0.5, True, fast, means, 2)
    slow, first = np.empty(n), np.empty(n)
    for i, (pa, pd) in enumerate(mpc.cands):
        wheel = HybridWheel(mode="tick")
        wheel.pv = mpc.pv
        wheel.s = s.copy()
        wheel.s[L.S_PEND_PHI_A], wheel.s[L.S_PEND_PHI_D] = pa, pd
        rows, queued = [], False
        for _ in range(ticks):
            was = wheel.s[L.S_Q]
            wheel.advance(TICK)
            if not queued and was == 0 and wheel.s[L.S_Q] == 1:     # the candidate is on
                wheel.command(int(wheel.s[L.S_ETA] + 1) % 16, pa, pd)
                queued = True
            rows.append((wheel.s[L.S_XI2], wheel.s[L.S_Q]))
        v, q = np.array(rows).T
        slow[i] = cost_59(v, q, ref, d, 0.5, True, pads=2)
        offs = np.flatnonzero((q[:-1] == 1) & (q[1:] == 0)) + 1
        first[i] = v[offs[0]:offs[1]].mean() if len(offs) > 1 else math.nan
    ok = np.isfinite(slow)
    assert np.array_equal(ok, np.isfinite(fast)) and ok.sum() >= n - 2
    assert np.allclose(fast[ok], slow[ok], rtol=1e-12, atol=0.0)
    assert np.allclose(means[ok], first[ok], rtol=1e-12, atol=0.0)
    # the second cycle is in the cost: it differs from the one-cycle cost of the same run
    one = np.empty(n)
    predict_cycle_costs(s, mpc.pv, mpc.cands, TICK, ticks, ref, d, 0.5, True, one, means, 1)
    assert not np.allclose(one[ok], fast[ok])


class FakeClock:
    """Each reading advances by ``step`` seconds."""

    def __init__(self, step):
        self.t, self.step = 0.0, step

    def __call__(self):
        self.t += self.step
        return self.t


def test_a_late_decision_is_replaced_by_the_fallback_and_counted():
    on_time = Mpc()
    xi1 = 1 * SECTOR + D(8)
    good = on_time.decide(xi1, 2.0, 1, D(8), D(22), reference=2.0)
    assert not good.deadline_missed and good.deadline_slack > 0
    # 14 deg at 2 rad/s leaves ~0.12 s; a decision that takes 1 s is too late
    late = Mpc(clock=FakeClock(1.0))
    late.last_drive = (D(7.5), D(22))
    dec = late.decide(xi1, 2.0, 1, D(8), D(22), reference=2.0)
    assert dec.deadline_missed and dec.deadline_slack == pytest.approx(
        good.deadline_slack + good.compute_time - 1.0, abs=2 * TICK_S)
    assert (dec.command.n_a, dec.command.phi_a, dec.command.phi_d) == (2, D(7.5), D(22))
    assert late.deadline_misses == 1 and on_time.deadline_misses == 0
    # the fallback's phi_a, chosen at a lower speed, is raised to where pad 2 can still
    # switch on after pad 1 switches off at 22 deg (earliest_phi_a)
    late.last_drive = (D(0.25), D(22))
    fast = late.decide(xi1, 4.5, 1, D(8), D(22), reference=4.5)
    assert fast.deadline_missed
    assert fast.command.phi_a == pytest.approx(earliest_phi_a(2, 4.5, 1 * SECTOR + D(22)))
    # with actuation limits, the first fallback (no driving decision yet) lies within them
    bound = Mpc(config=MpcConfig(phi_a_min=D(9), phi_a_max=D(12)), clock=FakeClock(1.0))
    first = bound.decide(xi1, 2.0, 1, D(8), D(22), reference=2.0)
    assert first.deadline_missed and D(9) <= first.command.phi_a <= D(12)


def test_refinement_searches_phi_a_and_phi_d_jointly_around_the_coarse_winner():
    cfg = MpcConfig()
    assert len(cfg.candidates()) == 15                       # the paper's floor
    fine = cfg.refinement(D(10))
    # +-0.25 deg x {21, 22} deg, less (10, 22) deg, which the coarse pass predicted
    assert sorted(tuple(np.round(np.degrees(r), 6)) for r in fine) == [
        (9.75, 21.0), (9.75, 22.0), (10.0, 21.0), (10.25, 21.0), (10.25, 22.0)]
    dec = Mpc().decide(1 * SECTOR + D(8), 2.0, 1, D(8), D(22), reference=2.0)
    assert dec.candidates == 15 + 5


@pytest.mark.parametrize("kw, match", [({"phi_a": (D(30),)}, "phi_a"),
                                       ({"brake_threshold": 0.0}, "brake_threshold"),
                                       ({"brake_phi_a": D(-3), "brake_phi_d": D(-6)}, "braking")])
def test_bad_configurations_are_refused(kw, match):
    with pytest.raises(ValueError, match=match):
        MpcConfig(**kw)


def test_actuation_limits_bound_every_chosen_phi_a_and_apply_when_changed():
    # a slow wheel far below the reference wants the strongest push (smallest phi_a); with
    # phi_a limited to [5, 8] deg the choice is the bound, refinement included
    mpc = Mpc()
    free = mpc.decide(1 * SECTOR + D(3), 0.65, 1, D(3), D(22), reference=2.0)
    assert free.command.phi_a < D(5)
    mpc.config = dataclasses.replace(mpc.config, phi_a_min=D(5), phi_a_max=D(8))
    assert len(mpc.cands) == 4                              # 5, 6, 7, 8 deg
    bound = mpc.decide(1 * SECTOR + D(3), 0.65, 1, D(3), D(22), reference=2.0)
    assert bound.command.phi_a == pytest.approx(D(5))
    assert all(D(5) - 1e-12 <= a <= D(8) + 1e-12 for a in mpc.config.refinement(D(5))[:, 0])
    # a fast wheel above target wants a weak push; the upper bound caps it
    weak = mpc.decide(1 * SECTOR + D(3), 1.9, 1, D(8), D(22), reference=1.8)
    assert D(5) <= weak.command.phi_a <= D(8)


@pytest.mark.parametrize("kw, match", [
    ({"phi_a_min": D(9), "phi_a_max": D(8)}, r"expected 0 <= phi_a_min < phi_a_max <= pi/8"),
    ({"phi_a_min": D(5.2), "phi_a_max": D(5.8)}, r"no coarse phi_a candidate lies in")])
def test_bad_actuation_limits_are_refused_with_the_range(kw, match):
    with pytest.raises(ValueError, match=match):
        MpcConfig(**kw)


def _next_switch_on(phi_a: float, start: float, xi2: float) -> int:
    """Unwrapped pad of the first switch-on after pad 4 (on, phi_d 22 deg) switches off, with
    pad 5 commanded at ``phi_a``; the wheel starts at pad 4's contact angle ``start``."""
    wheel = HybridWheel(mode="tick", xi1=4 * SECTOR + start, xi2=xi2)
    wheel.command(4, start + D(0.1), D(22))
    assert [int(e[2]) for e in wheel.advance()] == [L.EV_ARM, L.EV_ON]   # pad 4 is on
    wheel.command(5, phi_a, D(22))
    for _ in range(3000):
        for _, _, kind, eta in wheel.advance():
            if kind == L.EV_ON:
                return int(eta)
    raise AssertionError("no switch-on within 10 s")


def test_a_driving_target_is_never_chosen_behind_the_latch():
    # 4.5 rad/s (the wheel's top speed is 4.7) moves 0.86 deg per tick, and pad 4 switches
    # off on the first tick past 22 deg, up to 0.86 deg late: pad 5 at 0.25 deg (22.75 deg
    # of pad 4) can be behind the wheel by then, and would switch on only a turn later (pad
    # 21).  The MPC, asked for its strongest push (1 deg - 0.75 deg in the refinement), picks
    # no phi_a below earliest_phi_a (2 ticks past 22 deg), where the pad switches on at
    # every phase of the ticks.
    xi2 = 4.5
    floor = earliest_phi_a(5, xi2, 4 * SECTOR + D(22))
    assert floor == pytest.approx(D(22) - SECTOR + 2 * TICK_S * xi2)
    phases = [D(3) + k * xi2 * TICK_S / 24 for k in range(24)]
    assert {_next_switch_on(D(0.25), p, xi2) for p in phases} == {5, 21}
    assert {_next_switch_on(floor, p, xi2) for p in phases} == {5}
    mpc = Mpc(config=MpcConfig(refine_phi_a=tuple(D(x) for x in (-0.75, -0.5, -0.25, 0.0,
                                                                 0.25, 0.5, 0.75))))
    assert D(0.25) in [pytest.approx(a) for a in mpc.config.refinement(D(1))[:, 0]]
    dec = mpc.decide(4 * SECTOR + D(3), xi2, 4, D(3), D(22), reference=5.0)
    assert floor <= dec.command.phi_a < floor + D(0.25)


def test_no_garbage_collection_runs_inside_a_decision():
    # with a collection due at every allocation, one would start inside decide() unless it
    # pauses the collector; the fake clock marks where the timed decision begins and ends
    inside = []
    collected = []

    def clock():
        inside.append(not (inside and inside[-1]))
        return 0.0

    def watch(phase, info):
        if phase == "start" and inside and inside[-1]:
            collected.append(info["generation"])

    mpc = Mpc(clock=clock)
    old = gc.get_threshold()
    gc.callbacks.append(watch)
    gc.set_threshold(1, 1, 1)
    try:
        mpc.decide(1 * SECTOR + D(3), 1.0, 1, D(3), D(22), reference=1.2)
        mpc.decide(1 * SECTOR + D(3), 2.0, 1, D(3), D(22), reference=1.2)   # braking
        mpc.brake_now(1 * SECTOR + D(10), 2.0, 0.0, D(12))
    finally:
        gc.set_threshold(*old)
        gc.callbacks.remove(watch)
    assert len(inside) == 6 and collected == []
    assert gc.isenabled()


def test_a_skipped_pad_is_not_driven():
    mpc = Mpc()
    xi1 = 20 * SECTOR + D(3)                               # pad 4 just on
    mpc.skip = {5}
    dec = mpc.decide(xi1, 2.0, 20, D(3), D(22), reference=2.0)
    assert not dec.braking and dec.command.n_a == 6
    mpc.skip = {5, 6}
    assert mpc.target_pad(20) == 23
    mpc.skip = set(range(16))
    assert mpc.target_pad(20) == 36                        # none left: a whole turn on
