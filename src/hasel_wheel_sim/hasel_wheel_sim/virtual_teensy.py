"""A virtual Teensy: the plant behind a real pseudo-terminal, speaking protocol v1.

:class:`Firmware` is the device logic of ``docs/protocol.md`` section 4 (pure, no I/O):
HV interlock, command latching at switch-off, tick-sampled switching, watchdog, maximum
on-time, emergency stop.  :class:`VirtualTeensy` runs it at 300 Hz (real or scaled time) on a
pty, published under a stable symlink like ``/dev/serial/by-id/...``, and injects link faults
on demand: byte corruption, dropped bytes, stalls and unplug/replug.

Outgoing frames go through a transmit queue of :data:`TX_BUFFER_BYTES`, as a real device's
bytes go through its USB transmit buffers and the host kernel's tty buffer: a pty alone holds
only about 20 kB, which at 5x time is a quarter of a wall second of a host that does not read.
A frame goes into the queue whole or not at all (``write_drops``); the device never writes
part of a frame, and never waits for room.
"""
from __future__ import annotations

import gc
import math
import os
import random
import select
import threading
import time
import tty
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hasel_wheel_common import protocol as P

from hasel_wheel_sim import layout as L
from hasel_wheel_sim.integrator import advance
from hasel_wheel_sim.model import SECTOR, angle_reading
from hasel_wheel_sim.plant import COUNT, Plant
from hasel_wheel_sim.wheel import TICK


class Firmware:
    """Device behaviour (protocol section 4) around a :class:`Plant` in tick-switching mode."""

    def __init__(self, plant: Plant) -> None:
        if plant.config.switching != "tick":
            raise ValueError("the firmware switches on ticks: build the plant with switching='tick'")
        self.plant = plant
        self.reset()

    def reset(self) -> None:
        """Power-up state: HV off, nothing latched, estop clear, default configuration."""
        self.plant.wheel.cut_hv()
        self.config = P.Config()
        self.hv_enabled = False
        self.estop = False
        self.faults = 0
        self.counter = 0
        self.sample_seq = 0
        self.last_host_t = self.plant.t
        self.watchdog_trips = 0
        self.hv_off_t: float | None = None  # simulated time HV was last switched off

    # -- host frames --------------------------------------------------------------------
    def receive(self, frame: P.Frame) -> P.Message:
        """Handle one valid host frame; return the ACK or REJECT to send."""
        self.last_host_t = self.plant.t
        m = frame.message
        seq = m.command_seq if isinstance(m, P.Command) else 0

        def reject(reason: int) -> P.Reject:
            if isinstance(m, P.Command):
                self.faults |= P.F_REJECTED
            return P.Reject(frame.type, frame.counter, seq, reason)

        if isinstance(m, P.Command):
            reason = P.check_command(m.n_a, m.phi_a, m.phi_d)
            if reason:
                return reject(reason)
            if self.estop:
                return reject(P.R_ESTOP)
            if not self.hv_enabled:
                return reject(P.R_HV_DISABLED)
            # float32 angles may exceed pi/8 by a rounding step: clamp into the range
            pa = min(max(float(m.phi_a), -SECTOR), SECTOR)
            pd = min(max(float(m.phi_d), -SECTOR), SECTOR)
            self.plant.wheel.command(m.n_a, pa, pd, m.command_seq)
            self.faults &= ~(P.F_REJECTED | P.F_MAX_ON)
        elif isinstance(m, P.Hv):
            if m.enable:
                if self.estop:
                    return reject(P.R_ESTOP)
                self.hv_enabled = True
                self.faults &= ~P.F_WATCHDOG
            else:
                self._hv_off()
        elif isinstance(m, P.Estop):
            self._hv_off()
            self.estop = True
            self.faults |= P.F_ESTOP
        elif isinstance(m, P.ClearEstop):
            self.estop = False
            self.faults &= ~P.F_ESTOP
        elif isinstance(m, P.Config):
            if P.check_config(m):
                return reject(P.R_CONFIG)
            self.config = m
        return P.Ack(frame.type, frame.counter, seq)

    def _hv_off(self) -> None:
        if self.hv_enabled or self.plant.wheel.s[L.S_Q]:
            self.hv_off_t = self.plant.t
        self.hv_enabled = False
        self.plant.wheel.cut_hv()

    # -- ticks --------------------------------------------------------------------------
    def tick(self) -> P.Telemetry:
        """One firmware tick: watchdog, maximum on-time, physics, then the telemetry sample."""
        c = self.config
        if self.hv_enabled and self.plant.t - self.last_host_t >= c.watchdog_ms / 1000.0 - 1e-9:
            self._hv_off()
            self.faults |= P.F_WATCHDOG
            self.watchdog_trips += 1
        s = self.plant.wheel.s
        if s[L.S_Q] and s[L.S_ON_TIME] >= c.max_on_ms / 1000.0:
            self.plant.wheel.cut_hv()
            self.faults |= P.F_MAX_ON
        sample = self.plant.step(None, 1.0 / c.telemetry_rate_hz)
        self.sample_seq += 1
        xi1 = s[L.S_XI1]
        q = int(s[L.S_Q])
        eta_u = int(s[L.S_ETA])
        # a lost sample (plant dropout): the firmware still reads its sensor
        angle = sample.angle if sample is not None else angle_reading(xi1, self.plant.wheel.pv)
        return P.Telemetry(
            device_time_us=int(round(self.plant.t * 1e6)), sample_seq=self.sample_seq,
            encoder_raw=int(math.floor(angle / COUNT)) % 1024,
            encoder_unwrapped=int(math.floor(angle / COUNT)), q=q, eta=eta_u % 16,
            eta_unwrapped=eta_u, active_mask=(1 << (eta_u % 16)) if q else 0,
            hv_monitor=9000.0 if self.hv_enabled else 0.0, current_monitor=3e-4 if q else 0.0,
            last_command_seq=max(int(s[L.S_CMD_SEQ]), 0), fault_flags=self.faults)

    def next_counter(self) -> int:
        self.counter = (self.counter + 1) & 0xFFFF
        return self.counter


@dataclass
class LinkFaults:
    """Faults injected on the device -> host byte stream (probabilities per byte)."""

    corrupt: float = 0.0   # a byte is XORed with a random non-zero value
    drop: float = 0.0      # a byte is lost
    seed: int = 0
    host_corrupt: float = 0.0   # likewise on the host -> device stream (per byte)


@dataclass
class SentFrame:
    """Ground truth of one frame the device wrote: what it was and whether it was damaged."""

    counter: int
    type: int
    intact: bool
    message: P.Message
    t_wall: float = 0.0   # time.monotonic() when its last byte went to the pty (all processes)


@dataclass
class HostFrame:
    t: float            # simulated time of arrival [s]
    frame: P.Frame


#: Bytes the device -> host path holds beyond the pty before the device drops whole frames:
#: about a Teensy 4's USB transmit buffers (8 kB) plus the host kernel's tty flip buffer
#: (64 kB), less the pty's own ~20 kB.  At 300 Hz that is 3-4 s of a host that does not read.
TX_BUFFER_BYTES = 52 * 1024


@dataclass
class _State:
    running: bool = False
    plugged: bool = False
    stall_until: float = 0.0
    mute_until: float = 0.0


class VirtualTeensy:
    """Run :class:`Firmware` on a pty at ``time_scale`` x real time; ``link`` is the stable path."""

    def __init__(self, firmware: Firmware, link: str | os.PathLike, time_scale: float = 1.0,
                 faults: LinkFaults | None = None) -> None:
        self.fw = firmware
        self.link = Path(link)
        self.time_scale = time_scale
        self.faults = faults or LinkFaults()
        self._rng = random.Random(self.faults.seed)
        self.decoder = P.FrameDecoder()
        self.sent: list[SentFrame] = []
        self.received: list[HostFrame] = []
        self.write_drops = 0                  # frames never delivered: no room, no reader, unplugged
        self.faults_seen: list[str] = []     # firmware exceptions (each cut HV)
        self.re_anchors = 0                   # times the tick loop fell behind and re-anchored
        self._state = _State()
        self._lock = threading.Lock()
        self._master = -1
        self._thread: threading.Thread | None = None
        self._prev_delim_intact = True
        self._txq = bytearray()               # bytes not yet written to the pty
        self._txq_frames: deque[list[int]] = deque()   # [index in sent, bytes still queued]

    # -- lifecycle ----------------------------------------------------------------------
    def warm_up(self) -> None:
        """Compile or load the model core now (a throwaway tick on a copy of the state), so that
        the first live tick does not pay for it."""
        w = self.fw.plant.wheel
        advance(w.s.copy(), w.pv, TICK, np.zeros((L.EV_MAX_PER_TICK, 4)))

    def start(self) -> "VirtualTeensy":
        self.warm_up()
        self.plug()
        self._state.running = True
        self._thread = threading.Thread(target=self._run, name="virtual-teensy", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._state.running = False
        if self._thread:
            self._thread.join(timeout=5)
        self.unplug()

    def plug(self) -> None:
        """Create a new pty and point the stable link at it (a device appearing on USB).

        Plugging in powers the device up: the firmware restarts with HV off.
        """
        with self._lock:
            master, slave = os.openpty()
            tty.setraw(slave)
            os.set_blocking(master, False)
            name = os.ttyname(slave)
            os.close(slave)        # the host opens it by name; keeps the pty alive via master
            tmp = self.link.with_suffix(".tmp")
            if tmp.exists() or tmp.is_symlink():
                tmp.unlink()
            tmp.symlink_to(name)
            tmp.replace(self.link)
            self._master = master
            self.decoder = P.FrameDecoder()
            self.fw.reset()
            self._state.plugged = True

    def unplug(self) -> None:
        """Remove the device: the link disappears and the host's port fails.

        Frames still in the transmit queue are lost (marked not intact).
        """
        with self._lock:
            self._state.plugged = False
            self._lose_queue()
            if self.link.is_symlink():
                self.link.unlink()
            if self._master >= 0:
                os.close(self._master)
                self._master = -1

    #: Wall time [s] the tick loop may fall behind before it re-anchors (see ``_run``).
    CATCH_UP_LIMIT = 0.05

    def stall(self, seconds: float) -> None:
        """Stop talking and listening for ``seconds`` of wall time (a hung USB stack)."""
        self._state.stall_until = time.monotonic() + seconds

    def mute(self, seconds: float) -> None:
        """Send no new frames and read none for ``seconds`` of wall time, but still deliver
        what the transmit queue holds (the physics go on)."""
        self._state.mute_until = time.monotonic() + seconds

    # -- the device loop ------------------------------------------------------------------
    def _run(self) -> None:
        next_tick = time.monotonic()
        while self._state.running:
            now = time.monotonic()
            if now >= next_tick:
                period = 1.0 / self.fw.config.telemetry_rate_hz / self.time_scale
                next_tick += period
                # Behind by more than CATCH_UP_LIMIT of wall time (this process was not
                # scheduled): re-anchor instead of running the missed ticks in a burst.  A burst
                # would advance device time with no chance for host frames to arrive in between,
                # and trip the watchdog on a host that was never silent.  A real Teensy's timer
                # interrupt does not fall behind, so neither does this device's clock.
                if next_tick < now - self.CATCH_UP_LIMIT:
                    self.re_anchors += 1
                    next_tick = now + period
                with self._lock:
                    try:
                        live = now >= self._state.stall_until
                        if self._state.plugged and live and now >= self._state.mute_until:
                            self._read_host()
                            tel = self.fw.tick()
                            self._send(tel)
                        elif self._state.plugged:
                            if live:
                                self._flush()
                            self.fw.tick()         # physics go on; the device is mute
                        else:                      # unplugged: unpowered, HV off, wheel coasts
                            self.fw.plant.wheel.cut_hv()
                            self.fw.plant.step(None, 1.0 / self.fw.config.telemetry_rate_hz)
                    except Exception as exc:  # noqa: BLE001 - firmware must fail safe
                        self.faults_seen.append(repr(exc))
                        self.fw._hv_off()          # any firmware error: HV off, keep running
                continue
            fd = self._master
            timeout = max(0.0, min(next_tick - now, 0.002))
            if fd >= 0 and self._state.plugged and now >= self._state.stall_until:
                try:
                    select.select([fd], [], [], timeout)
                except (OSError, ValueError):
                    time.sleep(timeout)
                with self._lock:
                    if self._state.plugged:
                        self._flush()
                        if now >= self._state.mute_until:
                            self._read_host()
            else:
                time.sleep(timeout)

    def _read_host(self) -> None:
        try:
            data = os.read(self._master, 4096)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:           # the host side is closed: nothing to read
            return
        if self.faults.host_corrupt:
            data = bytes(b ^ self._rng.randrange(1, 256) if self._rng.random() < self.faults.host_corrupt
                         else b for b in data)
        for frame in self.decoder.feed(data):
            self.received.append(HostFrame(self.fw.plant.t, frame))
            self._send(self.fw.receive(frame))

    def _send(self, msg: P.Message) -> None:
        """Encode, damage as configured, write; record whether the frame arrives intact.

        A frame is intact when none of its bytes (its delimiter included) was damaged and the
        previous frame's delimiter arrived (else the two run together and both are lost).
        """
        counter = self.fw.next_counter()
        wire = P.encode(msg, counter)
        damaged = False
        delim_ok = True
        f = self.faults
        if f.corrupt or f.drop:
            out = bytearray()
            last = len(wire) - 1
            for i, b in enumerate(wire):
                r = self._rng.random()
                if r < f.drop + f.corrupt:
                    damaged = True
                    delim_ok = delim_ok and i != last
                    if r < f.drop:
                        continue
                    b ^= self._rng.randrange(1, 256)
                out.append(b)
            wire = bytes(out)
        if len(self._txq) + len(wire) > TX_BUFFER_BYTES or self._master < 0:
            # no room for the whole frame: it is not sent at all, and the stream stays framed
            self.write_drops += 1
            self.sent.append(SentFrame(counter, P.TYPE_OF[type(msg)], False, msg, time.monotonic()))
            return
        self.sent.append(SentFrame(counter, P.TYPE_OF[type(msg)],
                                   not damaged and self._prev_delim_intact, msg, 0.0))
        self._prev_delim_intact = delim_ok
        self._txq += wire
        self._txq_frames.append([len(self.sent) - 1, len(wire)])
        self._flush()

    def _lose_queue(self) -> None:
        """The queued frames will never arrive (unplugged, or no reader): count them as drops."""
        for idx, _ in self._txq_frames:
            self.sent[idx].intact = False
            self.write_drops += 1
        self._txq.clear()
        self._txq_frames.clear()
        self._prev_delim_intact = True

    def _flush(self) -> None:
        """Write what the pty takes from the transmit queue; stamp frames whose last byte went."""
        if not self._txq or self._master < 0:
            return
        try:
            n = os.write(self._master, self._txq)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:            # the pty refuses (no reader): the queued frames are lost
            self._lose_queue()
            return
        del self._txq[:n]
        now = time.monotonic()
        while n and self._txq_frames:
            head = self._txq_frames[0]
            k = min(n, head[1])
            head[1] -= k
            n -= k
            if head[1] == 0:
                self.sent[head[0]].t_wall = now
                self._txq_frames.popleft()


@dataclass
class DeviceReport:
    """What a virtual Teensy process saw, returned when it stops."""

    sent: list[SentFrame]
    received: list[HostFrame]
    hv_enabled: bool
    estop: bool
    faults: int
    hv_off_t: float | None
    t: float
    speed: float
    write_drops: int
    faults_seen: list[str] = field(default_factory=list)
    host_stream_dropped: int = 0    # host frames the device dropped (CRC, framing, ...)
    re_anchors: int = 0             # times the tick loop fell behind and re-anchored


def _device_main(conn, plant_config, params, w0, link, time_scale, faults) -> None:
    vt = VirtualTeensy(Firmware(Plant(params, plant_config, xi2=w0)), link, time_scale, faults)
    # Compile (or load) the core first, then move every object alive now out of the garbage
    # collector's reach.  A fresh compile leaves so many objects that the first full
    # collection, started by the plant's next block of random draws (tick 4096), held this
    # process for 0.38 s: at 5x time the host saw no telemetry for 250 ms and sent ESTOP.
    # A Teensy has no such pauses; this process should not have them either.
    vt.warm_up()
    gc.collect()
    gc.freeze()
    vt.start()
    while True:
        cmd, arg = conn.recv()
        if cmd == "unplug":
            vt.unplug()
        elif cmd == "plug":
            vt.plug()
        elif cmd == "stall":
            vt.stall(arg)
        elif cmd == "mute":
            vt.mute(arg)
        elif cmd == "status":
            with vt._lock:
                conn.send({"t": vt.fw.plant.t, "hv_enabled": vt.fw.hv_enabled,
                           "speed": float(vt.fw.plant.wheel.s[L.S_XI2]),
                           "received": len(vt.received), "sent": len(vt.sent)})
            continue
        elif cmd == "stop":
            vt.stop()
            conn.send(DeviceReport(vt.sent, vt.received, vt.fw.hv_enabled, vt.fw.estop,
                                   vt.fw.faults, vt.fw.hv_off_t, vt.fw.plant.t,
                                   float(vt.fw.plant.wheel.s[L.S_XI2]), vt.write_drops,
                                   vt.faults_seen, vt.decoder.stats.dropped, vt.re_anchors))
            return
        conn.send(None)


class DeviceProcess:
    """A :class:`VirtualTeensy` in its own process, as a real device would be (no shared GIL).

    Control it with :meth:`unplug`, :meth:`plug`, :meth:`stall`, :meth:`mute`, :meth:`status`; :meth:`stop`
    returns a :class:`DeviceReport` with the ground truth of every frame.
    """

    def __init__(self, link: str | os.PathLike, plant_config=None, params=None, w0: float = 0.0,
                 time_scale: float = 1.0, faults: LinkFaults | None = None) -> None:
        import multiprocessing as mp

        from hasel_wheel_sim.plant import PlantConfig
        ctx = mp.get_context("spawn")
        self._conn, child = ctx.Pipe()
        self.link = Path(link)
        self._proc = ctx.Process(target=_device_main, daemon=True,
                                 args=(child, plant_config or PlantConfig(switching="tick"), params,
                                       w0, str(link), time_scale, faults))
        self._proc.start()
        t_end = time.monotonic() + 180.0       # a fresh clone compiles the core first
        while not self.link.is_symlink():      # the child compiles and plugs in
            if time.monotonic() > t_end or not self._proc.is_alive():
                self._proc.kill()
                raise RuntimeError("the virtual Teensy process did not come up")
            time.sleep(0.01)

    def _call(self, cmd: str, arg=None):
        self._conn.send((cmd, arg))
        return self._conn.recv()

    def unplug(self) -> None:
        self._call("unplug")

    def plug(self) -> None:
        self._call("plug")

    def stall(self, seconds: float) -> None:
        self._call("stall", seconds)

    def mute(self, seconds: float) -> None:
        self._call("mute", seconds)

    def status(self) -> dict:
        return self._call("status")

    def stop(self) -> DeviceReport:
        report = self._call("stop")
        self._proc.join(timeout=5)
        return report
