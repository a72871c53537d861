"""Codec of the wheel's serial protocol, version 1.1 (``docs/protocol.md``): pure, no I/O, no ROS.

Frames are ``COBS(version, type, counter, payload, crc16) + 0x00``.  :class:`FrameDecoder`
takes bytes in any chunking, never raises on garbage, resynchronises at the next delimiter and
counts what it drops.  Messages are plain NamedTuples packed with :mod:`struct`.
"""
from __future__ import annotations

import math
import struct
from binascii import crc_hqx
from dataclasses import dataclass, field
from typing import NamedTuple, Union

from cobs import cobs

VERSION = 1                  # the version byte of every frame; v1.1 adds START, not a byte
MAX_RAW = 64                 # raw frame bytes (header + payload + crc)
MAX_STUFFED = MAX_RAW + 2    # COBS adds at most one byte per 254, plus one
SECTOR = math.pi / 8.0
ANGLE_TOLERANCE = 1e-6       # slack on +-pi/8 [rad]: float32(pi/8) exceeds pi/8 by ~4e-9

# message types
TELEMETRY, ACK, REJECT = 0x01, 0x02, 0x03
COMMAND, HEARTBEAT, HV, ESTOP, CONFIG, CLEAR_ESTOP = 0x10, 0x11, 0x12, 0x13, 0x14, 0x15
START = 0x16                 # v1.1; a v1.0 device drops it as an unknown type, unanswered

# REJECT reasons
R_N_A, R_ANGLE, R_ORDER, R_HV_DISABLED, R_ESTOP, R_CONFIG = 1, 2, 3, 4, 5, 6
R_NOT_IN_CONTACT = 7         # v1.1 START: pad n_a not in contact within [phi_a, phi_d), or position lost
R_ACTUATOR_ON = 8            # v1.1 START: an actuator is on (q = 1)

# fault flags (as in WheelTelemetry.msg)
F_WATCHDOG, F_HV_MONITOR, F_OVERCURRENT, F_MAX_ON, F_ENCODER, F_REJECTED, F_ESTOP = \
    1, 2, 4, 8, 16, 32, 64


class Telemetry(NamedTuple):
    device_time_us: int
    sample_seq: int
    encoder_raw: int
    encoder_unwrapped: int
    q: int
    eta: int
    eta_unwrapped: int
    active_mask: int
    hv_monitor: float
    current_monitor: float
    last_command_seq: int
    fault_flags: int


class Ack(NamedTuple):
    acked_type: int
    acked_counter: int
    command_seq: int


class Reject(NamedTuple):
    rejected_type: int
    rejected_counter: int
    command_seq: int
    reason: int


class Command(NamedTuple):
    command_seq: int
    n_a: int
    phi_a: float
    phi_d: float


class Start(NamedTuple):
    """v1.1 START: switch pad n_a on now if its contact angle lies in [phi_a, phi_d) [rad]
    (protocol rule 8); the payload is COMMAND's."""

    command_seq: int
    n_a: int
    phi_a: float
    phi_d: float


class Heartbeat(NamedTuple):
    host_time_us: int


class Hv(NamedTuple):
    enable: int


class Estop(NamedTuple):
    pass


class Config(NamedTuple):
    telemetry_rate_hz: int = 300
    watchdog_ms: int = 100
    max_on_ms: int = 2000
    drain_mode: int = 0


class ClearEstop(NamedTuple):
    pass


Message = Union[Telemetry, Ack, Reject, Command, Start, Heartbeat, Hv, Estop, Config, ClearEstop]

#: type -> (struct format of the payload, message class)
LAYOUT: dict[int, tuple[struct.Struct, type]] = {
    TELEMETRY: (struct.Struct("<QIHiBBiHffII"), Telemetry),
    ACK: (struct.Struct("<BHI"), Ack),
    REJECT: (struct.Struct("<BHIB"), Reject),
    COMMAND: (struct.Struct("<IBff"), Command),
    HEARTBEAT: (struct.Struct("<Q"), Heartbeat),
    HV: (struct.Struct("<B"), Hv),
    ESTOP: (struct.Struct("<"), Estop),
    CONFIG: (struct.Struct("<HHHB"), Config),
    CLEAR_ESTOP: (struct.Struct("<"), ClearEstop),
    START: (struct.Struct("<IBff"), Start),
}
TYPE_OF = {cls: t for t, (_, cls) in LAYOUT.items()}
_HEADER = struct.Struct("<BBH")


class ProtocolError(ValueError):
    """A message cannot be encoded (a value does not fit its field)."""


def crc16(data: bytes) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF); check value of b'123456789' is 0x29B1."""
    return crc_hqx(data, 0xFFFF)


def encode(msg: Message, counter: int) -> bytes:
    """The wire bytes of one frame: COBS(raw frame) + b'\\x00'."""
    mtype = TYPE_OF[type(msg)]
    fmt, _ = LAYOUT[mtype]
    try:
        raw = _HEADER.pack(VERSION, mtype, counter & 0xFFFF) + fmt.pack(*msg)
    except struct.error as exc:
        raise ProtocolError(f"{type(msg).__name__} {msg}: a value does not fit its field ({exc})") from exc
    raw += struct.pack("<H", crc16(raw))
    return cobs.encode(raw) + b"\x00"


class Frame(NamedTuple):
    """A decoded frame: its type, the sender's counter and the message."""

    type: int
    counter: int
    message: Message


@dataclass
class DecoderStats:
    """What a decoder delivered and what it dropped, by cause."""

    frames: int = 0
    crc_errors: int = 0
    framing_errors: int = 0
    oversize: int = 0
    version_errors: int = 0
    type_errors: int = 0
    length_errors: int = 0
    sequence_gaps: int = 0
    restarts: int = 0
    bytes: int = 0

    @property
    def dropped(self) -> int:
        return (self.crc_errors + self.framing_errors + self.oversize + self.version_errors
                + self.type_errors + self.length_errors)


@dataclass
class FrameDecoder:
    """Incremental decoder: ``feed(chunk) -> [Frame, ...]``.  Never raises on input bytes."""

    stats: DecoderStats = field(default_factory=DecoderStats)
    _buf: bytearray = field(default_factory=bytearray)
    _discarding: bool = False
    _last_counter: int | None = None

    def feed(self, data: bytes) -> list[Frame]:
        """Decode every complete frame in ``data`` (plus what earlier calls left over)."""
        self.stats.bytes += len(data)
        out: list[Frame] = []
        parts = data.split(b"\x00")
        for i, part in enumerate(parts):
            last = i == len(parts) - 1
            if self._discarding:
                if not last:
                    self._discarding = False  # the oversize chunk ended here
                continue
            self._buf += part
            if len(self._buf) > MAX_STUFFED:
                self.stats.oversize += 1
                self._buf.clear()
                self._discarding = last  # keep dropping until the next delimiter
                continue
            if last:
                break
            if self._buf:
                frame = self._decode(bytes(self._buf))
                if frame is not None:
                    out.append(frame)
                self._buf.clear()
        return out

    def _decode(self, chunk: bytes) -> Frame | None:
        st = self.stats
        try:
            raw = cobs.decode(chunk)
        except cobs.DecodeError:
            st.framing_errors += 1
            return None
        if len(raw) < _HEADER.size + 2:
            st.framing_errors += 1
            return None
        if crc16(raw[:-2]) != struct.unpack_from("<H", raw, len(raw) - 2)[0]:
            st.crc_errors += 1
            return None
        version, mtype, counter = _HEADER.unpack_from(raw)
        if version != VERSION:
            st.version_errors += 1
            return None
        layout = LAYOUT.get(mtype)
        if layout is None:
            st.type_errors += 1
            return None
        fmt, cls = layout
        if len(raw) - _HEADER.size - 2 != fmt.size:
            st.length_errors += 1
            return None
        msg = cls._make(fmt.unpack_from(raw, _HEADER.size))
        if self._last_counter is not None:
            gap = (counter - self._last_counter) & 0xFFFF
            if gap > 0x8000:       # far "behind": the peer restarted, nothing was lost
                st.restarts += 1
            elif gap > 1:
                st.sequence_gaps += gap - 1
        self._last_counter = counter
        st.frames += 1
        return Frame(mtype, counter, msg)


def check_command(n_a: int, phi_a: float, phi_d: float) -> int:
    """0 if u = (n_a, phi_a, phi_d) is acceptable, else the REJECT reason (protocol rule 7);
    the value check of COMMAND and START alike."""
    if not 0 <= n_a <= 15:
        return R_N_A
    for v in (phi_a, phi_d):
        if not math.isfinite(v) or abs(v) > SECTOR + ANGLE_TOLERANCE:
            return R_ANGLE
    if not phi_a < phi_d or (phi_a < 0.0 < phi_d):
        return R_ORDER
    return 0


def check_config(c: Config) -> int:
    """0 if the configuration is acceptable, else R_CONFIG (protocol rule 7)."""
    ok = 50 <= c.telemetry_rate_hz <= 1000 and 20 <= c.watchdog_ms <= 1000 \
        and 10 <= c.max_on_ms <= 10000 and c.drain_mode == 0
    return 0 if ok else R_CONFIG
