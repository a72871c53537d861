"""The observer's a_d coefficients travel in HybridStateEstimate (accel_c..accel_f), so the MPC
node predicts with the same a_d(xi1) as the embedded controller, and bags written before
those fields still read and replay."""
import math
from types import SimpleNamespace

import pytest

from hasel_wheel_common import samples
from hasel_wheel_common import topics
from hasel_wheel_bag.reader import read_messages
from hasel_wheel_bag.writer import BagWriter
from hasel_wheel_mpc.core import SWITCH_ON, decide_at
from hasel_wheel_mpc.mpc import Mpc
from hasel_wheel_mpc.observer import Observer, ObserverConfig
from hasel_wheel_bringup.replay import FieldDiff, _compare
from hasel_wheel_sim.effects import effects_from_mapping
from hasel_wheel_sim.plant import Plant, PlantConfig

D = math.radians
# a once-per-turn torque and a platform pull: both harmonics of a_d are then non-zero
EFFECTS = {"com_offset": {"enabled": True, "torque": {"value": 0.004, "unit": "N*m"},
                          "phase": {"value": 0.5, "unit": "rad"}},
           "platform_disturbance": {"enabled": True, "torque": {"value": 0.003, "unit": "N*m"},
                                    "phase": {"value": 1.0, "unit": "rad"}}}


@pytest.fixture(scope="module")
def estimate():
    plant = Plant(config=PlantConfig(seed=2, effects=effects_from_mapping(EFFECTS)), xi2=1.5)
    plant.open_loop(D(9), D(22))
    obs = Observer(config=ObserverConfig(default_phi_a=D(9)))
    e = None
    for _ in range(300 * 30):
        s = plant.step()
        if s is not None:
            e = obs.step(s)
    return e


def _through_a_bag(tmp_path, msg):
    with BagWriter(tmp_path / "b") as b:
        b.add_topic("/state_estimate", topics.STATE_ESTIMATE.type, topics.STATE_ESTIMATE.qos)
        b.write("/state_estimate", msg, 1)
    return [m for _, _, m in read_messages(tmp_path / "b")][0]


def test_the_coefficients_arrive_exactly_and_the_node_decides_as_the_embedded_loop(
        estimate, tmp_path):
    e = estimate
    assert all(abs(c) > 1e-4 for c in e.accel_coefficients)       # all five in use
    msg = samples.state_msg(e.t, e.xi1, e.xi2, e.q, e.act_counter, e.deact_counter,
                            e.eta_unwrapped, e.xi2_std, e.quality, e.accel_disturbance,
                            e.accel_coefficients)
    got = _through_a_bag(tmp_path, msg)
    coeffs = samples.accel_coefficients_of(got)
    assert coeffs == tuple(e.accel_coefficients)                   # float64, bit for bit
    # the node's decision from the message is the embedded controller's decision
    # a driving decision (the reference near the present speed, not a braking one)
    args = (SWITCH_ON, e.xi1, e.xi2, e.eta_unwrapped, D(9), D(22), e.xi2, 0.0)
    embedded = decide_at(Mpc(), *args, tuple(e.accel_coefficients), e.act_counter)
    node = decide_at(Mpc(), *args, coeffs, e.act_counter)
    assert not embedded.braking and embedded.candidates >= 15
    assert node.command[:3] == embedded.command[:3]
    assert node.predicted_speed == embedded.predicted_speed
    # a_d held at its present value over the whole prediction predicts differently
    held = decide_at(Mpc(), *args, (e.accel_disturbance, 0.0, 0.0), e.act_counter)
    assert held.predicted_speed != embedded.predicted_speed


def test_three_coefficients_leave_the_pivot_harmonic_at_zero_and_four_are_refused():
    m = samples.state_msg(0.0, 0.0, 1.0, 0, 0.0, 0.0, 0, accel_coefficients=(0.1, 0.2, 0.3))
    assert [m[f] for f in samples.ACCEL_FIELDS] == [0.1, 0.2, 0.3, 0.0, 0.0]
    with pytest.raises(ValueError, match=r"expected \(c, a, b\) or \(c, a, b, e, f\).*got 4"):
        samples.state_msg(0.0, 0.0, 1.0, 0, 0.0, 0.0, 0, accel_coefficients=(0.1,) * 4)


def test_an_estimate_from_before_the_coefficients_reads_as_none_and_replays_alike():
    old = SimpleNamespace(xi1=1.0, xi2=2.0, accel_disturbance=0.05)
    assert samples.accel_coefficients_of(old) is None
    # replay compares what both sides carry: the new fields are not a difference
    recorded = {k: v for k, v in samples.state_msg(0.5, 1.0, 2.0, 1, 0.1, 0.2, 3).items()
                if k not in samples.ACCEL_FIELDS}
    mine = samples.state_msg(0.5, 1.0, 2.0, 1, 0.1, 0.2, 3, accel_coefficients=(0.1,) * 5)
    diffs: dict[str, FieldDiff] = {}
    _compare(recorded, mine, 0.5, diffs)
    assert diffs == {}
    _compare(dict(recorded, xi2=2.5), mine, 0.5, diffs)            # a real difference still is
    assert set(diffs) == {"xi2"} and diffs["xi2"].max_abs == pytest.approx(0.5)
