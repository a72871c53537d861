"""The speed controller's decision points: when the MPC decides, and that a step down in the
reference is braked on at the next switch-on, whether it arrives during a pad or between two."""
import pytest

from hasel_wheel_mpc.closed_loop import WheelLoop, controller_config
from hasel_wheel_mpc.controller import (BETWEEN_PADS, IDLE, NEW_REFERENCE, REDECIDE_MIN_TIME,
                                        SWITCH_ON, decision_point)
from hasel_wheel_sim import layout as L
from hasel_wheel_sim.plant import PlantConfig


@pytest.mark.parametrize("args, why", [
    # (reference changed, q, switched on, idle, act counter [rad], deact counter [rad])
    ((False, 1, True, 0, 0.0, 0.3), SWITCH_ON),
    ((True, 1, True, 0, 0.0, 0.3), SWITCH_ON),           # a switch-on decides anyway
    ((False, 0, False, 150, 0.5, 0.8), IDLE),
    ((True, 1, False, 0, 0.0, 0.3), NEW_REFERENCE),      # 0.3 rad left > 0.02 s x 2 rad/s
    ((True, 1, False, 0, 0.0, 0.03), None),              # 0.03 rad < 0.04 rad: too late
    ((True, 0, False, 3, 0.1, 0.5), BETWEEN_PADS),       # pending switch-on 0.1 rad ahead
    ((True, 0, False, 3, 0.03, 0.5), None),
    ((False, 1, False, 0, 0.0, 0.3), None),
])
def test_decision_points(args, why):
    changed, q, on, idle, act, deact = args
    assert decision_point(changed, q, on, idle, 150, act, deact, 2.0, REDECIDE_MIN_TIME) == why


def _step_down(t_step: float):
    """2.6 -> 2.0 rad/s at t_step on the nominal plant; returns (q, counters at the step as
    time [s], phi_a of the first switch-on after the step)."""
    cfg = controller_config()
    loop = WheelLoop(cfg, ((0.0, 2.6), (t_step, 2.0)), PlantConfig(switching="tick"), w0=2.6,
                     clock=lambda: 0.0)
    s = loop.plant.wheel.s
    at_step = None
    prev_q = s[L.S_Q]
    while loop.plant.t < t_step + 0.5:
        loop.step()
        if at_step is None and loop.plant.t >= t_step:
            v = s[L.S_XI2]
            on_in = (s[L.S_THETA_ON] - s[L.S_XI1]) / v
            off_in = (s[L.S_THETA_OFF] - s[L.S_XI1]) / v
            at_step = (int(s[L.S_Q]), on_in, off_in)
        elif at_step is not None and prev_q == 0.0 and s[L.S_Q] == 1.0:
            return at_step + (s[L.S_PHI_A],)
        prev_q = s[L.S_Q]
    raise AssertionError("no switch-on within 0.5 s of the step")


def test_a_step_down_is_braked_on_at_the_next_switch_on_during_a_pad_or_between_two():
    # steps spread over one pad cycle (~0.15 s at 2.6 rad/s); the controller sees the step one
    # sample later and its command needs its way (4 ms) too, so "enough time" is counted
    # with 2 ticks and the latency on top of REDECIDE_MIN_TIME
    spare = REDECIDE_MIN_TIME + 2 / 300 + 0.004 + 0.002
    kinds = set()
    for k in range(16):
        q, on_in, off_in, phi_a = _step_down(3.0 + 0.01 * k)
        if (off_in if q else on_in) > spare:
            kinds.add(q)
            assert phi_a < 0.0, f"step at q={q}: next switch-on drives (phi_a {phi_a:.3f} rad)"
    assert kinds == {0, 1}       # both cases were exercised
