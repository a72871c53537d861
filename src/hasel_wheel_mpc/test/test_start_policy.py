"""StartConfig ranges and the StallMonitor's rules (stall after stall_time, give up after
max_restarts STARTs in a row, a run ends at half the reference)."""
import pytest

from hasel_wheel_mpc.start_policy import GIVE_UP, RECOVERED, StallMonitor, StartConfig


@pytest.mark.parametrize("field, value, match", [
    ("still_speed", 0.0, r"'still_speed' = 0.0 is out of range; allowed range is \(0, 1\] rad/s"),
    ("stall_time", 0.05, r"'stall_time' = 0.05 is out of range; allowed range is \[0.1, 60\] s"),
    ("max_restarts", 2.5, r"'max_restarts' = 2.5 is not a whole number"),
    ("max_restarts", True, r"'max_restarts' = True is not a number"),
])
def test_a_value_out_of_range_is_refused_with_its_range(field, value, match):
    with pytest.raises(ValueError, match=match):
        StartConfig(**{field: value})


def test_a_rolling_wheel_that_stands_for_stall_time_has_stalled():
    m = StallMonitor(StartConfig(stall_time=1.0))
    tick = 1.0 / 300.0
    stalls = [m.step(k * tick, True, 0.0, 1.0, True) for k in range(301)]
    assert stalls.index(True) == 300 and sum(stalls) == 1 and m.total_restarts == 1


@pytest.mark.parametrize("still, reference, started", [(False, 1.0, True), (True, 0.0, True),
                                                       (True, 1.0, False)])
def test_no_stall_while_rolling_without_a_reference_or_not_yet_started(still, reference, started):
    m = StallMonitor(StartConfig(stall_time=0.1))
    assert not any(m.step(k / 300.0, still, 0.0, reference, started) for k in range(300))


def test_the_start_after_max_restarts_in_a_row_gives_up_at_the_pad():
    m = StallMonitor(StartConfig(max_restarts=3))
    assert [m.start(4) for _ in range(3)] == [None, None, None]
    verdict = m.start(4)
    assert (verdict.what, verdict.pad) == (GIVE_UP, 4)


def test_reaching_half_the_reference_ends_a_run_of_restarts():
    m = StallMonitor(StartConfig(max_restarts=2))
    m.start(1), m.start(1)
    m.step(0.0, False, RECOVERED * 1.5, 1.5, True)
    assert m.restarts == 0 and m.start(1) is None
