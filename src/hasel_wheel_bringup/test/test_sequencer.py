"""The host-side sequencer decides at switch-on, for the next pad, and only with HV on; the
pad edges it (and the controller) reads from two consecutive samples."""
import math

import pytest

from hasel_wheel_common.samples import PadEdges, TelemetrySample, pad_edges
from hasel_wheel_bringup.sequencer import Sequencer


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


@pytest.mark.parametrize("prev, now, edges", [
    ((0, 5), (1, 5), (True, False)),     # switch-on
    ((1, 5), (0, 6), (False, True)),     # switch-off, next target latched
    ((1, 5), (1, 5), (False, False)),    # the same pad still on
    ((0, 6), (0, 6), (False, False)),    # coasting towards it
    ((1, 5), (1, 6), (True, True)),      # the one q = 0 sample between two pads was lost
    ((1, 5), (1, 7), (True, True)),      # a braking pad (eta + 2), likewise
])
def test_pad_edges_between_two_samples(prev, now, edges):
    assert pad_edges(now[0], now[1], prev[0], prev[1]) == edges


def test_pad_edges_tracker_reads_a_sample_stream():
    # before the first sample the pad counts as off: a first sample with HV on is a switch-on
    e = PadEdges()
    stream = [(1, 5), (1, 5), (0, 6), (0, 6), (1, 6), (1, 7), (0, 8)]
    assert [e.step(q, eta) for q, eta in stream] == [
        (True, False), (False, False), (False, True), (False, False), (True, False),
        (True, True), (False, True)]
    assert PadEdges().step(0, 9) == (False, False)


def test_a_switch_on_is_not_missed_when_the_sample_between_two_pads_is_lost():
    # at speed, with a small phi_a, pads 5 and 6 can be a single tick apart: its sample, the
    # only one with q = 0, is lost, and the next one already shows pad 6 on
    s = Sequencer(math.radians(0.5), math.radians(22))
    s.step(sample(1, 5))
    assert s.step(sample(1, 5)) is None
    c = s.step(sample(1, 6))
    assert c is not None and c.n_a == 7
