"""The host-side sequencer decides at switch-on, for the next pad, and only with HV on."""
import math

from hasel_wheel_driver.samples import TelemetrySample
from hasel_wheel_mpc.sequencer import Sequencer


def sample(q, eta_u, hv=9000.0, angle=None):
    angle = (eta_u + 0.5) * math.pi / 8 if angle is None else angle
    return TelemetrySample(0.0, 0, 0, 0, angle, q, eta_u % 16, eta_u, 0, hv, 0.0, 0, 0)


def test_commands_next_pad_at_switch_on_only():
    s = Sequencer(math.radians(3), math.radians(22))
    first = s.step(sample(0, 15))
    assert first.n_a == 0 and first.sequence == 1          # bootstrap: 15 -> 0
    assert s.step(sample(0, 15)) is None
    c = s.step(sample(1, 31))                              # switch-on of pad 15 (2nd revolution)
    assert (c.n_a, c.phi_a, c.phi_d, c.sequence) == (0, math.radians(3), math.radians(22), 2)
    assert s.step(sample(1, 31)) is None                   # once per cycle


def test_no_commands_while_hv_is_off_and_restart_when_idle():
    s = Sequencer(0.05, 0.38, restart_after=3)
    assert s.step(sample(0, 2, hv=0.0)) is None
    assert s.step(sample(0, 2)).sequence == 1
    assert [s.step(sample(0, 2)) for _ in range(3)][-1].sequence == 2


def test_restart_is_not_lost_when_hv_is_off_at_that_moment():
    s = Sequencer(0.05, 0.38, restart_after=3)
    assert s.step(sample(0, 2)).sequence == 1
    s.step(sample(0, 2))
    s.step(sample(0, 2))
    assert s.step(sample(0, 2, hv=0.0)) is None            # due now, but HV is off
    assert s.step(sample(0, 2)).sequence == 2              # restarts as soon as HV is back


def test_restart_counts_from_the_measured_sector_not_a_stale_target():
    # the actuator of interest says 17, but the wheel stopped in sector 5
    s = Sequencer(0.05, 0.38)
    assert s.step(sample(0, 17, angle=5.5 * math.pi / 8)).n_a == 6
