"""The virtual Teensy in a process of its own, as a real device is (no shared GIL):
:class:`DeviceProcess` starts a :class:`~.pty_device.VirtualTeensy` on a pty, controls it
through a pipe, and returns the ground truth of every frame (:class:`DeviceReport`) when it
stops.
"""
from __future__ import annotations

import gc
import os
import signal
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hasel_wheel_sim import layout as L
from hasel_wheel_sim.device_cpp import CppDeviceCore, load_library
from hasel_wheel_sim.firmware import Firmware
from hasel_wheel_sim.params import WheelParams
from hasel_wheel_sim.plant import Plant, PlantConfig
from hasel_wheel_sim.pty_device import HostFrame, LinkFaults, SentFrame, VirtualTeensy


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
    watchdog_trips: int = 0         # times the device's watchdog switched HV off


def _device_main(conn, plant_config, params, w0, link, time_scale, faults, core_build) -> None:
    # a Ctrl-C at the terminal reaches the whole process group; this process stops only when
    # its parent says so (stop), so that the parent still gets the report
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    core = CppDeviceCore(load_library(core_build)) if core_build else None
    vt = VirtualTeensy(Firmware(Plant(params, plant_config, xi2=w0), core), link, time_scale, faults)
    # Compile (or load) the core first, then move every object alive now out of the garbage
    # collector's reach: a compile leaves enough objects that a full collection would pause
    # the device for longer than the host's link timeout at scaled time.  A Teensy has no
    # such pauses, so neither does this process.
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
            conn.send(vt.status())
            continue
        elif cmd == "stop":
            vt.stop()
            conn.send(DeviceReport(vt.sent, vt.received, vt.fw.hv_enabled, vt.fw.estop,
                                   vt.fw.faults, vt.fw.hv_off_t, vt.fw.plant.t,
                                   float(vt.fw.plant.wheel.s[L.S_XI2]), vt.write_drops,
                                   vt.faults_seen, vt.decoder.stats.dropped, vt.re_anchors,
                                   vt.fw.watchdog_trips))
            return
        conn.send(None)


class DeviceProcess:
    """A :class:`VirtualTeensy` in its own process, as a real device would be (no shared GIL).

    Control it with :meth:`unplug`, :meth:`plug`, :meth:`stall`, :meth:`mute`,
    :meth:`status`; :meth:`stop` returns a :class:`DeviceReport` with the ground truth of
    every frame.  ``test_link_end_to_end.py`` runs the driver against it.
    """

    #: Seconds the process may take to come up (it compiles the model core on a cold cache).
    START_TIMEOUT = 600.0

    def __init__(self, link: str | os.PathLike, plant_config: PlantConfig | None = None,
                 params: WheelParams | None = None, w0: float = 0.0, time_scale: float = 1.0,
                 faults: LinkFaults | None = None, core_build: str | os.PathLike | None = None) -> None:
        """Start the device at wheel speed ``w0`` [rad/s] and ``time_scale`` x real time, its
        pty published at ``link``; returns once the link exists.  ``core_build``: a directory
        from :func:`~.device_cpp.build_core`, to run the C++ firmware core instead of the
        Python :class:`~.device_core.DeviceCore`."""
        import multiprocessing as mp

        ctx = mp.get_context("spawn")
        self._conn, child = ctx.Pipe()
        self.link = Path(link)
        self._proc = ctx.Process(target=_device_main, daemon=True,
                                 args=(child, plant_config or PlantConfig(switching="tick"), params,
                                       w0, str(link), time_scale, faults,
                                       str(core_build) if core_build else None))
        self._proc.start()
        t_end = time.monotonic() + self.START_TIMEOUT
        while not self.link.is_symlink():      # the child compiles and plugs in
            if time.monotonic() > t_end or not self._proc.is_alive():
                self._proc.kill()
                raise RuntimeError("the virtual Teensy process did not come up")
            time.sleep(0.01)

    def _call(self, cmd: str, arg: float | None = None) -> Any:
        self._conn.send((cmd, arg))
        return self._conn.recv()

    def unplug(self) -> None:
        """Remove the device (see :meth:`VirtualTeensy.unplug`)."""
        self._call("unplug")

    def plug(self) -> None:
        """Plug it in again: a new pty, the firmware powered up (HV off)."""
        self._call("plug")

    def stall(self, seconds: float) -> None:
        """Neither talk nor listen for ``seconds`` of wall time."""
        self._call("stall", seconds)

    def mute(self, seconds: float) -> None:
        """Send no new frames and read none for ``seconds`` of wall time; the queue drains."""
        self._call("mute", seconds)

    def status(self) -> dict:
        """:meth:`VirtualTeensy.status` of the device now."""
        return self._call("status")

    def stop(self) -> DeviceReport:
        """Stop the device and its process; the ground truth of the run."""
        report = self._call("stop")
        self._proc.join(timeout=5)
        return report
