"""The protocol codec: the specification's test vectors both ways, CRC and COBS against their
published reference values, and fuzzing (random bytes, truncations, bit flips, every split)."""
import json
import math
import struct
from pathlib import Path

import pytest
from cobs import cobs
from hypothesis import given, settings
from hypothesis import strategies as st

from hasel_wheel_common import protocol as P

VECTORS = json.loads((Path(__file__).resolve().parents[3] / "docs" / "protocol_vectors.json").read_text())


def test_crc_is_ccitt_false():
    assert P.crc16(b"123456789") == int(VECTORS["crc"]["check"], 16) == 0x29B1


@pytest.mark.parametrize("ex", VECTORS["cobs_examples"])
def test_cobs_matches_the_reference_examples(ex):
    assert cobs.encode(bytes.fromhex(ex["raw_hex"])).hex() == ex["stuffed_hex"]


@pytest.mark.parametrize("v", VECTORS["valid"], ids=lambda v: v["name"])
def test_valid_vectors_round_trip(v):
    cls = P.LAYOUT[v["type"]][1]
    msg = cls(**v["fields"])
    assert P.encode(msg, v["counter"]).hex() == v["wire_hex"]
    frames = P.FrameDecoder().feed(bytes.fromhex(v["wire_hex"]))
    assert frames == [P.Frame(v["type"], v["counter"], msg)]


@pytest.mark.parametrize("v", VECTORS["invalid"], ids=lambda v: v["name"])
def test_invalid_vectors_are_dropped_and_counted(v):
    d = P.FrameDecoder()
    good = next(v["wire_hex"] for v in VECTORS["valid"] if v["name"] == "HV on")
    frames = d.feed(bytes.fromhex(v["wire_hex"] + good))
    assert len(frames) == 1 and frames[0].message == P.Hv(1)      # resynchronised
    assert getattr(d.stats, v["counts"]) == 1 and d.stats.dropped == 1


def test_layout_sizes_are_the_specs():
    sizes = {t: fmt.size for t, (fmt, _) in P.LAYOUT.items()}
    assert sizes == {P.TELEMETRY: 42, P.ACK: 7, P.REJECT: 8, P.COMMAND: 13, P.HEARTBEAT: 8,
                     P.HV: 1, P.ESTOP: 0, P.CONFIG: 7, P.CLEAR_ESTOP: 0, P.START: 13}
    assert max(4 + s + 2 for s in sizes.values()) <= P.MAX_RAW


def test_v1_1_adds_start_with_the_payload_of_command_and_two_reject_reasons():
    # docs/protocol.md "Changes from 1.0": the version byte stays 1
    assert (P.VERSION, P.START, P.R_NOT_IN_CONTACT, P.R_ACTUATOR_ON) == (1, 0x16, 7, 8)
    assert P.LAYOUT[P.START][0].format == P.LAYOUT[P.COMMAND][0].format
    start, command = (P.encode(cls(19, 5, 0.05, 0.38), 43) for cls in (P.Start, P.Command))
    assert cobs.decode(start[:-1])[1] == P.START
    assert cobs.decode(start[:-1])[4:-2] == cobs.decode(command[:-1])[4:-2]


def test_values_that_do_not_fit_are_a_clear_error():
    with pytest.raises(P.ProtocolError, match="Command"):
        P.encode(P.Command(-1, 3, 0.1, 0.2), 0)


def test_sequence_gaps_are_counted_across_the_wrap():
    d = P.FrameDecoder()
    stream = b"".join(P.encode(P.Hv(1), c) for c in (65533, 65534, 1, 2, 5))
    assert len(d.feed(stream)) == 5
    assert d.stats.sequence_gaps == 2 + 2        # 65535, 0 missing; 3, 4 missing


@pytest.mark.parametrize("n_a, pa, pd, reason", [
    (3, math.radians(3), math.radians(22), 0), (6, math.radians(-22), math.radians(-6), 0),
    (16, 0.0, 0.1, P.R_N_A), (3, math.nan, 0.1, P.R_ANGLE), (3, 0.0, 0.5, P.R_ANGLE),
    (3, 0.2, 0.1, P.R_ORDER), (3, -0.1, 0.1, P.R_ORDER)])
def test_command_check(n_a, pa, pd, reason):
    assert P.check_command(n_a, pa, pd) == reason


# ---- fuzzing ---------------------------------------------------------------------------
messages = st.one_of(
    st.builds(P.Hv, st.integers(0, 1)),
    st.builds(P.Heartbeat, st.integers(0, 2**64 - 1)),
    st.builds(P.Command, st.integers(0, 2**32 - 1), st.integers(0, 15),
              st.floats(-0.375, 0.375, width=32), st.floats(-0.375, 0.375, width=32)),
    st.builds(P.Start, st.integers(0, 2**32 - 1), st.integers(0, 15),
              st.floats(-0.375, 0.375, width=32), st.floats(-0.375, 0.375, width=32)),
    st.builds(P.Telemetry, st.integers(0, 2**64 - 1), st.integers(0, 2**32 - 1),
              st.integers(0, 1023), st.integers(-2**31, 2**31 - 1), st.integers(0, 1),
              st.integers(0, 15), st.integers(-2**31, 2**31 - 1), st.integers(0, 2**16 - 1),
              st.floats(0, 1e4, width=32), st.floats(0, 1, width=32), st.integers(0, 2**32 - 1),
              st.integers(0, 2**32 - 1)),
)


@given(st.binary(max_size=2000))
@settings(max_examples=300, deadline=None)
def test_random_bytes_never_raise(data):
    d = P.FrameDecoder()
    d.feed(data)
    assert d.stats.bytes == len(data)


@given(st.lists(messages, min_size=1, max_size=20), st.data())
@settings(max_examples=150, deadline=None)
def test_any_chunking_gives_the_same_frames(msgs, data):
    wire = b"".join(P.encode(m, i) for i, m in enumerate(msgs))
    cuts = sorted(data.draw(st.lists(st.integers(0, len(wire)), max_size=30)))
    d = P.FrameDecoder()
    out = []
    for a, b in zip([0] + cuts, cuts + [len(wire)]):
        out += d.feed(wire[a:b])
    assert [f.message for f in out] == msgs and d.stats.dropped == 0


def test_a_frame_split_at_every_offset():
    wire = P.encode(P.Command(5, 3, 0.05, 0.38), 9)
    for k in range(len(wire) + 1):
        d = P.FrameDecoder()
        assert d.feed(wire[:k]) + d.feed(wire[k:]) == [P.Frame(P.COMMAND, 9, P.Command(5, 3, *struct.unpack("<ff", struct.pack("<ff", 0.05, 0.38))))]


@given(st.lists(messages, min_size=3, max_size=12), st.data())
@settings(max_examples=150, deadline=None)
def test_bit_flips_and_truncations_lose_only_the_hit_frames(msgs, data):
    frames = [P.encode(m, i) for i, m in enumerate(msgs)]
    hit = data.draw(st.integers(0, len(msgs) - 1))
    f = bytearray(frames[hit])
    if data.draw(st.booleans()):        # flip one bit, not in the delimiter
        pos = data.draw(st.integers(0, len(f) - 2))
        f[pos] ^= 1 << data.draw(st.integers(0, 7))
    else:                                # truncate (keep the delimiter, as after a lost USB packet)
        f = f[:data.draw(st.integers(1, len(f) - 2))] + b"\x00"
    frames[hit] = bytes(f)
    d = P.FrameDecoder()
    got = d.feed(b"".join(frames))
    others = [m for i, m in enumerate(msgs) if i != hit]
    # every intact frame arrives; the hit one is dropped and counted (CRC-16 misses 2^-16 of
    # multi-bit errors; a single flip or truncation is always caught)
    assert [g.message for g in got if g.counter != hit] == others
    assert len(got) == len(msgs) - 1 and d.stats.dropped >= 1


def test_a_wholly_lost_frame_shows_as_a_sequence_gap():
    d = P.FrameDecoder()
    frames = [P.encode(P.Hv(0), c) for c in range(5)]
    frames[2] = b"\x00"                       # nothing left of it but its delimiter
    assert len(d.feed(b"".join(frames))) == 4 and d.stats.sequence_gaps == 1
