"""CDR encoder for ROS 2 messages given as dicts, from their ``ros2msg`` schema text.

The writing half of :mod:`.cdr_flat`: XCDR1, little endian, as rmw writes it.  A 4-byte
encapsulation header (``00 01 00 00``), then the fields in order, each primitive aligned to
its own size (at most 8) from the start of the body; a string is a uint32 length counting
its NUL, the UTF-8 bytes and the NUL; an unbounded or bounded array (``T[]``, ``T[<=N]``) is
a uint32 count and the elements, a fixed array (``T[N]``) the N elements alone; a nested
message is its fields inline; a message without fields is one zero byte.

A field missing from the dict (or None) is written as its default from the schema, else zero,
False or "" (a nested message as all its fields missing, an array as empty, a fixed array
padded with missing values); a value is converted with ``int``, ``float``, ``bool`` or
``str`` of its field's type.  The bytes equal those of
mcap-ros2-support's writer for every type we publish: ``test_cdr_encode.py`` holds it.
"""
from __future__ import annotations

import re
import struct
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Callable

from hasel_wheel_bag.cdr_flat import PRIMITIVES

CDR_LE_HEADER = b"\x00\x01\x00\x00"
_SEPARATOR = re.compile(r"^={3,}\s*$", re.MULTILINE)
_TYPE = re.compile(r"^([A-Za-z0-9_/]+)(?:<=\d+)?(?:\[(<=)?(\d*)\])?$")
_COERCE: dict[str, Callable[[Any], Any]] = {
    "bool": bool, "float32": float, "float64": float, "string": str,
    **{t: int for t in PRIMITIVES if t not in ("bool", "float32", "float64")}}
_ZERO: dict[str, Any] = {"bool": False, "float32": 0.0, "float64": 0.0, "string": "",
                         **{t: 0 for t in PRIMITIVES if t not in ("bool", "float32", "float64")}}
_UINT32 = struct.Struct("<I")


@dataclass(frozen=True)
class Field:
    """One field of a message: its type ('float64', 'string' or 'pkg/Name'), its name, and
    its array kind: ``size`` None for a single value, else -1 for ``T[]``, N for ``T[N]``
    (``fixed``) or ``T[<=N]`` (not ``fixed``); ``default``: the value written when the field
    is missing (None: zero, False or "")."""

    type: str
    name: str
    size: int | None = None
    fixed: bool = False
    default: Any = None


def parse_schema(datatype: str, text: str) -> dict[str, list[Field]]:
    """Fields of every message type in a ros2msg schema ('pkg/Name' -> fields), the first
    block being ``datatype``.  Constants and comments are left out; a default value is read
    for a single primitive field (a default of an array raises ValueError)."""
    out: dict[str, list[Field]] = {}
    name = _short(datatype)
    for block in _SEPARATOR.split(text):
        lines = block.strip().splitlines()
        if lines and lines[0].startswith("MSG:"):
            name = _short(lines[0].split(None, 1)[1].strip())
            lines = lines[1:]
        pkg = name.split("/")[0]
        fields = []
        for line in lines:
            line = line.split("#", 1)[0].strip()
            parts = line.split(None, 2)
            if len(parts) < 2 or "=" in parts[1] or (len(parts) > 2 and parts[2].startswith("=")):
                continue                              # empty, a comment or a constant
            m = _TYPE.match(parts[0])
            if m is None:
                raise ValueError(f"{name}: field {parts[1]!r} has an unreadable type {parts[0]!r}")
            base, bounded, count = m.group(1), m.group(2), m.group(3)
            size = None if count is None else (int(count) if count else -1)
            ftype = _resolve(base, pkg)
            default = None
            if len(parts) > 2:
                if size is not None or ftype not in _COERCE:
                    raise ValueError(f"{name}: field {parts[1]!r}: defaults are supported for "
                                     f"single primitive values only")
                default = _literal(ftype, parts[2].strip())
            fields.append(Field(ftype, parts[1], size,
                                fixed=size is not None and size >= 0 and not bounded,
                                default=default))
        out[name] = fields
    return out


def encoder_for(datatype: str, schema_text: str) -> Callable[[Any], bytes]:
    """The encoder of ``datatype`` ('pkg/msg/Name') from its full ros2msg schema: a function
    of a dict shaped like the message (or an object with the fields as attributes) that
    returns its CDR bytes, header included."""
    types = parse_schema(datatype, schema_text)
    plans: dict[str, Callable[[bytearray, Any], None]] = {}

    def plan(name: str) -> Callable[[bytearray, Any], None]:
        if name not in plans:
            if name not in types:
                raise ValueError(f"{datatype}: the schema does not define {name}")
            steps = [_field_writer(f, plan) for f in types[name]]
            if not steps:
                steps = [lambda buf, _msg: buf.append(0)]

            def write(buf: bytearray, msg: Any) -> None:
                for step in steps:
                    step(buf, msg)
            plans[name] = write
        return plans[name]

    top = plan(_short(datatype))

    def encode(message: Any) -> bytes:
        buf = bytearray(CDR_LE_HEADER)
        top(buf, message)
        return bytes(buf)

    return encode


def _short(datatype: str) -> str:
    """'pkg/msg/Name' or 'pkg/Name' -> 'pkg/Name'."""
    parts = datatype.split("/")
    return f"{parts[0]}/{parts[-1]}"


def _resolve(base: str, pkg: str) -> str:
    """A field's type as written -> a primitive name or 'pkg/Name'."""
    if base in _COERCE:
        return base
    if base == "Header":
        return "std_msgs/Header"
    return _short(base) if "/" in base else f"{pkg}/{base}"


def _literal(ftype: str, text: str) -> Any:
    """A default value as written in a .msg file, as a value of ``ftype``."""
    if ftype == "string":
        return text[1:-1] if len(text) >= 2 and text[0] == text[-1] and text[0] in "'\"" else text
    if ftype == "bool":
        return text.lower() in ("true", "1")
    return _COERCE[ftype](float(text) if ftype.startswith("float") else int(text, 0))


def _get(msg: Any, name: str) -> Any:
    if isinstance(msg, Mapping):
        return msg.get(name)
    return getattr(msg, name, None)


def _align(buf: bytearray, size: int) -> None:
    pad = (4 - len(buf)) % size          # the 4-byte header does not count
    if pad:
        buf.extend(b"\0" * pad)


def _value_writer(ftype: str, plan: Callable[[str], Callable[[bytearray, Any], None]],
                  default: Any = None) -> Callable[[bytearray, Any], None]:
    """Writer of one value of ``ftype`` (None = ``default``, else the zero value)."""
    if ftype == "string":
        empty = "" if default is None else default

        def write_string(buf: bytearray, value: Any) -> None:
            data = (empty if value is None else str(value)).encode("utf-8")
            _align(buf, 4)
            buf += _UINT32.pack(len(data) + 1)
            buf += data
            buf.append(0)
        return write_string
    if ftype in PRIMITIVES:
        code, size = PRIMITIVES[ftype]
        pack = struct.Struct("<" + code).pack
        coerce = _COERCE[ftype]
        zero = _ZERO[ftype] if default is None else default

        def write_primitive(buf: bytearray, value: Any) -> None:
            if size > 1:
                _align(buf, size)
            buf += pack(zero if value is None else coerce(value))
        return write_primitive
    nested: list[Callable[[bytearray, Any], None]] = []

    def write_message(buf: bytearray, value: Any) -> None:
        if not nested:
            nested.append(plan(ftype))
        nested[0](buf, {} if value is None else value)
    return write_message


def _field_writer(f: Field, plan: Callable[[str], Callable[[bytearray, Any], None]]
                  ) -> Callable[[bytearray, Any], None]:
    """Writer of field ``f`` of a message."""
    one = _value_writer(f.type, plan, f.default)
    if f.size is None:
        return lambda buf, msg: one(buf, _get(msg, f.name))
    is_bytes = f.type in ("uint8", "byte")

    def write_array(buf: bytearray, msg: Any) -> None:
        values = _get(msg, f.name)
        values = [] if values is None else values
        if f.fixed:
            values = list(values)[:f.size]
            values += [None] * (f.size - len(values))
        else:
            if f.size >= 0:
                values = values[:f.size]
            _align(buf, 4)
            buf += _UINT32.pack(len(values))
        if is_bytes and isinstance(values, (bytes, bytearray)):
            buf += values
            return
        for v in values:
            one(buf, v)
    return write_array
