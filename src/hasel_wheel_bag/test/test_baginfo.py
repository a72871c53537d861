"""bag info: counts, rates, gaps and configuration against a bag whose timing is known."""
import pytest

from hasel_wheel_common import topics
from hasel_wheel_bag.writer import BagWriter
from hasel_wheel_bag.info import GAP_FACTOR, PERIOD_SAMPLES, bag_info

REF = topics.REFERENCE


@pytest.fixture
def bag(tmp_path):
    """/fast at 300 Hz for 3000 samples with 29 missing after sample 2000 (a 0.1 s hole);
    /slow at 10 Hz for 10 s; starts 5 s after t = 0."""
    path = tmp_path / "timed"
    t0 = 5_000_000_000
    with BagWriter(path, custom_data={"seed": "7", "plant.yaml": "a: 1\nb: 2\n"}) as b:
        b.add_topic("/fast", REF.type, REF.qos)
        b.add_topic("/slow", REF.type, REF.qos)
        fast = [k for k in range(3000) if not 2000 < k < 2030]
        events = [(t0 + round(k * 1e9 / 300), "/fast", k) for k in fast]
        events += [(t0 + k * 100_000_000, "/slow", k) for k in range(101)]
        for t, topic, k in sorted(events):
            b.write(topic, {"data": float(k)}, t)
    return path


def test_counts_rates_and_the_gap_are_what_was_written(bag):
    info = bag_info(bag)
    assert info.messages == 2971 + 101
    assert info.start_ns == 5_000_000_000
    assert info.duration_s == pytest.approx(10.0)
    f, s = info.topics["/fast"], info.topics["/slow"]
    assert (f.count, s.count) == (2971, 101)
    assert f.type == s.type == "std_msgs/msg/Float64"
    # rate = (count - 1) / (last - first): 2970 intervals over 2999/300 s
    assert f.rate_hz == pytest.approx(2970 / (2999 / 300))
    assert s.rate_hz == pytest.approx(10.0)
    assert f.period_s == pytest.approx(1 / 300, rel=1e-6)
    assert f.max_interval_s == pytest.approx(30 / 300, abs=1e-8)
    assert (f.gaps, s.gaps) == (1, 0)
    assert f.last_s == pytest.approx(2999 / 300, abs=1e-8)
    assert info.configuration == {"seed": "7", "plant.yaml": "a: 1\nb: 2\n"}
    assert info.files[0][2] is True and info.warnings == []
    assert "/fast" in info.text() and "plant.yaml: a: 1  (+1 lines)" in info.text()


def test_a_gap_after_the_nominal_period_is_known_is_counted_too(tmp_path):
    path = tmp_path / "late"
    with BagWriter(path) as b:
        b.add_topic("/fast", REF.type, REF.qos)
        n = PERIOD_SAMPLES + 500
        stamps = [k * 10_000_000 for k in range(n)]          # 100 Hz
        stamps += [stamps[-1] + round(GAP_FACTOR * 10_000_000) + 1 + k * 10_000_000
                   for k in range(10)]                         # one gap just over the limit
        for t in stamps:
            b.write("/fast", {"data": 0.0}, t)
    f = bag_info(path).topics["/fast"]
    assert f.gaps == 1 and f.count == n + 10
