"""Our CDR encoder writes the bytes mcap-ros2-support's public ``Writer`` writes, for every
type we publish, full and sparse, with edge values; and what it writes decodes to the values
given."""
import io
import math

import pytest
from mcap.reader import make_reader
from mcap.records import Schema
from mcap_ros2.decoder import DecoderFactory
from mcap_ros2.writer import Writer

from hasel_wheel_bag import interfaces
from hasel_wheel_bag.cdr_encode import encoder_for, parse_schema

VALUES = {"bool": [True, False], "byte": [7, 255, 0], "char": [65], "float32": [1.5, -0.25, math.inf],
          "float64": [0.1, -2.5e-300, math.inf, -math.inf, 3], "int8": [-3, 127],
          "uint8": [200, 0, 1], "int16": [-300], "uint16": [65535], "int32": [-2**31, 5],
          "uint32": [2**32 - 1, 9], "int64": [-2**63], "uint64": [2**64 - 1, 12345678901234],
          "string": ["", "abc", "wheel_0/ü", "x" * 13]}
# mcap-ros2-support reads a field missing from a dict through getattr, so a missing field
# named like a dict method (DiagnosticStatus.values) is that method: always give those
DICT_METHODS = {"values", "keys", "items"}


def _message(datatype, k, sparse):
    """A message of ``datatype`` from the field definitions: value k of each field's list,
    arrays of k % 3 elements, and (``sparse``) some fields left out."""
    fields = parse_schema(datatype, interfaces.full_definition(datatype))
    msg = {}
    for i, f in enumerate(fields[f"{datatype.split('/')[0]}/{datatype.split('/')[-1]}"]):
        if sparse and (k + i) % 3 == 0 and f.name not in DICT_METHODS:
            continue
        if f.type in VALUES:
            pick = VALUES[f.type]
            one = [pick[(k + j) % len(pick)] for j in range(k % 3)]
            msg[f.name] = one if f.size is not None else pick[k % len(pick)]
        else:
            pkg, name = f.type.split("/")
            sub = f"{pkg}/msg/{name}"
            msg[f.name] = ([_message(sub, k + j, sparse) for j in range(k % 3)]
                           if f.size is not None else _message(sub, k, sparse))
    return msg


def _theirs(datatype, messages):
    """The CDR bytes of ``messages`` as mcap-ros2-support's Writer writes them."""
    buf = io.BytesIO()
    w = Writer(buf)
    schema = w.register_msgdef(datatype, interfaces.full_definition(datatype))
    for m in messages:
        w.write_message("/x", schema, m, log_time=0)
    w.finish()
    buf.seek(0)
    return [message.data for _s, _c, message in make_reader(buf).iter_messages()]


@pytest.mark.parametrize("datatype", interfaces.known_types())
@pytest.mark.parametrize("sparse", [False, True])
def test_bytes_equal_mcap_ros2_supports_writer(datatype, sparse):
    messages = [_message(datatype, k, sparse) for k in range(12)]
    encode = encoder_for(datatype, interfaces.full_definition(datatype))
    ours = [encode(m) for m in messages]
    assert ours == _theirs(datatype, messages)


def test_an_empty_dict_is_every_field_zero():
    dt = "hasel_wheel_msgs/msg/ActuationCommand"
    text = interfaces.full_definition(dt)
    decode = DecoderFactory().decoder_for("cdr", Schema(id=1, name=dt, encoding="ros2msg", data=text.encode()))
    m = decode(encoder_for(dt, text)({}))
    assert (m.header.stamp.sec, m.header.frame_id, m.sequence, m.n_a, m.phi_a, m.mode) == (
        0, "", 0, 0, 0.0, 0)


def test_a_missing_array_of_messages_is_empty():
    dt = "diagnostic_msgs/msg/DiagnosticStatus"
    text = interfaces.full_definition(dt)
    decode = DecoderFactory().decoder_for("cdr", Schema(id=1, name=dt, encoding="ros2msg", data=text.encode()))
    m = decode(encoder_for(dt, text)({"level": 2, "name": "link"}))
    assert (m.level, m.name, m.message, m.values) == (2, "link", "", [])


def test_arrays_fixed_bounded_and_defaults():
    text = "uint8[3] a\nfloat64[<=2] b\nstring[] c\nint32 d -7\nstring e 'hi'\nuint16 K=4\n"
    encode = encoder_for("p/msg/T", text)
    decode = DecoderFactory().decoder_for("cdr", Schema(id=1, name="p/msg/T", encoding="ros2msg", data=text.encode()))
    m = decode(encode({"a": [1], "b": [0.5, 1.5, 2.5], "c": ["x", "yz"]}))
    assert (list(m.a), list(m.b), m.c, m.d, m.e) == ([1, 0, 0], [0.5, 1.5], ["x", "yz"], -7, "hi")
    assert encode({"a": b"\x01\x02\x03"}) == encode({"a": [1, 2, 3]})


def test_a_field_of_an_undefined_type_is_refused():
    with pytest.raises(ValueError, match="q/Missing"):
        encoder_for("p/msg/T", "q/Missing m\n")({})
