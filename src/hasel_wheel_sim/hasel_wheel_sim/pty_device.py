"""The virtual Teensy on a pseudo-terminal: a :class:`~.firmware.Firmware` board run at 300 Hz
(real or scaled time) behind a pty published under a stable symlink like ``/dev/serial/by-id/...``,
speaking protocol v1, with link faults injected on demand: byte corruption, dropped bytes,
stalls and unplug/replug.

Outgoing frames go through a transmit queue of :data:`TX_BUFFER_BYTES`, as a real device's
bytes go through its USB transmit buffers and the host kernel's tty buffer (a pty alone holds
about 20 kB).  A frame goes into the queue whole or not at all (``write_drops``); the device
never writes part of a frame, and never waits for room.  ``test_virtual_link.py`` holds
these rules.
"""
from __future__ import annotations

import os
import random
import select
import threading
import time
import tty
from collections import deque
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hasel_wheel_common import protocol as P

from hasel_wheel_sim import layout as L
from hasel_wheel_sim.firmware import Firmware
from hasel_wheel_sim.integrator import advance
from hasel_wheel_sim.wheel import TICK


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
        self._last_sample_seq = 0             # of the last telemetry frame queued
        self._rx = bytearray()                # host bytes read, not yet taken by the device
        self._own = P.FrameDecoder()          # reads back the device's own frames
        self.muted_frames = 0                 # frames the device made while muted (not sent)

    # -- lifecycle ----------------------------------------------------------------------
    def warm_up(self) -> None:
        """Compile or load the model core now (a throwaway tick on a copy of the state), so that
        the first live tick does not pay for it."""
        w = self.fw.plant.wheel
        advance(w.s.copy(), w.pv, TICK, np.zeros((L.EV_MAX_PER_TICK, 4)))

    def start(self) -> "VirtualTeensy":
        """Plug in and run the device loop in a thread."""
        self.warm_up()
        self.plug()
        self._state.running = True
        self._thread = threading.Thread(target=self._run, name="virtual-teensy", daemon=True)
        self._thread.start()
        return self

    def status(self) -> dict:
        """Device time ``t`` [s], ``hv_enabled``, wheel ``speed`` [rad/s], frames
        ``received`` and ``sent``, frames still ``queued`` for the pty, and the sample_seq of
        the last telemetry frame that went into the queue (``last_sample_seq``, 0 if none)."""
        with self._lock:
            return {"t": self.fw.plant.t, "hv_enabled": self.fw.hv_enabled,
                    "speed": float(self.fw.plant.wheel.s[L.S_XI2]),
                    "received": len(self.received), "sent": len(self.sent),
                    "queued": len(self._txq_frames), "last_sample_seq": self._last_sample_seq}

    def stop(self) -> None:
        """Stop the device loop and unplug."""
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
            self._rx.clear()
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
                period = self.fw.tick_period / self.time_scale
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
                            del self._rx[:self.fw.receive(bytes(self._rx))]
                            for wire in self.fw.tick():
                                self._send(wire)
                        elif self._state.plugged:
                            if live:
                                self._flush()
                            self.muted_frames += len(self.fw.tick())   # physics go on; mute
                        else:                      # unplugged: unpowered, HV off, wheel coasts
                            self.fw.cut_power()
                    except Exception as exc:  # noqa: BLE001 - firmware must fail safe
                        # any board error resets the device, as a Teensy's watchdog would:
                        # HV off, emergency stop and configuration cleared; it keeps running
                        self.faults_seen.append(repr(exc))
                        self.fw.reset()
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
        """Read what the host wrote; the device takes it at its next tick."""
        try:
            data = os.read(self._master, 4096)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:           # the host side is closed: nothing to read
            return
        if self.faults.host_corrupt:
            data = bytes(b ^ self._rng.randrange(1, 256) if self._rng.random() < self.faults.host_corrupt
                         else b for b in data)
        self._rx += data
        for frame in self.decoder.feed(data):       # the ground truth of what arrived
            self.received.append(HostFrame(self.fw.plant.t, frame))

    def _send(self, wire: bytes) -> None:
        """Damage a frame of the device as configured and queue it; record whether it
        arrives intact.

        A frame is intact when none of its bytes (its delimiter included) was damaged and the
        previous frame's delimiter arrived (else the two run together and both are lost).
        """
        frame = self._own.feed(wire)[0]
        msg = frame.message
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
            self.sent.append(SentFrame(frame.counter, frame.type, False, msg, time.monotonic()))
            return
        self.sent.append(SentFrame(frame.counter, frame.type,
                                   not damaged and self._prev_delim_intact, msg, 0.0))
        self._prev_delim_intact = delim_ok
        self._txq += wire
        self._txq_frames.append([len(self.sent) - 1, len(wire)])
        if isinstance(msg, P.Telemetry):
            self._last_sample_seq = msg.sample_seq
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
