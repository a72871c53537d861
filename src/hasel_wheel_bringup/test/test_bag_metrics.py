"""bag metrics on a recording whose answers are known in closed form: constant offsets give
the steady error and NRMSE, ramps of known slope give the rise and fall times."""
import math

import pytest

from hasel_wheel_common import samples
from hasel_wheel_common import topics
from hasel_wheel_bag.writer import BagWriter
from hasel_wheel_common.samples import Command
from hasel_wheel_bringup.bag_metrics import bag_metrics
from hasel_wheel_bringup.cli import main

RATE = 300.0
SLOPE = 0.5            # [rad/s^2] of the ramps


def _speed(t: float) -> float:
    """ref 1.0 (+0.01) until 20 s; ramp up to 2.0 (+0.02) until 40 s; ramp down to 1.5
    (-0.015) until 60 s: every hold is 1 % off its reference."""
    if t < 20.0:
        return 1.01
    if t < 40.0:
        return min(1.01 + SLOPE * (t - 20.0), 2.02)
    return max(2.02 - SLOPE * (t - 40.0), 1.485)


@pytest.fixture
def bag(tmp_path):
    path = tmp_path / "run"
    st, ref, status = topics.TRUE_STATE, topics.REFERENCE, topics.MPC_STATUS
    with BagWriter(path) as b:
        for ns in ("/w1", "/w2"):
            b.add_topic(ns + "/reference_speed", ref.type, ref.qos)
            b.add_topic(ns + "/state_estimate", st.type, st.qos)
        b.add_topic("/w1/sim/true_state", st.type, st.qos)
        b.add_topic("/w1/mpc_status", status.type, status.qos)
        events = []
        for t0, r in ((0.0, 1.0), (20.0, 2.0), (30.0, 2.0), (40.0, 1.5)):   # 30 s: a repeat
            for ns in ("/w1", "/w2"):
                events.append((round(t0 * 1e9), ns + "/reference_speed", {"data": r}))
        for k in range(int(60 * RATE)):
            t = k / RATE
            t_ns = round(t * 1e9)
            events.append((t_ns, "/w1/sim/true_state",
                           samples.state_msg(t, 0.0, _speed(t), 0, 0.0, 0.0, 0)))
            events.append((t_ns, "/w1/state_estimate",             # worse: must be ignored
                           samples.state_msg(t, 0.0, _speed(t) + 0.3, 0, 0.0, 0.0, 0)))
            events.append((t_ns, "/w2/state_estimate",
                           samples.state_msg(t, 0.0, _speed(t), 0, 0.0, 0.0, 0)))
        for k in range(10):
            slack = -0.001 if k in (3, 7) else 0.02 - 0.001 * k
            events.append((round(k * 1e9), "/w1/mpc_status",
                           samples.mpc_status_msg(k, Command(k + 1, 0.1, 0.3, k), 1.0, 1.0,
                                                  0.0, 1e-3, slack, 36, k in (3, 7), False)))
        for t_ns, topic, msg in sorted(events, key=lambda e: e[0]):
            b.write(topic, msg, t_ns)
    return path


def test_segments_match_the_closed_forms(bag):
    w1, w2 = bag_metrics(bag)
    assert (w1.namespace, w2.namespace) == ("/w1", "/w2")
    assert w1.speed_source == "/w1/sim/true_state" and w2.speed_source == "/w2/state_estimate"
    assert w1.profile == [(0.0, 1.0), (20.0, 2.0), (40.0, 1.5)]      # the repeat is no step
    for w in (w1, w2):
        up, down = w.segments[1], w.segments[2]
        for seg in w.segments:
            assert seg.steady_error == pytest.approx(1.0, rel=1e-6)
            assert seg.nrmse == pytest.approx(0.01, rel=1e-6)
        assert math.isnan(w.segments[0].transition)
        # first sample at or past the new reference on a ramp of slope 0.5 rad/s^2
        assert up.transition == pytest.approx((2.0 - 1.01) / SLOPE, abs=1.01 / RATE)
        assert down.transition == pytest.approx((2.02 - 1.5) / SLOPE, abs=1.01 / RATE)
        assert up.settle == pytest.approx((2.0 * 0.98 - 1.01) / SLOPE, abs=1.01 / RATE)
    assert (w1.decisions, w1.deadline_misses, w1.min_slack) == (10, 2, -0.001)
    assert (w2.decisions, w2.deadline_misses) == (0, 0) and math.isnan(w2.min_slack)


def test_the_command_line_prints_each_wheel(bag, tmp_path, capsys):
    assert main(["bag", "metrics", str(bag)]) == 0
    out = capsys.readouterr().out
    assert ("wheel /w1 (speed from /w1/sim/true_state, reference from /w1/reference_speed): "
            "10 MPC decisions, 2 deadline misses") in out
    assert "wheel /w2" in out
    empty = tmp_path / "empty"
    with BagWriter(empty) as b:
        b.add_topic("/x", topics.REFERENCE.type, topics.REFERENCE.qos)
    assert main(["bag", "metrics", str(empty)]) == 1
    assert "no wheel with a reference_speed topic" in capsys.readouterr().err


def test_a_declared_but_empty_true_state_falls_back_to_the_observer(tmp_path):
    path = tmp_path / "real"
    st, ref = topics.TRUE_STATE, topics.REFERENCE
    with BagWriter(path) as b:
        b.add_topic("/w3/reference_speed", ref.type, ref.qos)
        b.add_topic("/w3/sim/true_state", st.type, st.qos)       # declared, never written
        b.add_topic("/w3/state_estimate", st.type, st.qos)
        b.write("/w3/reference_speed", {"data": 2.0}, 0)
        for k in range(3000):
            t = k / RATE
            b.write("/w3/state_estimate", samples.state_msg(t, 0.0, 2.02, 0, 0.0, 0.0, 0),
                    round(t * 1e9))
    (w,) = bag_metrics(path)
    assert w.speed_source == "/w3/state_estimate"
    assert w.segments[0].steady_error == pytest.approx(1.0, rel=1e-6)


def test_a_stop_segment_has_no_relative_error_instead_of_a_crash(tmp_path):
    path = tmp_path / "stop"
    st, ref = topics.TRUE_STATE, topics.REFERENCE
    with BagWriter(path) as b:
        b.add_topic("/w4/reference_speed", ref.type, ref.qos)
        b.add_topic("/w4/sim/true_state", st.type, st.qos)
        b.write("/w4/reference_speed", {"data": 0.0}, 0)
        for k in range(300):
            b.write("/w4/sim/true_state", samples.state_msg(k / RATE, 0.0, 0.0, 0, 0.0, 0.0, 0),
                    round(k / RATE * 1e9))
    (w,) = bag_metrics(path)
    assert math.isnan(w.segments[0].steady_error) and math.isnan(w.segments[0].nrmse)


def test_link_errors_come_from_the_telemetry_counter_and_flags(tmp_path):
    """300 samples with the counter skipping 3 and then 1, one device restart, and 5 samples
    flagged (watchdog, then encoder): the counts follow by hand."""
    path = tmp_path / "link"
    tel, ref, st = topics.TELEMETRY, topics.REFERENCE, topics.TRUE_STATE
    seqs = (list(range(100)) + list(range(103, 200)) + list(range(201, 250)) + [249]
            + list(range(0, 50)))
    with BagWriter(path) as b:
        for tp in (tel, ref, st):
            b.add_topic(topics.qualified(tp, "/w5"), tp.type, tp.qos)
        b.write("/w5/reference_speed", {"data": 1.0}, 0)
        for k, seq in enumerate(seqs):
            t = k / RATE
            flags = 1 if k in (10, 11, 12) else (16 if k in (200, 201) else 0)
            s = samples.TelemetrySample(t, round(t * 1e6), seq, 0, 0.0, 0, 0, 0, 0, 0.0, 0.0, 0,
                                        flags)
            b.write("/w5/telemetry", samples.telemetry_msg(s), round(t * 1e9))
            b.write("/w5/sim/true_state", samples.state_msg(t, 0.0, 1.0, 0, 0.0, 0.0, 0),
                    round(t * 1e9))
    (w,) = bag_metrics(path)
    assert w.telemetry_samples == len(seqs)
    assert (w.lost_samples, w.device_restarts, w.duplicate_samples) == (3 + 1, 1, 1)
    assert (w.fault_samples, w.fault_flags) == (5, 1 | 16)
    assert ("4 lost (sequence gaps), 1 device restarts, 1 duplicates, 5 with fault flags "
            "(bits 0x11)") in w.text()


def test_steady_windows_are_the_last_window_seconds_of_each_segment(bag):
    w1, _ = bag_metrics(bag, window=5.0)
    end = 60.0 - 1 / RATE + 1 / RATE                     # one interval past the last sample
    assert w1.steady_windows == [(15.0, 20.0), (35.0, 40.0), (pytest.approx(end - 5.0),
                                                           pytest.approx(end))]


def test_a_sample_at_the_step_belongs_to_the_new_segment_in_either_order():
    from hasel_wheel_mpc.segments import SegmentTracker
    results = []
    for sample_first in (True, False):
        tr = SegmentTracker(window=1.0)
        tr.reference(0.0, 1.0)
        tr.sample(0.5, 1.0)
        if sample_first:
            tr.sample(1.0, 2.0)
            tr.reference(1.0, 2.0)
        else:
            tr.reference(1.0, 2.0)
            tr.sample(1.0, 2.0)
        tr.sample(1.5, 2.0)
        results.append(tr.finish(2.0))
    first, second = results
    assert first == second
    assert first[0].steady_error == 0.0 and first[1].steady_error == 0.0
    assert first[1].transition == 0.0                     # reached at the step itself


def test_the_tracker_keeps_only_the_steady_window_in_memory():
    from hasel_wheel_mpc.segments import SegmentTracker
    tr = SegmentTracker(window=2.0)
    tr.reference(0.0, 1.0)
    for k in range(100_000):                              # 333 s at 300 Hz
        tr.sample(k / RATE, 1.0 + 0.01 * (k % 2))
        assert len(tr._ring) <= 2.0 * RATE + 2
    (seg,) = tr.finish()
    assert seg.steady_error == pytest.approx(0.5, rel=1e-3)      # mean 1.005 over the window


def test_nan_speeds_and_references_are_left_out_and_a_negative_reference_is_relative():
    from hasel_wheel_mpc.segments import SegmentTracker
    tr = SegmentTracker(window=1.0)
    tr.reference(0.0, -2.0)                      # rolling backwards at 2 rad/s
    tr.reference(0.5, math.nan)                  # a broken message: no new segment
    for k in range(300):
        tr.sample(k / RATE, math.nan if k % 10 == 0 else -2.02)
    (seg,) = tr.finish()
    assert seg.steady_error == pytest.approx(1.0) and seg.nrmse == pytest.approx(0.01)
    assert seg.settle == pytest.approx(1 / RATE)       # the first sample is NaN, the next fits


def test_json_output_has_no_nan(bag, capsys):
    import json
    assert main(["bag", "metrics", str(bag), "--json"]) == 0
    data = json.loads(capsys.readouterr().out,
                      parse_constant=lambda c: pytest.fail(f"non-standard JSON: {c}"))
    assert data[0]["segments"][0][3] is None              # the first segment has no step


def test_without_reference_messages_the_mpc_status_gives_the_reference(tmp_path):
    """A ROS recording whose reference_speed topic is declared but empty (the reference was
    published before the recorder subscribed): the status records carry the reference."""
    path = tmp_path / "ros"
    st, ref, status = topics.TRUE_STATE, topics.REFERENCE, topics.MPC_STATUS
    with BagWriter(path) as b:
        for tp in (st, ref, status):
            b.add_topic(topics.qualified(tp, "/w6"), tp.type, tp.qos)
        for k in range(int(20 * RATE)):
            t = k / RATE
            r = 1.0 if t < 10.0 else 1.5
            if k % 30 == 0:
                b.write("/w6/mpc_status", samples.mpc_status_msg(
                    t, Command(1, 0.1, 0.3, k), r, r, 0.0, 1e-3, 0.02, 36, False, False),
                    round(t * 1e9))
            b.write("/w6/sim/true_state", samples.state_msg(t, 0.0, r * 1.01, 0, 0.0, 0.0, 0),
                    round(t * 1e9))
    (w,) = bag_metrics(path)
    assert w.reference_source == "/w6/mpc_status"
    assert w.profile == [(0.0, 1.0), (10.0, 1.5)]
    assert [s.steady_error for s in w.segments] == pytest.approx([1.0, 1.0])
