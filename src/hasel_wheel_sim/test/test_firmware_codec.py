"""The C++ firmware core's codec against protocol v1: every vector of
docs/protocol_vectors.json, and fuzzed streams decoded exactly as the Python decoder does."""
import json
import random
from pathlib import Path

import pytest

from hasel_wheel_common import protocol as P
from hasel_wheel_sim import device_cpp as H
from hasel_wheel_sim.device_core import angle_counts

VECTORS = json.loads((Path(__file__).resolve().parents[3] / "docs" / "protocol_vectors.json")
                     .read_text())
BY_TYPE = {t: cls for t, (_, cls) in P.LAYOUT.items()}


@pytest.fixture(scope="module")
def lib(firmware_build):
    return H.load_library(firmware_build)


def test_crc_check_value(lib):
    assert lib.hw_crc16(b"123456789", 9) == int(VECTORS["crc"]["check"], 16) == 0x29B1


@pytest.mark.parametrize("case", VECTORS["cobs_examples"], ids=lambda c: c["raw_hex"])
def test_cobs_examples(lib, case):
    import ctypes as C
    raw, stuffed = bytes.fromhex(case["raw_hex"]), bytes.fromhex(case["stuffed_hex"])
    buf = (C.c_uint8 * 300)()
    assert C.string_at(buf, lib.hw_cobs_encode(raw, len(raw), buf)) == stuffed
    assert C.string_at(buf, lib.hw_cobs_decode(stuffed, len(stuffed), buf)) == raw


@pytest.mark.parametrize("case", VECTORS["valid"], ids=lambda c: c["name"])
def test_every_valid_vector_decodes_to_its_fields_and_encodes_to_its_bytes(lib, case):
    wire = bytes.fromhex(case["wire_hex"])
    frames = H.CppDecoder(lib).feed(wire)
    assert [(f.type, f.counter) for f in frames] == [(case["type"], case["counter"])]
    msg = frames[0].message
    expected = BY_TYPE[case["type"]](**case["fields"])
    assert msg == expected
    assert H.encode(lib, msg, case["counter"]) == wire


@pytest.mark.parametrize("case", VECTORS["invalid"], ids=lambda c: c["name"])
def test_every_invalid_vector_is_dropped_and_counted_by_cause(lib, case):
    dec = H.CppDecoder(lib)
    assert dec.feed(bytes.fromhex(case["wire_hex"])) == []
    stats = dec.stats()
    assert stats[case["counts"]] == 1 and sum(stats.values()) == 1


@pytest.mark.parametrize("phi, count", [(0.0, 0), (3.0, 9), (22.0, 63), (-22.0, -62),
                                        (-6.0, -17), (22.5, 64), (-22.5, -64)])
def test_angles_become_counts_the_same_in_both_cores(lib, phi, count):
    import math
    f32 = float(__import__("numpy").float32(math.radians(phi)))
    assert lib.hw_angle_counts(f32) == angle_counts(f32) == count


def random_frames(rng, n):
    """n wire frames of random host and device messages, with their counters."""
    out = []
    for k in range(n):
        t = rng.choice(list(P.LAYOUT))
        fmt, cls = P.LAYOUT[t]
        values = []
        for code in fmt.format[1:]:
            if code in "f":
                values.append(rng.choice([0.0, 1.5, -0.3, 9000.0, 3e-4]))
            else:
                lo, hi = {"B": (0, 2**8), "H": (0, 2**16), "I": (0, 2**32),
                          "i": (-2**31, 2**31), "Q": (0, 2**64)}[code]
                values.append(rng.randrange(lo, hi))
        out.append(P.encode(cls(*values), k + 1))
    return out


def damage(rng, wire):
    """The stream with one of: a bit flip, a cut, random bytes, a long run without 0x00."""
    kind = rng.randrange(4)
    w = bytearray(wire)
    if kind == 0:
        w[rng.randrange(len(w))] ^= 1 << rng.randrange(8)
    elif kind == 1:
        w = w[:rng.randrange(1, len(w))]
    elif kind == 2:
        w = bytearray(rng.randbytes(rng.randrange(1, 40)))
    else:
        w = bytearray(rng.randbytes(80).replace(b"\x00", b"\x01"))
    return bytes(w), kind


def test_fuzzed_streams_decode_as_the_python_decoder_does_at_every_split(lib):
    rng = random.Random(40)
    for _ in range(20):
        frames = random_frames(rng, 30)
        stream, intact = bytearray(), set()
        for k, w in enumerate(frames):
            if rng.random() < 0.3:
                bad, _ = damage(rng, w)
                stream += bad + b"\x00"         # damage ends at a delimiter, as on the link
            else:
                stream += w
                intact.add(k + 1)
        stream = bytes(stream)
        py = P.FrameDecoder()
        want = py.feed(stream)
        assert intact <= {f.counter for f in want}
        for split in range(len(stream) + 1):                             # every split point
            dec = H.CppDecoder(lib)
            assert dec.feed(stream[:split]) + dec.feed(stream[split:]) == want
            stats = dec.stats()
            assert stats == {k: getattr(py.stats, k) for k in stats}


def test_every_intact_frame_is_recovered_after_any_damage(lib):
    rng = random.Random(41)
    for _ in range(200):
        frames = random_frames(rng, 6)
        bad, _ = damage(rng, frames[0])
        stream = bad + b"\x00" + b"".join(frames[1:])
        got = H.CppDecoder(lib).feed(stream)
        assert [(f.type, f.counter) for f in got[-5:]] == [
            (f.type, f.counter) for f in P.FrameDecoder().feed(b"".join(frames[1:]))]


def test_byte_by_byte_random_input_never_breaks_the_decoder(lib):
    rng = random.Random(42)
    dec = H.CppDecoder(lib)
    for _ in range(2000):
        dec.feed(rng.randbytes(rng.randrange(1, 200)))
    good = random_frames(rng, 3)
    assert [f.counter for f in dec.feed(b"\x00" + b"".join(good))] == [1, 2, 3]
