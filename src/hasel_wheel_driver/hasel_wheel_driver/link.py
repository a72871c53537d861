"""The host end of the serial link (protocol v1.1), without ROS.

:class:`DriverCore` owns the port and a reader thread, so nothing ever blocks a ROS executor.
The thread decodes frames as they arrive and hands each telemetry sample to a callback.  It
sends heartbeats and reconnects with backoff when the device disappears.  HV is switched off
whenever there is doubt: on a stale or lost link it sends ESTOP and then HV(0), and
:meth:`shutdown` does the same, ending on HV(0).  A START (a :class:`Command` with ``now``)
that the device leaves unanswered marks it as v1.0, which has no START (protocol section 5).
"""
from __future__ import annotations

import select
import threading
import time
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Callable

import serial

from hasel_wheel_common import protocol as P
from hasel_wheel_common.samples import Command, TelemetrySample, from_device


class RefusalCode(IntEnum):
    """Why :meth:`DriverCore.send_command` sent nothing: the protocol's reject reasons for a
    command that breaks its ranges, and three of the host's own."""

    N_A = P.R_N_A              # n_a outside 0..15
    ANGLE = P.R_ANGLE          # an angle not finite or outside [-pi/8, pi/8]
    ORDER = P.R_ORDER          # not phi_a < phi_d on one side of 0
    NO_LINK = 100              # no port open
    CLOSING = 101              # shutdown has begun: ESTOP and HV(0) are the last frames
    NO_START = 102             # a START to a v1.0 device, which left an earlier START unanswered


class Refusal(str):
    """The text of a refused command (for a reader), with its :attr:`code`."""

    code: RefusalCode

    def __new__(cls, text: str, code: RefusalCode) -> "Refusal":
        refusal = super().__new__(cls, text)
        refusal.code = code
        return refusal


@dataclass(frozen=True)
class LinkConfig:
    """Driver settings (times in seconds)."""

    port: str
    heartbeat_period: float = 0.02     # 50 Hz: 80 ms of slack inside the 100 ms watchdog
    link_timeout: float = 0.25         # no telemetry this long: the link is stale
    enable_hv_on_connect: bool = False  # send HV(1) after (re)connecting
    backoff_min: float = 0.05
    backoff_max: float = 0.25
    ack_timeout: float = 0.1
    device_config: P.Config | None = None  # sent after every (re)connect, before HV on


@dataclass
class LinkStats:
    connects: int = 0
    disconnects: int = 0
    stale_events: int = 0
    commands_sent: int = 0        # COMMAND and START frames
    starts_sent: int = 0
    starts_unanswered: int = 0    # STARTs with neither ACK nor REJECT within ack_timeout
    device_v1_0: bool = False     # this connection's device has no START (protocol 1.0)
    commands_rejected_locally: int = 0
    rejects: int = 0
    write_errors: int = 0
    callback_errors: int = 0
    watchdog_trips: int = 0       # rising edges of the device's watchdog fault bit
    samples: int = 0
    latencies: list[float] = field(default_factory=list)  # frame bytes read -> handed over [s]


class DriverCore:
    """Serial link to the wheel.  Call :meth:`start`, then :meth:`shutdown` when done."""

    def __init__(self, config: LinkConfig,
                 on_sample: Callable[[TelemetrySample], None] | None = None,
                 on_event: Callable[[str], None] | None = None,
                 clock: Callable[[], float] = time.monotonic,
                 keep_latencies: int = 100_000) -> None:
        self.config = config
        self.on_sample = on_sample or (lambda s: None)
        self.on_event = on_event or (lambda e: None)
        self.clock = clock
        self.stats = LinkStats()
        self.decoder = P.FrameDecoder()
        self.last_telemetry: P.Telemetry | None = None
        self.hv_requested = False
        self.connected = False
        self.stale = False
        self._keep = keep_latencies
        self._ser: serial.Serial | None = None
        self._counter = 0
        self._write_lock = threading.Lock()
        self._acks: dict[int, P.Message] = {}
        self._ack_cv = threading.Condition()
        self._starts: dict[int, float] = {}     # counter of a START awaiting its answer -> sent [s]
        self._running = False
        self._closing = False
        self.reader_failed: str | None = None   # set if the link thread died of an error
        self._thread: threading.Thread | None = None
        self._last_rx = 0.0
        self._loop_t = 0.0
        self._hb_thread: threading.Thread | None = None
        self._cmd_seq = 0
        self._rate_t0 = clock()
        self._rate_n0 = 0
        self.frame_rate = 0.0       # telemetry frames per second over the last >= 1 s

    # -- public API ------------------------------------------------------------------------
    def start(self) -> "DriverCore":
        self._running = True
        self._loop_t = self.clock()
        self._thread = threading.Thread(target=self._run, name="hasel-link", daemon=True)
        self._thread.start()
        self._hb_thread = threading.Thread(target=self._heartbeats, name="hasel-link-hb",
                                           daemon=True)
        self._hb_thread.start()
        return self

    #: Heartbeats stop when the reader loop has not turned for this long [s], so a wedged host
    #: still lets the device's watchdog switch HV off.
    READER_STALL = 0.5

    def _heartbeats(self) -> None:
        """Send HEARTBEAT every period from its own thread, so slow sample consumers (bag
        writing, a controller) cannot starve the device's watchdog."""
        while self._running:
            now = self.clock()
            if self.connected and not self._closing and now - self._loop_t < self.READER_STALL:
                self._write(P.Heartbeat(int(now * 1e6)))
            time.sleep(self.config.heartbeat_period)

    def send_command(self, cmd: Command) -> Refusal | None:
        """Validate and send u as COMMAND, or as START when ``cmd.now`` (protocol rule 8);
        return why it was refused (nothing sent), or None.  Both are checked as in rule 7; a
        START is refused with :attr:`RefusalCode.NO_START` once the device has shown it is
        v1.0 (:meth:`_check_starts`).  ``test_link_core.py`` holds it."""
        reason = P.check_command(cmd.n_a, cmd.phi_a, cmd.phi_d)
        if reason:
            self.stats.commands_rejected_locally += 1
            why = {P.R_N_A: f"n_a = {cmd.n_a} is outside 0..15",
                   P.R_ANGLE: f"phi_a = {cmd.phi_a!r} / phi_d = {cmd.phi_d!r} rad must be finite "
                              f"and within [-pi/8, pi/8]",
                   P.R_ORDER: f"need phi_a < phi_d on one side of 0 (accelerate: 0 <= phi_a < "
                              f"phi_d; brake: phi_a < phi_d <= 0), got {cmd.phi_a!r}, {cmd.phi_d!r}"}
            return Refusal(why[reason], RefusalCode(reason))
        if not self.connected:
            return Refusal("no link to the wheel", RefusalCode.NO_LINK)
        if cmd.now and self.stats.device_v1_0:
            self.stats.commands_rejected_locally += 1
            return Refusal("the device speaks protocol v1.0, which has no START: send the "
                           "command with now = false (it switches on when the pad reaches "
                           "phi_a)", RefusalCode.NO_START)
        seq = cmd.sequence or self._next_seq()
        counter = self._write((P.Start if cmd.now else P.Command)(seq, cmd.n_a, cmd.phi_a,
                                                                   cmd.phi_d))
        if counter is not None and cmd.now:
            with self._ack_cv:      # its answer may already be in _acks: looked up when due
                self._starts[counter] = self.clock()
        if counter is None:
            return Refusal("shutting down: no command after ESTOP / HV off", RefusalCode.CLOSING)
        self.stats.commands_sent += 1
        self.stats.starts_sent += int(cmd.now)
        return None

    def set_hv(self, enable: bool) -> int | None:
        """Ask for HV on or off; returns the frame counter (see :meth:`wait_ack`), None if closing."""
        self.hv_requested = enable
        return self._write(P.Hv(1 if enable else 0))

    def estop(self) -> int | None:
        self.hv_requested = False
        return self._write(P.Estop())

    def clear_estop(self) -> int | None:
        return self._write(P.ClearEstop())

    def wait_ack(self, counter: int, timeout: float | None = None) -> P.Message | None:
        """The ACK/REJECT for host frame ``counter``, or None after ``timeout`` seconds."""
        deadline = self.clock() + (self.config.ack_timeout if timeout is None else timeout)
        with self._ack_cv:
            while counter not in self._acks:
                left = deadline - self.clock()
                if left <= 0:
                    return None
                self._ack_cv.wait(left)
            return self._acks[counter]

    def shutdown(self) -> bool:
        """Stop heartbeats, send ESTOP then HV(0) (the last frame), wait for their ACKs, close.

        Returns True when the device acknowledged both.
        """
        with self._write_lock:
            self._closing = True
        self.hv_requested = False
        ok = False
        if self.connected:
            c1 = self._write(P.Estop(), closing=True)
            c2 = self._write(P.Hv(0), closing=True)
            ok = isinstance(self.wait_ack(c1), P.Ack) & isinstance(self.wait_ack(c2), P.Ack)
        self._running = False
        for th in (self._thread, self._hb_thread):
            if th and th is not threading.current_thread():
                th.join(timeout=1.0)
        self._close()
        return ok

    def diagnostics(self) -> dict[str, str]:
        d = self.decoder.stats
        lat = sorted(self.stats.latencies[-3000:])
        p99 = lat[int(0.99 * (len(lat) - 1))] if lat else float("nan")
        up = self.connected and not self.stale
        t = self.last_telemetry if up else None
        return {"connected": str(self.connected), "stale": str(self.stale),
                "link_thread": "alive" if self._thread and self._thread.is_alive() else
                               f"stopped{': ' + self.reader_failed if self.reader_failed else ''}",
                "hv_requested": str(self.hv_requested),
                "hv_on": str(bool(t.hv_monitor > 0)) if t else "unknown (no link)",
                "fault_flags": str(t.fault_flags) if t else "unknown (no link)",
                "frames": str(d.frames), "frame_rate_hz": f"{self.frame_rate if up else 0.0:.1f}",
                "version_or_type_errors": str(d.version_errors + d.type_errors),
                "device_restarts": str(d.restarts),
                "crc_errors": str(d.crc_errors),
                "framing_errors": str(d.framing_errors + d.oversize + d.length_errors),
                "sequence_gaps": str(d.sequence_gaps), "reconnects": str(self.stats.connects),
                "device_rejects": str(self.stats.rejects),
                "device_protocol": "1.0 (no START)" if self.stats.device_v1_0 else "1.1",
                "starts_unanswered": str(self.stats.starts_unanswered),
                "watchdog_trips": str(self.stats.watchdog_trips),
                "callback_errors": str(self.stats.callback_errors),
                "latency_p99_ms": f"{p99 * 1e3:.3f}"}

    # -- internals ---------------------------------------------------------------------------
    def _check_starts(self, now: float) -> None:
        """Protocol section 5: a START with neither ACK nor REJECT ``ack_timeout`` seconds
        after it was sent, while the link is up, marks the device as v1.0 (it dropped the
        frame as an unknown type): counted in ``stats.starts_unanswered``, warned once, and
        later STARTs are refused until the next connect.  On a stale or lost link nothing
        is concluded."""
        with self._ack_cv:
            due = [c for c, t in self._starts.items() if now - t >= self.config.ack_timeout]
            unanswered = 0
            for c in due:
                del self._starts[c]
                m = self._acks.get(c)
                answered = (isinstance(m, P.Ack) and m.acked_type == P.START) or \
                    (isinstance(m, P.Reject) and m.rejected_type == P.START)
                unanswered += not answered
        if not unanswered or not self.connected or self.stale:
            return
        self.stats.starts_unanswered += unanswered
        if not self.stats.device_v1_0:
            self.stats.device_v1_0 = True
            self.on_event(f"device answered no START within {self.config.ack_timeout * 1e3:.0f} "
                          f"ms: it speaks protocol v1.0; STARTs are refused until it reconnects")

    def _next_seq(self) -> int:
        self._cmd_seq += 1
        return self._cmd_seq

    def _write(self, msg: P.Message, closing: bool = False) -> int | None:
        """Send one frame; returns its counter, or None when refused because we are closing.

        Once :meth:`shutdown` has begun, only its own ESTOP and HV(0) go out (``closing``),
        so HV(0) stays the last frame on the wire whatever other threads try to send.
        """
        with self._write_lock:
            if (self._closing or self.reader_failed) and not closing:
                return None
            self._counter = (self._counter + 1) & 0xFFFF
            counter = self._counter
            ser = self._ser
            if ser is None:
                self.stats.write_errors += 1
                return counter
            try:
                # a leading delimiter: whatever half frame an interrupted write left on the
                # wire ends here, so it cannot swallow this frame (e.g. the final HV(0))
                ser.write(b"\x00" + P.encode(msg, counter))
            except (serial.SerialException, OSError):
                self.stats.write_errors += 1
        return counter

    def _open(self) -> bool:
        try:
            ser = serial.Serial(self.config.port, timeout=0, write_timeout=0.05, exclusive=True)
        except (serial.SerialException, OSError, ValueError):
            return False
        with self._write_lock:
            self._counter = 0          # protocol 6: our first frame after (re)connect is 1
        with self._ack_cv:             # counters restart: earlier answers name other frames
            self._acks.clear()
            self._starts.clear()
        self.stats.device_v1_0 = False  # the device may have been reflashed meanwhile
        self._ser = ser
        self.decoder = P.FrameDecoder()
        self.connected = True
        self.stale = False
        self.stats.connects += 1
        now = self.clock()
        self._last_rx = now
        self.on_event("connected")
        # the device may not have rebooted (a short loss): make its HV state known, off
        self._write(P.Hv(0), closing=True)
        if self.config.device_config is not None:
            self._write(self.config.device_config)
        if self.config.enable_hv_on_connect and not self._closing:
            self.clear_estop()
            self.set_hv(True)
        return True

    def _close(self) -> None:
        ser, self._ser = self._ser, None
        self.connected = False
        if ser is not None:
            try:
                ser.close()
            except (serial.SerialException, OSError):
                pass

    def _lost(self, why: str) -> None:
        # the link is gone: try the safe sequence anyway, then close and reconnect
        self.estop()
        self._write(P.Hv(0))
        self._close()
        self.stats.disconnects += 1
        self.on_event(f"link lost: {why}")

    def _run(self) -> None:
        try:
            self._loop()
        except Exception as exc:  # noqa: BLE001 - a dying link thread must leave HV off
            self.reader_failed = repr(exc)
            self._write(P.Estop(), closing=True)
            self._write(P.Hv(0), closing=True)
            self._close()
            self.on_event(f"link thread failed, sent ESTOP and HV off: {exc!r}")

    def _loop(self) -> None:
        backoff = self.config.backoff_min
        while self._running:
            if self._ser is None:
                if self._open():
                    backoff = self.config.backoff_min
                else:
                    time.sleep(backoff)
                    backoff = min(2 * backoff, self.config.backoff_max)
                continue
            data = b""
            try:  # only the I/O is guarded: a bug in decoding must not look like a lost link
                ready, _, _ = select.select([self._ser.fileno()], [], [], 0.005)
                if ready:
                    data = self._ser.read(4096)
                    if not data:
                        raise serial.SerialException("device reports readiness but returned no data")
            except (serial.SerialException, OSError) as exc:
                if self._running:
                    self._lost(str(exc))
                continue
            if data:
                self._handle(data, self.clock())
            now = self.clock()
            self._loop_t = now
            if self._starts:
                self._check_starts(now)
            if not self.stale and now - self._last_rx > self.config.link_timeout:
                self.stale = True
                self.stats.stale_events += 1
                self.estop()
                self._write(P.Hv(0))
                self.on_event("link stale: no telemetry; sent ESTOP and HV off")

    def _handle(self, data: bytes, t_rx: float) -> None:
        for frame in self.decoder.feed(data):
            m = frame.message
            if frame.type == P.TELEMETRY:
                self._last_rx = t_rx
                if self.stale:
                    self.stale = False
                    self.on_event("telemetry resumed")
                    if self.config.enable_hv_on_connect and not self._closing:
                        self.clear_estop()
                        self.set_hv(True)
                prev = self.last_telemetry
                if m.fault_flags & P.F_WATCHDOG and not (prev and prev.fault_flags & P.F_WATCHDOG):
                    self.stats.watchdog_trips += 1
                    self.on_event("device watchdog tripped: HV was switched off")
                self.last_telemetry = m
                if t_rx - self._rate_t0 >= 1.0:
                    self.frame_rate = (self.stats.samples - self._rate_n0) / (t_rx - self._rate_t0)
                    self._rate_t0, self._rate_n0 = t_rx, self.stats.samples
                sample = from_device(m)
                try:  # a failing consumer must not stop the link (heartbeats, acks)
                    self.on_sample(sample)
                except Exception as exc:  # noqa: BLE001 - reported, counted, link continues
                    self.stats.callback_errors += 1
                    if self.stats.callback_errors == 1:
                        self.on_event(f"sample callback failed (reported once): {exc!r}")
                self.stats.samples += 1
                lat = self.stats.latencies
                lat.append(self.clock() - t_rx)
                if len(lat) > self._keep:
                    del lat[: len(lat) - self._keep]
            elif frame.type in (P.ACK, P.REJECT):
                if frame.type == P.REJECT:
                    self.stats.rejects += 1
                    self.on_event(f"device rejected frame {m.rejected_counter} "
                                  f"(type 0x{m.rejected_type:02x}): reason {m.reason}")
                key = m.acked_counter if frame.type == P.ACK else m.rejected_counter
                with self._ack_cv:
                    self._acks[key] = m
                    if len(self._acks) > 1000:
                        for k in list(self._acks)[:500]:
                            del self._acks[k]
                    self._ack_cv.notify_all()
