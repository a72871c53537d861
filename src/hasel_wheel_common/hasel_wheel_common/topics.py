"""The wheel's topics: names (relative, so they follow the node's namespace), types and QoS.

This table is the single source for the driver node, the sim node, the embedded runner's
bags and the README.  QoS is described with plain strings so the core needs no rclpy;
nodes turn it into ``rclpy.qos.QoSProfile`` and bags into rosbag2's metadata.
"""
from __future__ import annotations

from dataclasses import dataclass


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


#: rclpy's qos_profile_sensor_data: best effort, keep last 5.
SENSOR = QosSpec("best_effort", "volatile", "keep_last", 5)
#: Commands and slow state: reliable, keep last 10.
RELIABLE = QosSpec("reliable", "volatile", "keep_last", 10)
#: Reference speed: reliable and latched, so a late subscriber still gets the last value.
LATCHED = QosSpec("reliable", "transient_local", "keep_last", 1)


@dataclass(frozen=True)
class Topic:
    name: str
    type: str
    qos: QosSpec
    publisher: str
    doc: str


TELEMETRY = Topic("telemetry", "hasel_wheel_msgs/msg/WheelTelemetry", SENSOR, "driver | sim",
                  "device sample at 300 Hz: encoder, q, eta, HV monitor, faults")
JOINT_STATES = Topic("joint_states", "sensor_msgs/msg/JointState", SENSOR, "driver | sim",
                     "wheel joint angle from the encoder [rad] (velocity left empty)")
COMMAND = Topic("command", "hasel_wheel_msgs/msg/ActuationCommand", RELIABLE, "mpc | open loop",
                "actuation input u = (n_a, phi_a, phi_d) for the next cycle")
STATE_ESTIMATE = Topic("state_estimate", "hasel_wheel_msgs/msg/HybridStateEstimate", SENSOR,
                       "observer", "six hybrid states and the disturbance estimate at 300 Hz")
MPC_STATUS = Topic("mpc_status", "hasel_wheel_msgs/msg/MpcStatus", RELIABLE, "mpc",
                   "one record per MPC decision")
REFERENCE = Topic("reference_speed", "std_msgs/msg/Float64", LATCHED, "user | runner",
                  "speed reference xi2_r [rad/s]")
TRUE_STATE = Topic("sim/true_state", "hasel_wheel_msgs/msg/HybridStateEstimate", SENSOR, "sim",
                   "the simulator's true hybrid state (ground truth, sim only)")
DIAGNOSTICS = Topic("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", RELIABLE, "every node",
                    "health: link, rates, HV state, deadline misses")

ALL = (TELEMETRY, JOINT_STATES, COMMAND, STATE_ESTIMATE, MPC_STATUS, REFERENCE, TRUE_STATE,
       DIAGNOSTICS)


def qualified(topic: Topic, namespace: str = "") -> str:
    """Absolute topic name under ``namespace`` ('' or '/wheel0'); absolute names stay as they are."""
    if topic.name.startswith("/"):
        return topic.name
    ns = namespace.rstrip("/")
    if ns and not ns.startswith("/"):
        ns = "/" + ns
    return f"{ns}/{topic.name}"
