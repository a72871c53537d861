"""Our .msg files parse with independent ROS 2 message parsers, every field states its unit,
and the standard definitions we ship agree with rosbags' Jazzy type store."""
import re
from pathlib import Path

import pytest
from mcap.records import Schema
from mcap_ros2.decoder import DecoderFactory

from hasel_wheel_bag import interfaces

# rosbags (pip only, requirements-test.txt) is the independent reader of Jazzy's type store;
# a ROS install without it skips this file rather than failing to collect it
typesys = pytest.importorskip("rosbags.typesys", reason="rosbags is not installed (pip)")
Stores, get_types_from_msg, get_typestore = (typesys.Stores, typesys.get_types_from_msg,
                                             typesys.get_typestore)

PRIMITIVE_NUMBERS = {"bool", "byte", "float32", "float64", "int8", "uint8", "int16", "uint16",
                     "int32", "uint32", "int64", "uint64"}
MSG_DIR = Path(__file__).resolve().parents[2] / "hasel_wheel_msgs" / "msg"
OWN = sorted(p.stem for p in MSG_DIR.glob("*.msg"))
STD = ["std_msgs/msg/Header", "std_msgs/msg/Float64", "sensor_msgs/msg/JointState",
       "diagnostic_msgs/msg/DiagnosticArray", "diagnostic_msgs/msg/DiagnosticStatus",
       "diagnostic_msgs/msg/KeyValue", "builtin_interfaces/msg/Time"]


def test_the_package_sees_the_msgs_package_files():
    assert OWN == ["ActuationCommand", "HybridStateEstimate", "MpcStatus", "WheelTelemetry"]
    for name in OWN:
        assert interfaces.definition(f"hasel_wheel_msgs/msg/{name}") == (MSG_DIR / f"{name}.msg").read_text()


@pytest.mark.parametrize("name", OWN)
def test_rosbags_parser_reads_every_msg(name):
    types = get_types_from_msg((MSG_DIR / f"{name}.msg").read_text(), f"hasel_wheel_msgs/msg/{name}")
    consts, fields = types[f"hasel_wheel_msgs/msg/{name}"]
    assert fields and all(isinstance(f[0], str) for f in fields)


@pytest.mark.parametrize("name", OWN)
def test_mcap_ros2_parser_reads_the_full_schema(name):
    dt = f"hasel_wheel_msgs/msg/{name}"
    text = interfaces.full_definition(dt)
    schema = Schema(id=1, name=dt, encoding="ros2msg", data=text.encode())
    assert DecoderFactory().decoder_for("cdr", schema) is not None


@pytest.mark.parametrize("name", OWN)
def test_every_field_states_its_unit(name):
    for line in (MSG_DIR / f"{name}.msg").read_text().splitlines():
        code, _, comment = line.partition("#")
        if code.strip() and "=" not in code:
            assert comment.strip(), f"{name}: field without a comment: {line!r}"
            ftype = code.split()[0]
            if ftype.split("[")[0] in PRIMITIVE_NUMBERS:
                assert re.search(r"\[[^\]]+\]", comment), f"{name}: numeric field without [unit]: {line!r}"


@pytest.mark.parametrize("dt", STD)
def test_std_definitions_match_rosbags_jazzy(dt):
    store = get_typestore(Stores.ROS2_JAZZY)
    ours = get_types_from_msg(interfaces.definition(dt), dt)[dt]
    assert ours == store.fielddefs[dt]


def test_unknown_type_is_a_clear_error():
    with pytest.raises(interfaces.UnknownMessageType, match="geometry_msgs/msg/Twist"):
        interfaces.full_definition("geometry_msgs/msg/Twist")
    with pytest.raises(interfaces.UnknownMessageType, match="Twist"):
        interfaces.definition("Twist")


def test_full_definition_layout_is_rosbag2s():
    text = interfaces.full_definition("sensor_msgs/msg/JointState")
    parts = text.split("=" * 80 + "\n")
    assert [p.splitlines()[0] for p in parts[1:]] == ["MSG: std_msgs/Header", "MSG: builtin_interfaces/Time"]
