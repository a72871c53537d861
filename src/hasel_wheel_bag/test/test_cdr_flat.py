"""The flat CDR decoder against mcap-ros2-support's generic one, field by field, over random
values and frame_ids of every length (the frame_id sets the alignment of what follows)."""
import math

from hypothesis import given, settings
from hypothesis import strategies as st
from mcap_ros2.decoder import DecoderFactory
from mcap.records import Schema

from hasel_wheel_bag import interfaces
from hasel_wheel_bag.cdr_encode import encoder_for
from hasel_wheel_bag.export import flatten
from hasel_wheel_bag.cdr_flat import flat_decoder

TELEMETRY = "hasel_wheel_msgs/msg/WheelTelemetry"
STATE = "hasel_wheel_msgs/msg/HybridStateEstimate"


def _codecs(datatype):
    text = interfaces.full_definition(datatype)
    encode = encoder_for(datatype, text)
    schema = Schema(id=1, name=datatype, encoding="ros2msg", data=text.encode())
    generic = DecoderFactory().decoder_for("cdr", schema)
    return encode, generic, flat_decoder(datatype, text)


def _same(a, b):
    fa, fb = flatten(a), flatten(b)
    assert fa.keys() == fb.keys()
    for k in fa:
        x, y = fa[k], fb[k]
        assert x == y or (isinstance(x, float) and math.isnan(x) and math.isnan(y)), k


frame_ids = st.text(alphabet="abcdefgh_/0123456789", max_size=17)
f64 = st.floats(allow_nan=True, allow_infinity=True, width=64)
f32 = st.floats(allow_nan=False, allow_infinity=True, width=32)


@settings(max_examples=300, deadline=None)
@given(frame=frame_ids, sec=st.integers(0, 2**31 - 1), nsec=st.integers(0, 999_999_999),
       us=st.integers(0, 2**64 - 1), seq=st.integers(0, 2**32 - 1), raw=st.integers(0, 1023),
       angle=f64, q=st.integers(0, 1), eta=st.integers(0, 15),
       eta_u=st.integers(-2**31, 2**31 - 1), mask=st.integers(0, 2**16 - 1), hv=f32, cur=f32,
       cmd=st.integers(0, 2**32 - 1), faults=st.integers(0, 2**32 - 1))
def test_telemetry_decodes_as_the_generic_decoder(frame, sec, nsec, us, seq, raw, angle, q, eta,
                                                  eta_u, mask, hv, cur, cmd, faults):
    encode, generic, flat = _codecs(TELEMETRY)
    data = encode({"header": {"stamp": {"sec": sec, "nanosec": nsec}, "frame_id": frame},
                   "device_time_us": us, "sequence": seq, "encoder_raw": raw, "angle": angle,
                   "q": q, "eta": eta, "eta_unwrapped": eta_u, "active_mask": mask,
                   "hv_monitor": hv, "current_monitor": cur, "last_command_sequence": cmd,
                   "fault_flags": faults})
    m = flat(data)
    _same(m, generic(data))
    assert m.header.frame_id == frame and m.sequence == seq and m.fault_flags == faults


@settings(max_examples=200, deadline=None)
@given(frame=frame_ids, xs=st.lists(f64, min_size=8, max_size=8), q=st.integers(0, 1),
       eta=st.integers(0, 15), eta_u=st.integers(-2**31, 2**31 - 1))
def test_state_estimate_decodes_as_the_generic_decoder(frame, xs, q, eta, eta_u):
    encode, generic, flat = _codecs(STATE)
    names = ("xi1", "xi2", "activation_counter", "deactivation_counter", "disturbance",
             "accel_disturbance", "xi2_stddev", "quality")
    msg = dict(zip(names, xs), header={"stamp": {"sec": 1, "nanosec": 2}, "frame_id": frame},
               q=q, eta=eta, eta_unwrapped=eta_u)
    data = encode(msg)
    _same(flat(data), generic(data))


def test_only_flat_types_get_the_fast_decoder():
    for datatype in ("sensor_msgs/msg/JointState", "hasel_wheel_msgs/msg/MpcStatus",
                     "std_msgs/msg/Float64", "diagnostic_msgs/msg/DiagnosticArray"):
        assert flat_decoder(datatype, interfaces.full_definition(datatype)) is None, datatype
    for datatype in (TELEMETRY, STATE):
        assert flat_decoder(datatype, interfaces.full_definition(datatype)) is not None


def test_bounded_fields_and_constants_are_told_apart():
    """'=' inside a bounded type is a field (so the message is not flat); '=' after the name
    is a constant (left out)."""
    header = "std_msgs/Header header\n"
    assert flat_decoder("a/msg/A", header + "string<=8 label\nfloat64 x\n") is None
    assert flat_decoder("a/msg/B", header + "float64[<=3] v\nfloat64 x\n") is None
    assert flat_decoder("a/msg/C", header + "uint8 MODE_A=1\nuint8 MODE_B = 2\nfloat64 x\n")
    text = header + "uint8 MODE_A=1\nfloat64 x 0.5\n================================================================================\nMSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n================================================================================\nMSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"
    encode = encoder_for("a/msg/C", text)
    m = flat_decoder("a/msg/C", text)(encode({"header": {"stamp": {"sec": 3, "nanosec": 4},
                                                           "frame_id": "w"}, "x": 1.5}))
    assert m.x == 1.5 and m.header.stamp.sec == 3 and m._fields == ("header", "x")
