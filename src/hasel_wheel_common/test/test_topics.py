"""The topic table's QoS rules: DDS request/offer matching, a second of history on the 300 Hz
streams, and a recorder that matches every publisher the graph has on a topic."""
import itertools

import pytest
import yaml

from hasel_wheel_common import topics
from hasel_wheel_common.topics import LATCHED, RELIABLE, STREAM, TOPIC_PUB_DEFAULT, QosSpec

STREAMS = (topics.TELEMETRY, topics.JOINT_STATES, topics.STATE_ESTIMATE, topics.TRUE_STATE)


@pytest.mark.parametrize("reader,writer,matches", [
    # DDS: a reader's request must not exceed the writer's offer
    (("best_effort", "volatile"), ("best_effort", "volatile"), True),
    (("best_effort", "volatile"), ("reliable", "transient_local"), True),
    (("reliable", "volatile"), ("best_effort", "volatile"), False),
    (("reliable", "volatile"), ("reliable", "transient_local"), True),
    (("reliable", "transient_local"), ("reliable", "volatile"), False),
    (("best_effort", "transient_local"), ("best_effort", "transient_local"), True),
])
def test_compatibility_follows_the_dds_request_offer_rule(reader, writer, matches):
    r = QosSpec(*reader, "keep_last", 1)
    w = QosSpec(*writer, "keep_last", 1)
    assert r.compatible_with(w) is matches


@pytest.mark.parametrize("topic", STREAMS, ids=lambda t: t.name)
def test_a_300_hz_stream_keeps_a_second_of_samples(topic):
    assert topic.qos.reliability == "best_effort"
    assert topic.qos.history == "keep_last"
    assert topic.qos.depth >= topics.STREAM_RATE * 1.0


@pytest.mark.parametrize("topic", topics.ALL, ids=lambda t: t.name)
def test_the_recorder_matches_every_publisher_of_a_topic(topic):
    profile = topics.recorder_profile(topic)
    for offered in (topic.qos, *topics.OTHER_PUBLISHERS.get(topic.name, ())):
        assert profile.compatible_with(offered), (topic.name, offered)
    assert profile.depth >= topics.STREAM_RATE


def test_a_latched_request_would_lose_a_topic_pub_reference():
    """Why the recorder needs overrides: rosbag2 requests transient_local when every
    publisher it has seen (the MPC node's) is latched, and then a ``ros2 topic pub``
    (volatile) is not matched."""
    as_rosbag2_picks = QosSpec("reliable", "transient_local", "keep_last", 10)
    assert as_rosbag2_picks.compatible_with(LATCHED)
    assert not as_rosbag2_picks.compatible_with(TOPIC_PUB_DEFAULT)
    assert topics.recorder_profile(topics.REFERENCE).compatible_with(TOPIC_PUB_DEFAULT)


def test_the_mpc_node_hears_latched_and_volatile_references():
    assert RELIABLE.compatible_with(LATCHED) and RELIABLE.compatible_with(TOPIC_PUB_DEFAULT)


def test_overrides_name_every_topic_of_every_wheel_once():
    profiles = topics.recorder_profiles(["wheel0", "wheel1", ""])
    expected = {topics.qualified(t, ns) for t, ns in itertools.product(topics.ALL,
                                                                       ("wheel0", "wheel1", ""))}
    assert set(profiles) == expected
    assert "/wheel1/telemetry" in profiles and "/telemetry" in profiles
    assert profiles["/wheel0/telemetry"] == QosSpec("best_effort", "volatile", "keep_last",
                                                    STREAM.depth)
    assert profiles["/wheel0/reference_speed"] == QosSpec("reliable", "volatile", "keep_last",
                                                          topics.STREAM_RATE)


def test_the_overrides_file_is_what_ros2_bag_record_reads():
    data = yaml.safe_load(topics.recorder_overrides_yaml(["wheel0"]))
    allowed = {"history": {"keep_last", "keep_all"}, "reliability": {"reliable", "best_effort"},
               "durability": {"volatile", "transient_local"}}
    for name, entry in data.items():
        assert name.startswith("/")
        assert set(entry) == {"history", "depth", "reliability", "durability"}
        assert all(entry[k] in v for k, v in allowed.items())
        assert isinstance(entry["depth"], int) and entry["depth"] > 0
    assert data["/wheel0/reference_speed"]["durability"] == "volatile"
