"""The device rules of protocol v1.1 section 4, decided on the device's own readings: what the
wheel's Teensy does on every tick, in Python.

This is the reference the C++ firmware core (``firmware/core``) is held to, tick for tick and
byte for byte (``test_firmware_lockstep.py``); :mod:`.firmware` wires it to a plant for the
virtual Teensy.  Integer counts, binary32 angles and the order of every step follow
``docs/protocol.md`` sections 4 and 6 exactly, so the two implementations cannot drift apart
silently.  Pure: no I/O, no clock of its own (the caller passes device time in us).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from hasel_wheel_common import protocol as P

#: HV converter output while enabled [V] and the allowed deviation from it [1] (fault bit 2).
HV_SETPOINT_V = np.float32(9000.0)
HV_BAND = np.float32(0.10)
#: The HV monitor is not checked for this long after HV is enabled [us] (the converter ramps).
HV_SETTLE_US = 100_000
#: Supply current above which HV trips [A] (fault bit 4); the converter gives at most 3 mA.
CURRENT_LIMIT_A = np.float32(2.0e-3)
#: Encoder counts per radian, 512/pi, as binary32 (section 6: switching angles in counts).
COUNTS_PER_RAD = np.float32(512.0 / math.pi)
COUNTS_PER_SECTOR = 64        # pi/8 rad
PADS = 16
ENCODER_COUNTS = 1024
#: A reading further than this from the last good one, per tick since it, is a glitch [counts].
MAX_STEP_COUNTS = 64
#: Bad readings in a row after which the position is lost (HV off, next reading taken) [ticks].
LOST_AFTER = 10
#: Host bytes the device buffers between two ticks [bytes].
RX_BUFFER = 512
HOST_TYPES = frozenset({P.COMMAND, P.HEARTBEAT, P.HV, P.ESTOP, P.CONFIG, P.CLEAR_ESTOP, P.START})


class Sensors(NamedTuple):
    """What the board reads at the start of a tick."""

    encoder_raw: int = 0           # 0..1023
    encoder_ok: bool = True        # False: the encoder read failed (parity, status bits)
    hv_monitor: float = 0.0        # [V], binary32
    current_monitor: float = 0.0   # [A], binary32


class Outputs(NamedTuple):
    """What the board applies until the next tick."""

    active_mask: int = 0           # bit i: actuator i gets HV (at most one bit)
    hv_supply: bool = False        # the HV converter's 24 V supply
    telemetry_rate_hz: int = 300   # tick rate from the next tick on


@dataclass
class Latched:
    """A command the device holds pending or has latched (its target pad)."""

    valid: bool = False
    seq: int = 0
    n_a: int = 0
    phi_a: float = 0.0             # [rad], binary32 as received
    phi_d: float = 0.0
    sector: int = 0                # unwrapped sector N of the target pad
    on_count: int = 0              # switch on when the unwrapped count reaches this (a START:
                                   # the count it switched on at)
    off_count: int = 0             # switch off when it reaches this
    now: bool = False              # a START latched it (rule 8), switching the pad on at once


@dataclass
class DeviceState:
    """Everything the device holds; equal field by field to the C++ core's after every tick."""

    hv_enabled: bool = False
    estop: bool = False
    faults: int = 0
    counter: int = 0               # counter of the last frame sent
    sample_seq: int = 0
    last_host_us: int = 0          # time of the tick that handled the last valid host frame
    hv_on_since_us: int = 0
    on_since_us: int = 0           # switch-on time of the pad that is on
    q: bool = False
    eta_unwrapped: int = 0
    last_command_seq: int = 0
    pending: Latched = field(default_factory=Latched)
    target: Latched = field(default_factory=Latched)
    telemetry_rate_hz: int = 300
    watchdog_ms: int = 100
    max_on_ms: int = 2000
    drain_mode: int = 0


def angle_counts(phi: float) -> int:
    """Smallest count c >= phi * 512/pi (phi [rad]), the product in binary32, within one
    sector either way (section 6)."""
    c = math.ceil(float(np.float32(phi) * COUNTS_PER_RAD))
    return max(-COUNTS_PER_SECTOR, min(COUNTS_PER_SECTOR, c))


def start_sector(n_a: int, phi_a: float, phi_d: float, c: int) -> int | None:
    """Rule 8 in counts (section 6): the unwrapped sector N = n_a (mod 16) with
    64 N + a(phi_a) <= c < 64 N + a(phi_d), c the unwrapped count and phi [rad]; None when
    pad n_a is not in contact within [phi_a, phi_d).  The window is at most 64 counts wide,
    so only the largest N = n_a (mod 16) with 64 N + a(phi_a) <= c can fit.
    ``test_device_rules.py::test_a_start_*`` holds it."""
    top = (c - angle_counts(phi_a)) // COUNTS_PER_SECTOR
    n = top - (top - n_a) % PADS
    return n if c < n * COUNTS_PER_SECTOR + angle_counts(phi_d) else None


class EncoderTrack:
    """10-bit readings unwrapped into a count that grows across turns; a glitched reading
    (a step beyond :data:`MAX_STEP_COUNTS` per tick) is not taken and cannot break it."""

    def __init__(self) -> None:
        self.started = False
        self.unwrapped = 0
        self.last_raw = 0
        self.bad_run = 0

    def update(self, raw: int, ok: bool) -> tuple[bool, bool]:
        """Take one reading; returns (good, lost): good when taken, lost after
        :data:`LOST_AFTER` bad readings in a row."""
        if not ok or not 0 <= raw < ENCODER_COUNTS:
            return self._bad()
        d = (raw - self.last_raw + ENCODER_COUNTS // 2) % ENCODER_COUNTS - ENCODER_COUNTS // 2
        if not self.started or self.bad_run >= LOST_AFTER:
            self.unwrapped = self.unwrapped + d if self.started else raw
            self.started = True
        elif abs(d) > MAX_STEP_COUNTS * (self.bad_run + 1):
            return self._bad()
        else:
            self.unwrapped += d
        self.last_raw = raw
        self.bad_run = 0
        return True, False

    def _bad(self) -> tuple[bool, bool]:
        self.bad_run = min(self.bad_run + 1, 0xFFFF)
        return False, self.bad_run >= LOST_AFTER


class DeviceCore:
    """The device's decisions, tick by tick: feed host bytes with :meth:`receive`, call
    :meth:`tick` at every timer tick with the sensor readings; it returns the frames to send
    and what to switch."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Power-up (rule 1): HV off, nothing latched, estop clear, default configuration."""
        self.s = DeviceState()
        self.encoder = EncoderTrack()
        self.decoder = P.FrameDecoder()
        self._rx = bytearray()
        self._now = 0
        self._tx: list[bytes] = []
        self._started = False          # a START switched a pad on at this tick

    def state(self) -> DeviceState:
        """A copy of the device state."""
        return dataclasses.replace(self.s, pending=dataclasses.replace(self.s.pending),
                                   target=dataclasses.replace(self.s.target))

    def receive(self, data: bytes) -> int:
        """Buffer host bytes for the next tick; returns how many were taken (the rest waits
        in the USB buffers while the receive buffer of :data:`RX_BUFFER` bytes is full)."""
        n = min(len(data), RX_BUFFER - len(self._rx))
        self._rx += data[:n]
        return n

    def tick(self, now_us: int, sensors: Sensors) -> tuple[list[bytes], Outputs]:
        """One tick at device time ``now_us``: host frames (each answered), rules 4-6, the
        encoder reading and at most one switch, then one TELEMETRY frame.  Returns the wire
        frames sent, in order, and the outputs to apply."""
        self._now = now_us
        self._tx = []
        self._started = False
        for frame in self.decoder.feed(bytes(self._rx)):
            if frame.type in HOST_TYPES:
                self._handle(frame)
        self._rx.clear()
        self._interlocks(now_us, sensors)
        s = self.s
        first = not self.encoder.started
        good, lost = self.encoder.update(sensors.encoder_raw, sensors.encoder_ok)
        if good:
            s.faults &= ~P.F_ENCODER
            if first:
                s.eta_unwrapped = self.encoder.unwrapped // COUNTS_PER_SECTOR
            self._switching(now_us, self.encoder.unwrapped)
        else:
            s.faults |= P.F_ENCODER
            if lost:
                self._hv_off()
        s.sample_seq = (s.sample_seq + 1) & 0xFFFFFFFF
        out = self.outputs()
        self._send(P.Telemetry(
            device_time_us=now_us, sample_seq=s.sample_seq,
            encoder_raw=sensors.encoder_raw & 0x3FF, encoder_unwrapped=self.encoder.unwrapped,
            q=int(s.q), eta=s.eta_unwrapped % PADS, eta_unwrapped=s.eta_unwrapped,
            active_mask=out.active_mask, hv_monitor=sensors.hv_monitor,
            current_monitor=sensors.current_monitor, last_command_seq=s.last_command_seq,
            fault_flags=s.faults))
        return self._tx, out

    def outputs(self) -> Outputs:
        """The pad mask, HV supply and tick rate the device drives now."""
        s = self.s
        mask = 1 << (s.eta_unwrapped % PADS) if s.hv_enabled and s.q else 0
        return Outputs(mask, s.hv_enabled, s.telemetry_rate_hz)

    # -- host frames ----------------------------------------------------------------------
    def _send(self, msg: P.Message) -> None:
        self.s.counter = (self.s.counter + 1) & 0xFFFF
        self._tx.append(P.encode(msg, self.s.counter))

    def _handle(self, frame: P.Frame) -> None:
        s = self.s
        s.last_host_us = self._now
        m = frame.message
        seq = m.command_seq if frame.type in (P.COMMAND, P.START) else 0
        reason = 0
        if frame.type in (P.COMMAND, P.START):
            reason = P.check_command(m.n_a, m.phi_a, m.phi_d) or \
                (P.R_ESTOP if s.estop else 0) or (0 if s.hv_enabled else P.R_HV_DISABLED)
            if not reason and frame.type == P.START:
                reason = self._start(m)
            elif not reason:
                s.pending = Latched(True, m.command_seq, m.n_a, m.phi_a, m.phi_d)
            if reason:
                s.faults |= P.F_REJECTED
            else:
                s.faults &= ~(P.F_REJECTED | P.F_MAX_ON)
        elif frame.type == P.HV:
            if m.enable > 1:
                reason = P.R_CONFIG
            elif m.enable == 0:
                self._hv_off()
            elif s.estop:
                reason = P.R_ESTOP
            else:
                if not s.hv_enabled:
                    s.hv_on_since_us = self._now
                s.hv_enabled = True
                s.faults &= ~(P.F_WATCHDOG | P.F_HV_MONITOR | P.F_OVERCURRENT)
        elif frame.type == P.ESTOP:
            self._hv_off()
            s.estop = True
            s.faults |= P.F_ESTOP
        elif frame.type == P.CLEAR_ESTOP:
            s.estop = False
            s.faults &= ~P.F_ESTOP
        elif frame.type == P.CONFIG:
            reason = P.check_config(m)
            if not reason:
                s.telemetry_rate_hz, s.watchdog_ms, s.max_on_ms, s.drain_mode = m
        if reason:
            self._send(P.Reject(frame.type, frame.counter, seq, reason))
        else:
            self._send(P.Ack(frame.type, frame.counter, seq))

    def _start(self, m: P.Start) -> int:
        """Rule 8 past the checks it shares with COMMAND: 0 when pad n_a switched on now (the
        pending command cleared, the START latched in its sector), else the REJECT reason:
        R_ACTUATOR_ON while q = 1, R_NOT_IN_CONTACT while the position is lost or the pad's
        contact angle on the last taken count is outside [phi_a, phi_d)."""
        s, enc = self.s, self.encoder
        if s.q:
            return P.R_ACTUATOR_ON
        n = start_sector(m.n_a, m.phi_a, m.phi_d, enc.unwrapped) \
            if enc.started and enc.bad_run < LOST_AFTER else None
        if n is None:
            return P.R_NOT_IN_CONTACT
        s.pending.valid = False
        s.target = Latched(True, m.command_seq, m.n_a, m.phi_a, m.phi_d, n, enc.unwrapped,
                           n * COUNTS_PER_SECTOR + angle_counts(m.phi_d), True)
        s.eta_unwrapped = n
        s.last_command_seq = m.command_seq
        s.q = True
        s.on_since_us = self._now
        self._started = True
        return 0

    # -- rules 3-6 ------------------------------------------------------------------------
    def _pads_off(self) -> None:
        s = self.s
        s.q = False
        s.target.valid = False
        s.pending.valid = False

    def _hv_off(self) -> None:
        self.s.hv_enabled = False
        self._pads_off()

    def _interlocks(self, now_us: int, sensors: Sensors) -> None:
        s = self.s
        if s.hv_enabled and now_us - s.last_host_us >= s.watchdog_ms * 1000:     # rule 4
            self._hv_off()
            s.faults |= P.F_WATCHDOG
        if s.q and now_us - s.on_since_us >= s.max_on_ms * 1000:                  # rule 5
            self._pads_off()
            s.faults |= P.F_MAX_ON
        if s.hv_enabled:                                                         # section 6
            if not np.float32(sensors.current_monitor) <= CURRENT_LIMIT_A:
                self._hv_off()
                s.faults |= P.F_OVERCURRENT
            elif now_us - s.hv_on_since_us >= HV_SETTLE_US and not \
                    abs(np.float32(sensors.hv_monitor) - HV_SETPOINT_V) <= HV_BAND * HV_SETPOINT_V:
                self._hv_off()
                s.faults |= P.F_HV_MONITOR

    def _latch(self, u: Latched, count: int) -> None:
        """Rule 3: the first future switch-on of pad n_a, the smallest N = n_a (mod 16) with
        64 N + a >= count, a the activation angle in counts."""
        a = angle_counts(u.phi_a)
        m = -((a - count) // COUNTS_PER_SECTOR)         # ceil((count - a) / 64)
        n = m + (u.n_a - m) % PADS
        s = self.s
        s.target = dataclasses.replace(u, valid=True, sector=n, on_count=n * COUNTS_PER_SECTOR + a,
                                       off_count=n * COUNTS_PER_SECTOR + angle_counts(u.phi_d))
        s.eta_unwrapped = n
        s.last_command_seq = u.seq

    def _switching(self, now_us: int, c: int) -> None:
        s = self.s
        if self._started:                            # a START was this tick's one switch
            return
        if s.q:
            if c >= s.target.off_count:              # switch off; latch what is pending
                s.q = False
                s.target.valid = False
                if s.pending.valid:
                    self._latch(s.pending, c)
                    s.pending.valid = False
            return
        if s.pending.valid:                          # idle, or a target not yet on: latch now
            self._latch(s.pending, c)
            s.pending.valid = False
        if s.target.valid and s.hv_enabled and c >= s.target.on_count:
            s.q = True
            s.on_since_us = now_us

