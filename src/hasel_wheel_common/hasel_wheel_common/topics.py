"""The wheel's topics: names (relative, so they follow the node's namespace), types and QoS.

This table is the single source for the nodes, the embedded runner's bags, the recorder's
QoS overrides and ``docs/ros2.md``.  QoS is described with plain strings so the core needs
no rclpy; nodes turn it into ``rclpy.qos.QoSProfile`` and bags into rosbag2's metadata.

Two rules hold it (``test_topics.py``): every 300 Hz stream is read with a history of at
least one second of samples, so a reader that stalls for less than that loses nothing; and
the recorder's profile for each topic (:func:`recorder_profiles`) matches every publisher
the graph has on it, the user's ``ros2 topic pub`` included.
"""
from __future__ import annotations

from dataclasses import dataclass

import yaml


@dataclass(frozen=True)
class QosSpec:
    """A QoS profile in rosbag2's vocabulary (history, depth, reliability, durability)."""

    reliability: str  # "reliable" | "best_effort"
    durability: str   # "volatile" | "transient_local"
    history: str      # "keep_last" | "keep_all"
    depth: int

    def rosbag2(self) -> dict:
        """The profile as one entry of rosbag2's ``offered_qos_profiles`` (metadata v9)."""
        inf = {"sec": 9223372036, "nsec": 854775807}
        return {"history": self.history, "depth": self.depth, "reliability": self.reliability,
                "durability": self.durability, "deadline": dict(inf), "lifespan": dict(inf),
                "liveliness": "automatic", "liveliness_lease_duration": dict(inf),
                "avoid_ros_namespace_conventions": False}

    def compatible_with(self, offered: QosSpec) -> bool:
        """True if a reader with this profile matches a writer offering ``offered`` (DDS
        request/offer rules: a reliable reader needs a reliable writer, a transient-local
        reader a transient-local writer)."""
        return ((self.reliability == "best_effort" or offered.reliability == "reliable")
                and (self.durability == "volatile" or offered.durability == "transient_local"))

    def rosbag2_override(self) -> dict:
        """The profile as one entry of ``ros2 bag record --qos-profile-overrides-path``."""
        return {"history": self.history, "depth": self.depth, "reliability": self.reliability,
                "durability": self.durability}


#: Samples per second of the device's telemetry and of the observer's estimates [Hz].
STREAM_RATE = 300
#: 300 Hz streams: best effort (a late sample is worthless, a resent one worse) with one
#: second of history, so a reader that stalls briefly catches up instead of dropping.
STREAM = QosSpec("best_effort", "volatile", "keep_last", STREAM_RATE)
#: Commands and slow state: reliable, keep last 10.
RELIABLE = QosSpec("reliable", "volatile", "keep_last", 10)
#: Reference speed as the MPC node publishes it: reliable and latched, so a late
#: subscriber still gets the last value.
LATCHED = QosSpec("reliable", "transient_local", "keep_last", 1)
#: What ``ros2 topic pub`` offers unless told otherwise (rclpy's qos_profile_default).
TOPIC_PUB_DEFAULT = QosSpec("reliable", "volatile", "keep_last", 10)


@dataclass(frozen=True)
class Topic:
    name: str
    type: str
    qos: QosSpec
    publisher: str
    doc: str


TELEMETRY = Topic("telemetry", "hasel_wheel_msgs/msg/WheelTelemetry", STREAM, "driver | sim",
                  "device sample at 300 Hz: encoder, q, eta, HV monitor, faults")
JOINT_STATES = Topic("joint_states", "sensor_msgs/msg/JointState", STREAM, "driver | sim",
                     "wheel joint angle from the encoder [rad] (velocity left empty)")
COMMAND = Topic("command", "hasel_wheel_msgs/msg/ActuationCommand", RELIABLE, "mpc | open loop",
                "actuation input u = (n_a, phi_a, phi_d) for the next cycle")
STATE_ESTIMATE = Topic("state_estimate", "hasel_wheel_msgs/msg/HybridStateEstimate", STREAM,
                       "observer", "six hybrid states and the disturbance estimate at 300 Hz")
MPC_STATUS = Topic("mpc_status", "hasel_wheel_msgs/msg/MpcStatus", RELIABLE, "mpc",
                   "one record per MPC decision")
REFERENCE = Topic("reference_speed", "std_msgs/msg/Float64", LATCHED, "user | runner",
                  "speed reference xi2_r [rad/s]")
TRUE_STATE = Topic("sim/true_state", "hasel_wheel_msgs/msg/HybridStateEstimate", STREAM, "sim",
                   "the simulator's true hybrid state (ground truth, sim only)")
HV_REQUEST = Topic("hv_request", "std_msgs/msg/Bool", LATCHED, "mpc",
                   "false: switch HV off now (the control core gave up a stalled wheel)")
DIAGNOSTICS = Topic("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", RELIABLE, "every node",
                    "health: link, rates, HV state, deadline misses")

ALL = (TELEMETRY, JOINT_STATES, COMMAND, STATE_ESTIMATE, MPC_STATUS, REFERENCE, TRUE_STATE,
       HV_REQUEST, DIAGNOSTICS)


def qualified(topic: Topic, namespace: str = "") -> str:
    """Absolute topic name under ``namespace`` ('' or '/wheel0'); absolute names stay as they are."""
    if topic.name.startswith("/"):
        return topic.name
    ns = namespace.rstrip("/")
    if ns and not ns.startswith("/"):
        ns = "/" + ns
    return f"{ns}/{topic.name}"


#: Offered profiles each topic may see besides the table's own: the reference is sent by
#: users (``ros2 topic pub``, volatile) as well as by the MPC node (latched).
OTHER_PUBLISHERS: dict[str, tuple[QosSpec, ...]] = {"reference_speed": (TOPIC_PUB_DEFAULT,)}


def recorder_profile(topic: Topic) -> QosSpec:
    """The QoS the recorder subscribes to ``topic`` with: the topic's reliability, volatile
    (so latched and volatile publishers both match) and at least a second of history."""
    return QosSpec(topic.qos.reliability, "volatile", "keep_last",
                   max(topic.qos.depth, STREAM_RATE))


def recorder_profiles(namespaces: list[str]) -> dict[str, QosSpec]:
    """Absolute topic name -> recorder QoS for every topic of the wheels in ``namespaces``
    ('' = root); rosbag2 would otherwise pick the first publisher's durability and keep 10."""
    return {qualified(t, ns): recorder_profile(t) for ns in namespaces for t in ALL}


def recorder_overrides_yaml(namespaces: list[str]) -> str:
    """:func:`recorder_profiles` as the YAML that ``ros2 bag record
    --qos-profile-overrides-path`` reads (topic name -> history, depth, reliability,
    durability)."""
    return yaml.safe_dump({name: p.rosbag2_override()
                           for name, p in recorder_profiles(namespaces).items()}, sort_keys=True)
