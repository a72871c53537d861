"""bag observer: estimates paired with true states by stamp give the error's closed form."""
import math

import pytest

from hasel_wheel_common import samples
from hasel_wheel_common import topics
from hasel_wheel_bag.layout import BagError
from hasel_wheel_bag.writer import BagWriter
from hasel_wheel_bringup.bag_cli import main as bag_main
from hasel_wheel_bringup.observer_error import observer_error

RATE = 300


def _state(t, xi2):
    return samples.state_msg(t, 0.0, xi2, 0, 0.0, 0.0, 0)


def write(path, n, truth=True, estimates=True, offset=lambda k: 0.0, start_error=5.0):
    """n samples at 300 Hz of a wheel at 2 rad/s; the estimate is off by ``offset(k)``, and by
    ``start_error`` during the first second (acquisition)."""
    st = topics.TRUE_STATE
    with BagWriter(path) as b:
        if truth:
            b.add_topic("/w/sim/true_state", st.type, st.qos)
        if estimates:
            b.add_topic("/w/state_estimate", st.type, st.qos)
        for k in range(n):
            t = 10.0 + k / RATE
            if truth:
                b.write("/w/sim/true_state", _state(t, 2.0), round(t * 1e9))
            if estimates and k % 10 != 9:                       # every 10th estimate missing
                e = start_error if t < 11.0 else offset(k)
                b.write("/w/state_estimate", _state(t, 2.0 + e), round(t * 1e9))


def test_alternating_offset_has_its_rms_and_the_start_is_left_out(tmp_path):
    # +-0.01 alternating after the first second: RMS = |e| = 0.01 exactly; the 5 rad/s start
    # error would dominate if the skip did not leave out the first 2 s
    write(tmp_path / "b", 3000, offset=lambda k: 0.01 if k % 2 else -0.01)
    (w,) = observer_error(tmp_path / "b", skip=2.0)
    assert w.namespace == "/w" and w.unpaired == 0
    assert w.pairs == pytest.approx((3000 - 600) * 0.9, abs=2)
    assert w.rms == pytest.approx(0.01, rel=1e-9)
    assert w.median == pytest.approx(0.01, rel=1e-9) and w.p99 == pytest.approx(0.01, rel=1e-9)
    (w0,) = observer_error(tmp_path / "b", skip=0.0)
    assert w0.rms > 1.0                                     # 270 of 2700 estimates off by 5


def test_a_replay_s_estimates_pair_with_the_original_run_s_truth(tmp_path, capsys):
    write(tmp_path / "run", 1500, estimates=False)
    write(tmp_path / "replay", 1500, truth=False, offset=lambda k: 0.003 * (k % 3 - 1))
    (w,) = observer_error(tmp_path / "replay", tmp_path / "run", skip=2.0)
    assert w.rms == pytest.approx(0.003 * math.sqrt(2 / 3), rel=1e-3)   # e in {-3, 0, 3} mrad/s
    assert bag_main(["observer", str(tmp_path / "replay"), "--truth", str(tmp_path / "run")]) == 0
    assert "/w: observer speed error over" in capsys.readouterr().out


def test_nothing_to_pair_is_a_clear_error(tmp_path):
    write(tmp_path / "est", 300, truth=False)
    with pytest.raises(BagError, match="no state_estimate pairs by stamp with a sim/true_state"):
        observer_error(tmp_path / "est")
    with pytest.raises(BagError, match=r"skip = -1.0 s: expected a time >= 0"):
        observer_error(tmp_path / "est", skip=-1.0)
    assert bag_main(["observer", str(tmp_path / "est")]) == 2
