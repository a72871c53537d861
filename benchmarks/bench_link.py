"""Benchmark of the serial link (protocol v1).

* decode throughput of FrameDecoder on one core, frames/s (target >= 100,000);
* latency from a frame's last byte arriving at the host to the decoded sample being handed
  to the publisher callback, p50 and p99, measured over a real pseudo-terminal with the
  virtual Teensy in its own process at 300 Hz (target p99 < 1 ms);
* a host whose reader pauses: frames the device lost (always whole: the stream stays framed)
  and frames the host found damaged (target 0), by length of the pause.
* the open-loop sequencer at 5x time through the driver: commands that reached the device too
  late for their pad (target <= 1 %), and the driver's frame rate (target 1500 /s within 10 %);
* replug -> telemetry with HV on again (target < 1 s), and host silence -> device HV off.

Run: ``./dev bench`` or ``.venv/bin/python benchmarks/bench_link.py``.
"""
from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import numpy as np

from hasel_wheel_common import protocol as P
from hasel_wheel_driver.link import DriverCore, LinkConfig
from hasel_wheel_sim.device_process import DeviceProcess


def decode_throughput(n: int = 200_000) -> float:
    frames = [P.encode(P.Telemetry(i * 3333, i, i % 1024, i, i % 2, i % 16, i, 1 << (i % 16),
                                   9000.0, 3e-4, i // 40, 0), i) for i in range(n)]
    wire = b"".join(frames)
    chunks = [wire[i:i + 512] for i in range(0, len(wire), 512)]   # USB-sized reads
    best = 0.0
    for _ in range(3):
        d = P.FrameDecoder()
        t0 = time.perf_counter()
        got = 0
        for c in chunks:
            got += len(d.feed(c))
        best = max(best, got / (time.perf_counter() - t0))
    assert got == n
    return best


def link_latency(seconds: float = 20.0) -> tuple[np.ndarray, np.ndarray]:
    """(read() returned -> handed on, device write -> handed on) [s] per telemetry frame."""
    link = Path(tempfile.mkdtemp()) / "teensy"
    dev = DeviceProcess(link, w0=2.0)
    handed: dict[int, float] = {}
    core = DriverCore(LinkConfig(str(link)),
                      on_sample=lambda s: handed.__setitem__(s.sequence, time.monotonic())).start()
    time.sleep(seconds)
    core.shutdown()
    rep = dev.stop()
    written = {f.message.sample_seq: f.t_wall for f in rep.sent if f.type == P.TELEMETRY}
    e2e = np.array([handed[k] - written[k] for k in sorted(handed) if k > 300 and k in written])
    return np.array(core.stats.latencies[300:]), e2e


def reconnect_and_watchdog(trials: int = 5) -> tuple[list[float], float]:
    """Seconds from a replug to telemetry with HV on again (per trial); watchdog delay [s]."""
    rng = np.random.default_rng(0)
    link = Path(tempfile.mkdtemp()) / "teensy"
    dev = DeviceProcess(link, w0=2.0)
    core = DriverCore(LinkConfig(str(link), enable_hv_on_connect=True)).start()
    time.sleep(1.0)
    back = []
    for _ in range(trials):
        c0 = core.stats.connects
        dev.unplug()
        time.sleep(float(rng.uniform(0.3, 1.2)))      # unplugged for a random while
        core.last_telemetry = None
        dev.plug()
        t0 = time.monotonic()
        while not (core.stats.connects > c0 and core.last_telemetry is not None
                   and core.last_telemetry.hv_monitor > 0):
            time.sleep(0.0005)
        back.append(time.monotonic() - t0)
        time.sleep(0.3)
    core._running = False                              # the host falls silent
    core._thread.join()
    time.sleep(0.5)
    rep = dev.stop()
    core._close()
    return back, rep.hv_off_t - rep.received[-1].t


def host_pause(pause: float, scale: float = 5.0) -> tuple[int, int, int]:
    """The host's reader sleeps ``pause`` [s of wall time] once, with the device at ``scale`` x
    real time.  Returns (frames the device could not deliver, frames the host found damaged,
    telemetry frames the host got)."""
    cfg = P.Config(telemetry_rate_hz=300, watchdog_ms=1000, max_on_ms=2000, drain_mode=0)
    link = Path(tempfile.mkdtemp()) / "teensy"
    dev = DeviceProcess(link, w0=2.0, time_scale=scale)
    got: list[int] = []

    def on_sample(s) -> None:
        got.append(s.sequence)
        if len(got) == 3000:
            time.sleep(pause)
    core = DriverCore(LinkConfig(str(link), link_timeout=5.0, device_config=cfg),
                      on_sample=on_sample).start()
    time.sleep(3000 / 300 / scale + pause + 2.0)
    dev.mute(10.0)                 # no new frames; the device's queue drains to the host
    time.sleep(1.5)
    core.shutdown()
    rep = dev.stop()
    st = core.decoder.stats
    return rep.write_drops, st.crc_errors + st.framing_errors + st.oversize, len(got)


def closed_loop_at_scale(seconds: float = 30.0, scale: float = 5.0) -> dict[str, float]:
    """The open-loop Sequencer (phi_a 3 deg, phi_d 22 deg) driving the device at ``scale`` x
    real time for ``seconds`` of device time through the driver.  Returns the commands sent,
    those that never switched on their pad (``late``: they reached the device after that
    pad's switch-on angle; the host's latency in device time), the wheel speed at the end
    [rad/s] and the driver's telemetry frame rate [frames per wall second] at the end."""
    from hasel_wheel_bringup.sequencer import Sequencer

    cfg = P.Config(telemetry_rate_hz=300, watchdog_ms=1000, max_on_ms=2000, drain_mode=0)
    link = Path(tempfile.mkdtemp()) / "teensy"
    dev = DeviceProcess(link, w0=2.0, time_scale=scale)
    ctrl = Sequencer(np.radians(3.0), np.radians(22.0))
    samples: list = []
    sent: list[tuple[int, int]] = []
    core: DriverCore

    def on_sample(s) -> None:
        samples.append(s)
        cmd = ctrl.step(s)
        if cmd is not None and core.send_command(cmd) is None:
            sent.append((cmd.sequence, cmd.n_a))
    core = DriverCore(LinkConfig(str(link), heartbeat_period=0.02, link_timeout=0.25,
                                 enable_hv_on_connect=True, device_config=cfg),
                      on_sample=on_sample)
    core.start()
    while not (samples and samples[-1].hv_monitor > 0):
        time.sleep(0.01)
    t_end = dev.status()["t"] + seconds
    while dev.status()["t"] < t_end:
        time.sleep(0.05)
    speed, rate = dev.status()["speed"], float(core.diagnostics()["frame_rate_hz"])
    core.shutdown()
    dev.stop()
    switched = {(s.last_command_sequence, s.eta) for s in samples if s.q == 1}
    late = sum((seq, pad) not in switched for seq, pad in sent[:-2])
    return {"commands": len(sent) - 2, "late": late, "speed": speed, "rate": rate}


def main() -> None:
    cores = os.sched_getaffinity(0)
    os.sched_setaffinity(0, {min(cores)})
    fps = decode_throughput()
    os.sched_setaffinity(0, cores)
    read, e2e = link_latency()
    print("serial link benchmark")
    print(f"  decode throughput, one core          : {fps:10.0f} frames/s   (target 100,000: {fps / 1e5:4.1f}x)")
    for name, lat in (("read() returned -> sample handed on", read),
                      ("device wrote frame -> handed on    ", e2e)):
        print(f"  {name}: p50 {np.percentile(lat, 50) * 1e3:.3f} ms, p99 {np.percentile(lat, 99) * 1e3:.3f} ms"
              f" over {lat.size} frames on a pty at 300 Hz   (target p99 < 1 ms)")
    for pause in (0.5, 0.9, 1.3):
        lost, damaged, n = host_pause(pause)
        print(f"  host reader paused {pause:.1f} s at 5x ({pause * 5:.1f} s of device time): "
              f"{lost} frames lost whole, {damaged} damaged, of {n + lost}   (target 0 damaged)")
    loop = closed_loop_at_scale()
    print(f"  sequencer at 5x for 30 s of device time: {loop['late']} of {loop['commands']} commands "
          f"late for their pad   (target <= 1 %); wheel at {loop['speed']:.2f} rad/s")
    print(f"  driver frame rate at 5x                : {loop['rate']:.0f} frames/s   "
          f"(target 1500 within 10 %)")
    back, wd = reconnect_and_watchdog()
    print(f"  replug -> telemetry with HV on again : {', '.join(f'{b * 1e3:.0f}' for b in back)} ms"
          f"   (target < 1000 ms; backoff cap 250 ms)")
    print(f"  host silent -> device HV off         : {wd * 1e3:.1f} ms of device time   (target <= 100 ms)")


if __name__ == "__main__":
    main()
