"""The sim node's core: pacing against a wall clock, scaled time, command rejection."""
import math

import pytest

from hasel_wheel_common import protocol as P

from hasel_wheel_common.samples import Command
from hasel_wheel_sim.sim_runtime import MAX_TICKS_PER_CALL, SimRuntime
from hasel_wheel_sim.wheel import TICK


def test_real_time_pacing_advances_300_ticks_per_second():
    rt = SimRuntime(initial_speed=1.0)
    assert rt.run_until(100.0) == []                  # anchors the clock
    n = sum(len(rt.run_until(100.0 + k * 0.01)) for k in range(1, 101))
    assert n == 300 and rt.plant.t == pytest.approx(1.0, abs=1e-9)


def test_scaled_time():
    rt = SimRuntime(time_scale=10.0)
    rt.run_until(0.0)
    total = sum(len(rt.run_until(k * 0.01)) for k in range(1, 11))
    assert total == 300 and rt.plant.t == pytest.approx(1.0, abs=1e-9)
    with pytest.raises(ValueError, match=r"time_scale = 0"):
        rt.set_time_scale(0)


def test_falling_behind_drops_the_backlog_and_is_counted():
    rt = SimRuntime()
    rt.run_until(0.0)
    assert len(rt.run_until(10.0)) == MAX_TICKS_PER_CALL and rt.overruns == 1
    # from there on real time again: 10 ms later 3 ticks, not the 10 s left behind
    assert len(rt.run_until(10.01)) == 3 and rt.overruns == 1
    assert rt.plant.t == pytest.approx((MAX_TICKS_PER_CALL + 3) * TICK, abs=1e-9)


@pytest.mark.parametrize("cmd, code, field", [
    (Command(16, 0.05, 0.38), P.R_N_A, "n_a = 16"),
    (Command(3, math.nan, 0.38), P.R_ANGLE, "phi_a = nan"),
    (Command(3, 0.05, 0.5), P.R_ANGLE, "phi_d = 0.5"),
    (Command(3, 0.3, 0.1), P.R_ORDER, "phi_a = 0.3"),
    (Command(3, -0.1, 0.1), P.R_ORDER, "phi_a = -0.1"),
])
def test_bad_commands_are_rejected_and_never_switch_hv(cmd, code, field):
    rt = SimRuntime(initial_speed=2.0)
    reason = rt.submit(cmd)
    assert rt.last_rejection_code == code == P.check_command(cmd.n_a, cmd.phi_a, cmd.phi_d)
    assert reason is not None and field in reason
    outs = [rt.step() for _ in range(300)]
    assert all(o.truth.q == 0 for o in outs)          # no target latched, HV stays off
    assert rt.commands_rejected == 1 and rt.diagnostics()["commands_rejected"] == "1"


def test_good_command_is_applied_and_echoed():
    rt = SimRuntime(initial_speed=2.0)
    assert rt.submit(Command(2, math.radians(3), math.radians(22), sequence=41)) is None
    outs = [rt.step() for _ in range(300)]
    assert any(o.truth.q == 1 for o in outs)
    assert outs[-1].sample.last_command_sequence == 41
    assert outs[0].t == pytest.approx(TICK)


def test_hv_off_cuts_the_pad_and_refuses_commands():
    from hasel_wheel_common import protocol as P
    from hasel_wheel_common.samples import Command
    from hasel_wheel_sim import layout as L
    rt = SimRuntime(initial_speed=2.0)
    rt.submit(Command(1, 0.05, 0.38, 1))
    while not rt.plant.wheel.s[L.S_Q]:
        rt.step()
    rt.set_hv(False)
    assert rt.plant.wheel.s[L.S_Q] == 0.0 and rt.plant.wheel.s[L.S_ARMED] == 0.0
    assert rt.submit(Command(3, 0.05, 0.38, 2)) is not None
    assert rt.last_rejection_code == P.R_HV_DISABLED
    rt.set_hv(True)
    assert rt.submit(Command(3, 0.05, 0.38, 3)) is None
