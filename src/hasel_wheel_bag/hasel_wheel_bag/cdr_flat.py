"""A fast decoder for "flat" ROS 2 messages: a ``std_msgs/Header`` and then primitives only.

The 300 Hz types (``WheelTelemetry``, ``HybridStateEstimate``) are flat.  The generic
decoder of mcap-ros2-support interprets the schema field by field for every message (about
25 us each); this one turns the schema into one ``struct`` format (per alignment of the end
of the header's frame_id, which has a variable length) once, and decodes a message with a
single ``unpack_from`` call.  :func:`flat_decoder` returns None for any other schema (and the
caller keeps the generic decoder), and the result is checked against the generic decoder
field by field in the tests.

CDR rules used (XCDR1, little endian, as rmw writes): a 4-byte encapsulation header (0x00
0x01 for little endian), then each primitive aligned to its own size (at most 8) from the
start of the body; a string is a uint32 length (counting its NUL) and the bytes.
"""
from __future__ import annotations

import struct
from collections import namedtuple
from typing import Any, Callable

#: ROS 2 primitive -> (struct code, size in bytes)
PRIMITIVES = {"bool": ("?", 1), "byte": ("B", 1), "char": ("B", 1), "int8": ("b", 1),
              "uint8": ("B", 1), "int16": ("h", 2), "uint16": ("H", 2), "int32": ("i", 4),
              "uint32": ("I", 4), "int64": ("q", 8), "uint64": ("Q", 8), "float32": ("f", 4),
              "float64": ("d", 8)}
HEADER_TYPES = ("std_msgs/Header", "std_msgs/msg/Header", "Header")
CDR_LE = b"\x00\x01"

Time = namedtuple("Time", "sec nanosec")
Header = namedtuple("Header", "stamp frame_id")


def _own_fields(schema_text: str) -> list[tuple[str, str]]:
    """(type, name) of the top-level message's fields (constants and comments left out).
    A constant is ``TYPE NAME=value``: an '=' after the type (a bounded type such as
    ``string<=8`` has one inside the type, and is a field)."""
    own = schema_text.split("\n" + "=" * 80 + "\n")[0]
    out = []
    for line in own.splitlines():
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        parts = line.split(None, 1)
        if len(parts) < 2 or "=" in parts[1]:          # a constant
            continue
        out.append((parts[0], parts[1].split()[0]))
    return out


def flat_decoder(schema_name: str, schema_text: str) -> Callable[[bytes], Any] | None:
    """A decoder for a ros2msg schema of the form ``std_msgs/Header header`` + primitives
    (no arrays, strings or other nested types), or None when the schema is not of that form.

    The decoded message is a namedtuple with the schema's field names (``header`` as
    ``Header(stamp=Time(sec, nanosec), frame_id)``), so ``m.header.stamp.sec`` and ``m.xi2``
    read as with the generic decoder.
    """
    fields = _own_fields(schema_text)
    if not fields or fields[0][0] not in HEADER_TYPES:
        return None
    prims = fields[1:]
    if not prims or any(t not in PRIMITIVES for t, _ in prims):
        return None
    cls = namedtuple(schema_name.rsplit("/", 1)[-1], ["header"] + [n for _, n in prims])
    # one struct format per start alignment (position mod 8 after the frame_id)
    formats = []
    for start in range(8):
        pos, fmt = start, "<"
        for t, _ in prims:
            code, size = PRIMITIVES[t]
            pad = (-pos) % size
            fmt += "x" * pad + code
            pos += pad + size
        formats.append(struct.Struct(fmt))
    head = struct.Struct("<iII")

    def decode(data: bytes) -> Any:
        if data[:2] != CDR_LE:
            raise ValueError(f"{schema_name}: not little-endian CDR (encapsulation "
                             f"{bytes(data[:2]).hex()})")
        sec, nanosec, n = head.unpack_from(data, 4)
        frame_id = bytes(data[16:16 + n - 1]).decode() if n else ""
        body_pos = 12 + n                  # position in the body (after the 4-byte header)
        values = formats[body_pos % 8].unpack_from(data, 4 + body_pos)
        return cls(Header(Time(sec, nanosec), frame_id), *values)

    return decode
