"""Plain-Python telemetry and command records, and their message dictionaries.

The driver (real wheel) and the simulator both produce :class:`TelemetrySample`; the MPC
and open-loop schedules produce :class:`Command`.  ``*_msg`` functions turn them into the
dict form of our ROS messages, which the bag writer encodes and nodes copy into rclpy
messages field by field.
"""
from __future__ import annotations

import math
import struct
from typing import Any, NamedTuple, Sequence

ENCODER_COUNTS = 1024
#: One encoder count [rad] (10-bit absolute encoder).
ENCODER_COUNT = 2.0 * math.pi / ENCODER_COUNTS
MODE_ACCELERATE = 0
MODE_BRAKE = 1


class TelemetrySample(NamedTuple):
    """One 300 Hz device sample (fields as in ``WheelTelemetry.msg``; SI units).

    Immutable; ``sample._replace(t=...)`` gives a copy with a field changed.
    """

    t: float                    # sample time [s] (host receive time; simulated time in the sim)
    device_time_us: int         # device clock [us]
    sequence: int               # device sample counter
    encoder_raw: int            # 0..1023
    angle: float                # unwrapped encoder angle [rad]
    q: int                      # 0/1
    eta: int                    # actuator of interest 0..15
    eta_unwrapped: int          # unwrapped sector of the actuator of interest
    active_mask: int            # bit i = HV on actuator i
    hv_monitor: float           # [V]
    current_monitor: float      # [A]
    last_command_sequence: int
    fault_flags: int = 0


class Command(NamedTuple):
    """Actuation input u = (n_a, phi_a [rad], phi_d [rad]) with its sequence number.

    ``now`` False: pad n_a switches on when its contact angle reaches phi_a (protocol COMMAND).
    ``now`` True: pad n_a switches on at once if its contact angle already lies in
    [phi_a, phi_d), which is how a standing wheel starts (protocol v1.1 START, docs/protocol.md).
    """

    n_a: int
    phi_a: float
    phi_d: float
    sequence: int = 0
    now: bool = False

    @property
    def mode(self) -> int:
        return MODE_BRAKE if self.phi_d <= 0.0 and self.phi_a < 0.0 else MODE_ACCELERATE


def pad_edges(q: int, eta_unwrapped: int, prev_q: int, prev_eta: int) -> tuple[bool, bool]:
    """(switched_on, switched_off) between the previous sample (``prev_q``, ``prev_eta``) and
    this one (``q``, ``eta_unwrapped``): q 0/1, unwrapped pad indices.

    A new pad with q = 1 in both samples means both edges happened in between: the samples
    with q = 0 were lost.  Between two pads there can be a single such sample (a small
    phi_a at speed, e.g. 0.5 deg after 22 deg is one tick at 2.6 rad/s), and one lost sample
    would otherwise leave the switch-on unseen and the wheel without a next command.
    """
    jumped = q == 1 and prev_q == 1 and eta_unwrapped != prev_eta
    return (q == 1 and prev_q == 0) or jumped, (q == 0 and prev_q == 1) or jumped


class PadEdges:
    """Reads :func:`pad_edges` from sample to sample; before the first sample, q = 0."""

    def __init__(self) -> None:
        self.q = 0
        self.eta: int | None = None

    def step(self, q: int, eta_unwrapped: int) -> tuple[bool, bool]:
        """(switched_on, switched_off) since the previous sample; remembers this one."""
        prev_eta = eta_unwrapped if self.eta is None else self.eta
        edges = pad_edges(q, eta_unwrapped, self.q, prev_eta)
        self.q, self.eta = q, eta_unwrapped
        return edges


def header(t: float, frame_id: str = "") -> dict:
    """std_msgs/Header dict for time t [s] (t >= 0)."""
    sec = math.floor(t)
    nsec = int(round((t - sec) * 1e9))
    if nsec >= 1_000_000_000:
        sec, nsec = sec + 1, nsec - 1_000_000_000
    return {"stamp": {"sec": int(sec), "nanosec": nsec}, "frame_id": frame_id}


def telemetry_msg(s: TelemetrySample, frame_id: str = "wheel") -> dict:
    """hasel_wheel_msgs/msg/WheelTelemetry as a dict."""
    return {"header": header(s.t, frame_id), "device_time_us": s.device_time_us,
            "sequence": s.sequence, "encoder_raw": s.encoder_raw, "angle": s.angle, "q": s.q,
            "eta": s.eta, "eta_unwrapped": s.eta_unwrapped, "active_mask": s.active_mask,
            "hv_monitor": s.hv_monitor, "current_monitor": s.current_monitor,
            "last_command_sequence": s.last_command_sequence, "fault_flags": s.fault_flags}


def telemetry_from_msg(msg) -> TelemetrySample:
    """The core's sample of a WheelTelemetry message (an rclpy message, a message decoded from
    a bag, or anything with its fields as attributes).  ``t`` is the device clock
    (device_time_us * 1e-6 s), free of the host's receive jitter."""
    return TelemetrySample(
        msg.device_time_us * 1e-6, int(msg.device_time_us), int(msg.sequence),
        int(msg.encoder_raw), float(msg.angle), int(msg.q), int(msg.eta), int(msg.eta_unwrapped),
        int(msg.active_mask), float(msg.hv_monitor), float(msg.current_monitor),
        int(msg.last_command_sequence), int(msg.fault_flags))


class _Fields:
    def __init__(self, d: dict) -> None:
        self.__dict__.update(d)


def from_device(m: Any) -> TelemetrySample:
    """The sample of a device TELEMETRY message (``protocol.Telemetry``): the device clock
    as ``t`` [s], the unwrapped encoder count as ``angle`` [rad]."""
    return TelemetrySample(
        t=m.device_time_us * 1e-6, device_time_us=m.device_time_us, sequence=m.sample_seq,
        encoder_raw=m.encoder_raw, angle=m.encoder_unwrapped * ENCODER_COUNT, q=m.q, eta=m.eta,
        eta_unwrapped=m.eta_unwrapped, active_mask=m.active_mask, hv_monitor=m.hv_monitor,
        current_monitor=m.current_monitor, last_command_sequence=m.last_command_seq,
        fault_flags=m.fault_flags)


def as_received(s: TelemetrySample) -> TelemetrySample:
    """``s`` as a node receives it through a WheelTelemetry message: the device clock as
    ``t`` and the monitors as float32.  The embedded runner's controller sees this, so a
    replay from the bag computes exactly what the run computed."""
    m = telemetry_msg(s)
    for name in ("hv_monitor", "current_monitor"):       # float32 fields
        m[name] = struct.unpack("<f", struct.pack("<f", m[name]))[0]
    return telemetry_from_msg(_Fields(m))


def joint_state_msg(s: TelemetrySample, joint: str = "wheel_joint") -> dict:
    """sensor_msgs/msg/JointState with the encoder angle [rad] (no velocity: see the observer)."""
    return {"header": header(s.t, ""), "name": [joint], "position": [s.angle], "velocity": [],
            "effort": []}


def command_msg(c: Command, t: float) -> dict:
    """hasel_wheel_msgs/msg/ActuationCommand as a dict."""
    return {"header": header(t, ""), "sequence": c.sequence, "n_a": c.n_a, "phi_a": c.phi_a,
            "phi_d": c.phi_d, "mode": c.mode, "now": bool(c.now)}


def state_msg(t: float, xi1: float, xi2: float, q: int, act_counter: float,
              deact_counter: float, eta_unwrapped: int, xi2_stddev: float = 0.0, quality: float = 1.0,
              accel_disturbance: float = 0.0,
              accel_coefficients: Sequence[float] = (0.0,) * 5) -> dict:
    """hasel_wheel_msgs/msg/HybridStateEstimate as a dict.  ``accel_coefficients`` are the
    observer's (c, a, b, e, f) of a_d [rad/s^2] (observer.py); (c, a, b) leaves e, f at 0."""
    if len(accel_coefficients) not in (3, 5):
        raise ValueError(f"accel_coefficients: expected (c, a, b) or (c, a, b, e, f) [rad/s^2],"
                         f" got {len(accel_coefficients)} values")
    c = tuple(float(x) for x in accel_coefficients) + (0.0,) * (5 - len(accel_coefficients))
    return {"header": header(t, "wheel"), "xi1": xi1, "xi2": xi2, "q": q,
            "activation_counter": act_counter, "deactivation_counter": deact_counter,
            "eta": eta_unwrapped % 16, "eta_unwrapped": eta_unwrapped,
            "accel_disturbance": accel_disturbance,
            **dict(zip(ACCEL_FIELDS, c)),
            "xi2_stddev": xi2_stddev, "quality": quality}


#: The HybridStateEstimate fields of the observer's a_d coefficients (c, a, b, e, f).
ACCEL_FIELDS = ("accel_c", "accel_a", "accel_b", "accel_e", "accel_f")


def accel_coefficients_of(m: Any) -> tuple[float, ...] | None:
    """(c, a, b, e, f) [rad/s^2] from a HybridStateEstimate message, or None when it predates
    these fields (a bag recorded before them carries only ``accel_disturbance``)."""
    if not all(hasattr(m, f) for f in ACCEL_FIELDS):
        return None
    return tuple(float(getattr(m, f)) for f in ACCEL_FIELDS)


def mpc_status_msg(t: float, c: Command, reference: float, predicted: float, cost: float,
                   compute_time: float, slack: float, candidates: int, missed: bool,
                   braking: bool, disturbance: float = 0.0) -> dict:
    """hasel_wheel_msgs/msg/MpcStatus as a dict (speeds rad/s, times s; ``disturbance`` the
    estimator's d [rad/s] the decision used)."""
    return {"header": header(t, ""), "command": command_msg(c, t), "reference_speed": reference,
            "predicted_speed": predicted, "disturbance": disturbance, "cost": cost, "compute_time": compute_time,
            "deadline_slack": slack, "candidates_evaluated": candidates,
            "deadline_missed": missed, "braking": braking}
