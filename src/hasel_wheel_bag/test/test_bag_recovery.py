"""Bags that were never closed, broken files and unknown types: read what is there, say what
is not (issue 6, robustness of recording)."""
import os
import random
import signal
import subprocess
import sys

import pytest
from mcap.writer import Writer

from hasel_wheel_common import topics
from hasel_wheel_bag.cdr_encode import encoder_for
from hasel_wheel_bag.layout import (NOTE_CUT, NOTE_UNDECODABLE, NOTE_UNFINISHED, BagError,
                                    BagErrorCode)
from hasel_wheel_bag.reader import read_messages
from hasel_wheel_bag.writer import BagWriter

#: A recorder of a 60 s run at 300 Hz (telemetry and true state, as the sim writes them),
#: writing as fast as it can.  After every message that completed a chunk (the file grew) it
#: prints how many messages are now in finished chunks; once that reaches argv[2] it sends
#: itself SIGKILL (mid-chunk: it has written on since the last chunk finished).
RECORDER = r"""
import math, os, signal, sys
at = int(sys.argv[2])
from hasel_wheel_common import samples, topics
from hasel_wheel_bag.writer import BagWriter
bag = BagWriter(sys.argv[1], chunk_size=64 * 1024)
for tp in (topics.TELEMETRY, topics.TRUE_STATE):
    bag.add_topic(topics.qualified(tp, "/w0"), tp.type, tp.qos)
size, n, finished = 0, 0, 0
for k in range(60 * 300):
    t = k / 300
    s = samples.TelemetrySample(t=t, device_time_us=round(t * 1e6), sequence=k,
                                encoder_raw=k % 1024, angle=0.01 * k, q=k % 2, eta=k % 16,
                                eta_unwrapped=k, active_mask=1 << (k % 16), hv_monitor=9000.0,
                                current_monitor=3e-4, last_command_sequence=k // 10,
                                fault_flags=0)
    for topic, msg in (("/w0/telemetry", samples.telemetry_msg(s)),
                       ("/w0/sim/true_state", samples.state_msg(t, 0.01 * k, 2.0, 1, 0.0,
                                                                 math.inf, k))):
        bag.write(topic, msg, round(t * 1e9))
        n += 1
        grown = os.fstat(bag._fh.fileno()).st_size
        if grown != size:
            size = grown
            print(n, flush=True)
            finished = n
        if size and finished >= at and n >= finished + 100:
            os.kill(os.getpid(), signal.SIGKILL)
print("done", flush=True)
bag.close()
"""


def _record_and_kill(path, at: int) -> tuple[int, bool]:
    """Run the recorder until it kills itself with SIGKILL once ``at`` messages or more are
    in finished chunks (a moment given by progress, not wall time, so that a fast or slow
    machine kills at the same place).  Returns (messages in finished chunks as it last
    reported, whether it had finished instead)."""
    child = subprocess.run([sys.executable, "-c", RECORDER, str(path), str(at)],
                           capture_output=True, text=True, timeout=300)
    lines = child.stdout.split()
    done = "done" in lines
    assert done or child.returncode == -signal.SIGKILL, \
        f"the recorder failed (exit code {child.returncode}): {child.stderr[-500:]}"
    counts = [int(x) for x in lines if x.isdigit()]
    return (counts[-1] if counts else 0), done


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_recording_killed_at_a_random_moment_is_read_up_to_its_last_finished_chunk(
        tmp_path, seed):
    at = random.Random(seed).randrange(2000, 34000)     # of 36,000 messages
    finished, done = _record_and_kill(tmp_path / "killed", at)
    assert not done
    assert finished >= at
    said = []
    got = list(read_messages(tmp_path / "killed", warn=said.append))
    assert len(got) >= 0.99 * finished          # the bar
    assert len(got) >= finished                 # what this writer does: every finished chunk
    # a prefix of the recording, nothing skipped: each topic's stamps are k / 300 s
    by_topic = {}
    for topic, t_ns, _ in got:
        by_topic.setdefault(topic, []).append(t_ns)
    assert set(by_topic) == {"/w0/telemetry", "/w0/sim/true_state"}
    for stamps in by_topic.values():
        assert stamps == [round(k / 300 * 1e9) for k in range(len(stamps))]
    tel = [m for tp, _, m in got if tp == "/w0/telemetry"]
    assert [m.sequence for m in tel] == list(range(len(tel)))
    assert len(said) == 1 and said[0].kind in (NOTE_UNFINISHED, NOTE_CUT)
    assert said[0].facts["messages"] == len(got)


def _numbered_bag(path):
    """A closed bag of 20,000 Float64 messages 0, 1, 2, ... in 16 KiB chunks; its file."""
    with BagWriter(path, chunk_size=16 * 1024) as b:
        b.add_topic("/w0/reference_speed", topics.REFERENCE.type, topics.REFERENCE.qos)
        for k in range(20000):
            b.write("/w0/reference_speed", {"data": float(k)}, k * 1000)
    return path / f"{path.name}_0.mcap"


def test_a_file_cut_inside_a_chunk_keeps_the_chunks_before(tmp_path):
    path = tmp_path / "cut"
    f = _numbered_bag(path)
    whole = list(read_messages(path))
    data = f.read_bytes()
    f.write_bytes(data[: len(data) // 2])
    said = []
    got = list(read_messages(path, warn=said.append))
    assert 0 < len(got) < len(whole)
    assert [m.data for _, _, m in got] == [float(k) for k in range(len(got))]
    assert said[0].kind == NOTE_CUT and said[0].facts["messages"] == len(got)
    assert said[0].facts["size"] == len(data) // 2 and said[0].facts["cut_at"] < len(data) // 2
    # cut at half the bytes: the chunks of the first half survive (one chunk of 16 KiB holds
    # a few hundred of these messages, so at most that many of the first half are lost)
    assert len(got) >= len(whole) // 2 - 1500


def test_damage_inside_a_closed_file_is_an_error_naming_it(tmp_path):
    path = tmp_path / "hurt"
    f = _numbered_bag(path)
    data = bytearray(f.read_bytes())
    for at in range(len(data) // 3, 2 * len(data) // 3, 997):
        data[at:at + 8] = bytes(8)                 # zeros over the middle third's chunks
    f.write_bytes(bytes(data))
    with pytest.raises(BagError, match=r"hurt_0\.mcap") as err:
        list(read_messages(path))
    assert err.value.code == BagErrorCode.CORRUPT


def test_a_file_that_is_not_mcap_is_named_not_a_traceback(tmp_path):
    bad = tmp_path / "junk.mcap"
    bad.write_bytes(b"this is a text file\n" * 10)
    with pytest.raises(BagError, match=r"junk\.mcap") as err:
        list(read_messages(bad))
    assert err.value.code == BagErrorCode.NOT_MCAP
    (tmp_path / "empty.mcap").write_bytes(b"")
    with pytest.raises(BagError, match=r"empty\.mcap") as err:
        list(read_messages(tmp_path / "empty.mcap"))
    assert err.value.code == BagErrorCode.FILE_EMPTY
    missing = tmp_path / "gone"
    with BagWriter(missing) as b:
        b.add_topic("/w0/reference_speed", topics.REFERENCE.type, topics.REFERENCE.qos)
    os.remove(missing / "gone_0.mcap")
    with pytest.raises(BagError, match=r"gone_0\.mcap") as err:
        list(read_messages(missing))
    assert err.value.code == BagErrorCode.FILE_MISSING


def test_a_topic_of_an_unknown_type_is_skipped_with_a_warning(tmp_path):
    f = tmp_path / "mixed.mcap"
    with open(f, "wb") as fh:
        w = Writer(fh)
        w.start(profile="ros2", library="test")
        schema = w.register_schema("some/Blob", "protobuf", b"\x00")
        blob = w.register_channel("/blob", "protobuf", schema)
        ok_schema = w.register_schema("std_msgs/msg/Float64", "ros2msg", b"float64 data")
        ok = w.register_channel("/reference_speed", "cdr", ok_schema)
        enc = encoder_for("std_msgs/msg/Float64", "float64 data")
        for k in range(5):
            w.add_message(blob, log_time=k, data=b"\x01\x02", publish_time=k)
            w.add_message(ok, log_time=k, data=enc({"data": float(k)}), publish_time=k)
        w.finish()
    said = []
    got = list(read_messages(f, warn=said.append))
    assert [(tp, m.data) for tp, _, m in got] == [("/reference_speed", float(k)) for k in range(5)]
    assert [(n.kind, n.facts) for n in said] == [(NOTE_UNDECODABLE, {"topic": "/blob"})]


@pytest.mark.parametrize("text, code", [("", BagErrorCode.METADATA_NOT_ROSBAG2),
                                        ("a: [1, 2\n", BagErrorCode.METADATA_NOT_YAML),
                                        ("rosbag2_bagfile_information: {version: 9}\n",
                                         BagErrorCode.METADATA_NO_FILE_LIST)])
def test_a_broken_metadata_yaml_is_named(tmp_path, text, code):
    bag = tmp_path / "b"
    bag.mkdir()
    (bag / "metadata.yaml").write_text(text)
    with pytest.raises(BagError, match="metadata.yaml") as err:
        list(read_messages(bag))
    assert err.value.code == code


def test_configuration_survives_a_reindexed_metadata_yaml(tmp_path):
    """ros2 bag reindex writes a metadata.yaml without our custom data: the configuration
    still comes from the MCAP file's own records."""
    import yaml

    from hasel_wheel_bag.reader import bag_configuration
    bag = tmp_path / "r"
    with BagWriter(bag, custom_data={"seed": "7"}) as b:
        b.add_topic("/x", topics.REFERENCE.type, topics.REFERENCE.qos)
        b.write("/x", {"data": 1.0}, 0)
    meta = yaml.safe_load((bag / "metadata.yaml").read_text())
    meta["rosbag2_bagfile_information"].pop("custom_data")
    (bag / "metadata.yaml").write_text(yaml.safe_dump(meta))
    assert bag_configuration(bag) == {"seed": "7"}
