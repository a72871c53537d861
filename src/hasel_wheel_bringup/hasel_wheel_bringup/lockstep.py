"""The C++ firmware core in lockstep with the Python device core on one simulated wheel.

The Python core (:class:`~hasel_wheel_sim.device_core.DeviceCore`) drives the plant, as the
virtual Teensy does; the C++ core, built for the host, gets exactly the same host bytes,
sensor readings and device time on every tick.  The host is the MPC speed controller, fed
from the device's telemetry, and a schedule of faults: corrupted and cut host frames, host
silence, an over-current sample, an HV sag, an emergency stop, configuration (a short
maximum on-time, a faster tick) and invalid input, HV off by the host, START frames (protocol
v1.1: accepted, and refused for each of its reasons), a device reset and a failing encoder.  Every tick the two cores' frames must match byte for byte and their states field by field.
``test_firmware_lockstep.py`` holds the result; ``benchmarks/bench_firmware.py`` prints it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

from hasel_wheel_common import protocol as P
from hasel_wheel_common.samples import as_received, from_device
from hasel_wheel_mpc.closed_loop import controller_config
from hasel_wheel_mpc.controller import SpeedController
from hasel_wheel_sim.device_core import DeviceCore
from hasel_wheel_sim.device_cpp import CppDeviceCore, load_library
from hasel_wheel_sim.firmware import Firmware
from hasel_wheel_sim.params import WheelParams, packaged
from hasel_wheel_sim.plant import Plant, load_plant_config

#: Host heartbeat period [ticks] (50 Hz at 300 Hz).
HEARTBEAT_TICKS = 6


@dataclass
class LockstepReport:
    """What a lockstep run compared and what happened in it."""

    ticks: int = 0
    frames: int = 0                      # frames compared (both cores sent the same)
    bytes: int = 0
    switch_ons: int = 0
    commands_acked: int = 0
    starts_acked: int = 0
    rejects: dict[int, int] = field(default_factory=dict)   # reason -> count
    faults_seen: int = 0                 # OR of every telemetry fault_flags
    host_frames_dropped: int = 0         # by the device's decoder (CRC, framing, ...)
    first_mismatch: str = ""             # '' when the cores agreed on every tick
    final_speed: float = math.nan        # true wheel speed at the end [rad/s]
    reference: float = math.nan
    speeds: list[float] = field(default_factory=list)   # true speed at each whole second [rad/s]


class _Host:
    """The host side: MPC controller, heartbeats, and the fault schedule's frames."""

    def __init__(self, fw: Firmware, reference: float) -> None:
        self.counter = 0
        self.ctrl = SpeedController(controller_config(), clock=lambda: 0.0)
        self.reference = reference
        self.decoder = P.FrameDecoder()
        self.out = bytearray()
        self.silent = False
        self.last_count = fw.plant.encoder_raw    # unwrapped count of the last telemetry
        self.send(P.Hv(1))
        s = fw.plant.wheel.s
        first = self.ctrl.start(float(fw.plant.encoder_raw) * P.SECTOR / 64, s[2])
        if first is not None:                 # a standing wheel is started from its samples
            self.send_command(first)

    def send(self, msg: P.Message, damage: str = "") -> None:
        self.counter = (self.counter + 1) & 0xFFFF
        wire = bytearray(P.encode(msg, self.counter))
        if damage == "flip":
            wire[len(wire) // 2] ^= 0x10
        elif damage == "cut":
            wire = wire[:len(wire) // 2]          # the rest never comes; the next 0x00 ends it
        if not self.silent:
            self.out += b"\x00" + wire

    def send_command(self, c) -> None:
        """A controller's Command as COMMAND, or as START when ``c.now``."""
        self.send((P.Start if c.now else P.Command)(c.sequence, c.n_a, c.phi_a, c.phi_d))

    def send_starts(self, k: int) -> None:
        """Three STARTs for the pad sectors from the last count: one not in contact (REJECT
        7), one in contact within [0, pi/8) (ACK, while no pad is on), one more (REJECT 8)."""
        n_a = (self.last_count // 64) % 16
        self.send(P.Start(3 * 10**6 + k, (n_a + 8) % 16, 0.05, 0.3))
        self.send(P.Start(3 * 10**6 + k + 1, n_a, 0.0, P.SECTOR))
        self.send(P.Start(3 * 10**6 + k + 2, n_a, 0.0, P.SECTOR))

    def take(self) -> bytes:
        data, self.out = bytes(self.out), bytearray()
        return data

    def on_frames(self, frames: list[bytes], report: LockstepReport) -> None:
        for f in self.decoder.feed(b"".join(frames)):
            m = f.message
            if f.type == P.TELEMETRY:
                report.faults_seen |= m.fault_flags
                self.last_count = m.encoder_unwrapped
                r = self.ctrl.step(as_received(from_device(m)), self.reference)
                if r.command is not None:
                    self.send_command(r.command)
            elif f.type == P.ACK and m.acked_type == P.COMMAND:
                report.commands_acked += 1
            elif f.type == P.ACK and m.acked_type == P.START:
                report.starts_acked += 1
            elif f.type == P.REJECT:
                report.rejects[m.reason] = report.rejects.get(m.reason, 0) + 1


def _faults(k: int, host: _Host) -> dict:
    """The fault schedule at tick k (300 per second), repeating every 60 s: frames it sends,
    sensor readings it overrides, and ``reset`` when both devices reset."""
    sec, tick = divmod(k % 18000, 300)
    over: dict = {}
    if sec == 5 and tick < 5:                                # five corrupted heartbeats
        host.send(P.Heartbeat(k), damage="flip")
    if sec == 5 and tick == 10:                              # a command cut short
        host.send(P.Command(10**6 + k, 3, 0.05, 0.3), damage="cut")
    if sec == 15 and tick == 0:                              # host silence: the watchdog
        host.silent = True
    if sec == 15 and tick == 45:
        host.silent = False
        host.send(P.Hv(1))
    if sec == 25 and tick == 0:                              # an over-current sample
        over["current_monitor"] = 5e-3
    if sec == 25 and tick == 3:
        host.send(P.Hv(1))
    if sec == 35 and tick == 0:                              # emergency stop
        host.send(P.Estop())
        host.send(P.Hv(1))                                   # refused while latched
        host.send(P.Start(4 * 10**6 + k, 0, 0.0, P.SECTOR))  # refused while latched
    if sec == 35 and tick == 15:
        host.send(P.ClearEstop())
        host.send(P.Hv(1))
    if sec == 45 and tick == 0:                              # the HV supply sags
        over["hv_monitor"] = 7000.0
    if sec == 45 and tick == 3:
        host.send(P.Hv(1))
    if sec == 50 and tick == 0:                              # configuration, invalid input
        host.send(P.Config(300, 100, 10, 0))                 # a 10 ms maximum on-time
        host.send(P.Config(300, 5, 2000, 0))
        host.send(P.Command(2 * 10**6 + k, 17, 0.05, 0.3))
        host.send(P.Start(2 * 10**6 + k + 1, 3, 0.3, 0.05))   # phi_a > phi_d
        host.send(P.Hv(2))
    if sec == 50 and tick == 150:
        host.send(P.Config(300, 100, 2000, 0))
    if sec == 52 and tick in (0, 30):                        # the host switches HV off, on
        host.send(P.Hv(int(tick == 30)))
    if sec == 52 and tick == 1:                              # a START without HV
        host.send(P.Start(5 * 10**6 + k, 0, 0.0, P.SECTOR))
    if sec == 52 and tick == 30:                             # STARTs right after HV is on
        host.send_starts(k)
    if sec == 54 and tick in (0, 150):                       # 500 Hz ticks for a while
        host.send(P.Config(500 if tick == 0 else 300, 100, 2000, 0))
    if sec == 56 and tick == 0:                              # the device resets (brown-out)
        over["reset"] = True
    if sec == 56 and tick == 30:
        host.send(P.Hv(1))
    if sec == 58 and tick < 12:                              # the encoder fails: position lost
        over["encoder_ok"] = False
    if sec == 58 and tick == 30:
        host.send(P.Hv(1))
    return over


def run_lockstep(core_build, seconds: float = 60.0, seed: int = 1, reference: float = 1.5,
                 w0: float = 1.5) -> LockstepReport:
    """Run both cores for ``seconds`` of simulated time on the realistic plant with plant
    seed ``seed``, the MPC holding ``reference`` [rad/s] from ``w0`` [rad/s]."""
    cfg = load_plant_config(packaged("hasel_wheel_sim", "plant_realistic.yaml"))
    fw = Firmware(Plant(WheelParams(), replace(cfg, seed=seed), xi2=w0), DeviceCore())
    cpp = CppDeviceCore(load_library(core_build))
    host = _Host(fw, reference)
    report = LockstepReport(reference=reference)
    for k in range(int(round(seconds * 300))):
        over = _faults(k, host)
        if k % HEARTBEAT_TICKS == 0:
            host.send(P.Heartbeat(k))
        data = host.take()
        taken, taken_cpp = fw.receive(data), cpp.receive(data)
        if taken != taken_cpp or taken != len(data):
            report.first_mismatch = (f"tick {k}: of {len(data)} host bytes the Python device "
                                     f"took {taken}, the C++ core {taken_cpp}")
            break
        if over.pop("reset", False):
            report.host_frames_dropped += fw.core.decoder.stats.dropped
            fw.reset()
            cpp.reset()
        sensors = fw.sensors()._replace(**over)
        now = int(round(fw.plant.t * 1e6))
        frames_cpp, out_cpp = cpp.tick(now, sensors)
        frames = fw.tick(sensors)
        if frames != frames_cpp or fw.outputs != out_cpp or fw.state != cpp.state():
            report.first_mismatch = (f"tick {k}: python {frames} {fw.outputs} {fw.state}\n"
                                     f"c++ {frames_cpp} {out_cpp} {cpp.state()}")
            break
        report.ticks += 1
        report.frames += len(frames)
        report.bytes += sum(map(len, frames))
        report.switch_ons += int(fw.state.q and fw.state.on_since_us == now)
        if k % 300 == 299:
            report.speeds.append(float(fw.plant.wheel.s[2]))
        host.on_frames(frames, report)
    report.host_frames_dropped += fw.core.decoder.stats.dropped
    report.final_speed = float(fw.plant.wheel.s[2])
    return report
