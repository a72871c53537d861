"""Bag round trip: what we write is read back field for field by rosbags (independent) and
by mcap-ros2-support, with rosbag2 (Jazzy, v9) metadata."""
import math

import pytest
import yaml
from rosbags.highlevel import AnyReader

from hasel_wheel_common import samples
from hasel_wheel_common import topics
from hasel_wheel_bag.layout import BagError, BagErrorCode
from hasel_wheel_bag.reader import read_messages
from hasel_wheel_bag.writer import BagWriter


def _sample(k):
    return samples.TelemetrySample(t=k / 300, device_time_us=round(k * 1e6 / 300), sequence=k,
                                   encoder_raw=k % 1024, angle=0.01 * k, q=k % 2, eta=k % 16,
                                   eta_unwrapped=k, active_mask=1 << (k % 16), hv_monitor=9000.0,
                                   current_monitor=3e-4, last_command_sequence=k // 10,
                                   fault_flags=4 if k == 3 else 0)


@pytest.fixture
def bag(tmp_path):
    path = tmp_path / "rt"
    with BagWriter(path, custom_data={"seed": "42"}) as b:
        for tp in (topics.TELEMETRY, topics.COMMAND, topics.TRUE_STATE, topics.REFERENCE):
            b.add_topic(topics.qualified(tp, "/w0"), tp.type, tp.qos)
        for k in range(50):
            s = _sample(k)
            t_ns = round(s.t * 1e9)
            b.write("/w0/telemetry", samples.telemetry_msg(s), t_ns)
            b.write("/w0/sim/true_state", samples.state_msg(s.t, 0.01 * k, 2.0, 1, 0.0, math.inf, k), t_ns)
        b.write("/w0/command", samples.command_msg(samples.Command(15, -0.38, -0.1, 9), 0.1), 100_000_000)
        b.write("/w0/reference_speed", {"data": 2.5}, 0)
    return path


def test_rosbags_reads_every_field(bag):
    with AnyReader([bag]) as r:
        got = {}
        for conn, ts, raw in r.messages():
            got.setdefault(conn.topic, []).append((ts, r.deserialize(raw, conn.msgtype)))
    assert {k: len(v) for k, v in got.items()} == {"/w0/telemetry": 50, "/w0/sim/true_state": 50,
                                                  "/w0/command": 1, "/w0/reference_speed": 1}
    ts, m = got["/w0/telemetry"][3]
    assert ts == round(3 / 300 * 1e9)
    assert (m.sequence, m.encoder_raw, m.q, m.eta, m.eta_unwrapped, m.active_mask) == (3, 3, 1, 3, 3, 8)
    assert m.angle == 0.03 and m.fault_flags == 4 and m.hv_monitor == 9000.0
    assert (m.header.stamp.sec, m.header.stamp.nanosec) == (0, 10_000_000)
    _, c = got["/w0/command"][0]
    assert (c.n_a, c.phi_a, c.phi_d, c.sequence, c.mode) == (15, -0.38, -0.1, 9, 1)
    _, x = got["/w0/sim/true_state"][7]
    assert x.deactivation_counter == math.inf and x.eta == 7 and x.xi2 == 2.0
    assert got["/w0/reference_speed"][0][1].data == 2.5


def test_our_reader_agrees(bag):
    msgs = list(read_messages(bag, topics=["/w0/telemetry"]))
    assert [m.sequence for _, _, m in msgs] == list(range(50))


def test_metadata_is_rosbag2_v9(bag):
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    # keys the Jazzy decoder requires for version 9
    for key in ("version", "storage_identifier", "duration", "starting_time", "message_count",
                "topics_with_message_count", "compression_format", "compression_mode",
                "relative_file_paths", "files", "custom_data", "ros_distro"):
        assert key in info
    assert info["version"] == 9 and info["storage_identifier"] == "mcap"
    assert info["message_count"] == 102
    assert info["relative_file_paths"] == ["rt_0.mcap"] and (bag / "rt_0.mcap").is_file()
    assert info["duration"]["nanoseconds"] == round(49 / 300 * 1e9)
    tm = {t["topic_metadata"]["name"]: t for t in info["topics_with_message_count"]}
    q = tm["/w0/telemetry"]["topic_metadata"]["offered_qos_profiles"]
    assert isinstance(q, list) and q[0]["reliability"] == "best_effort" and q[0]["history"] == "keep_last"
    assert tm["/w0/command"]["topic_metadata"]["offered_qos_profiles"][0]["reliability"] == "reliable"
    assert info["custom_data"] == {"seed": "42"}


def test_refuses_to_overwrite_and_names_missing_bags(tmp_path, bag):
    with pytest.raises(BagError, match=str(bag)) as err:
        BagWriter(bag)
    assert err.value.code == BagErrorCode.EXISTS
    with pytest.raises(BagError, match="nope") as err:
        list(read_messages(tmp_path / "nope"))
    assert err.value.code == BagErrorCode.NO_SUCH_BAG
    with BagWriter(tmp_path / "b2") as b:
        with pytest.raises(BagError, match="/x") as err:
            b.write("/x", {}, 0)
        assert err.value.code == BagErrorCode.TOPIC_UNDECLARED
