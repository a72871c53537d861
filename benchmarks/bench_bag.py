"""Benchmark of the bag tools: write rate, and ``bag info`` / ``bag metrics`` on long
recordings, with peak memory.

A synthetic recording of one wheel: telemetry, joint state, state estimate and true state at
300 Hz, an MPC status and a command at 5 Hz, the reference every 40 s: 1,210 messages per
second of bag time, so 14 minutes make about 1 M messages (a 1-hour bag at about 280 messages
per second).  The recording is written with the project's BagWriter (as the embedded runner
does) for 14 and 28 minutes (1 M and 2 M messages), and each tool runs in a fresh process so
that its peak memory (ru_maxrss) is its own.  Targets: ``metrics`` on about 1 M messages in
<= 30 s; peak memory that does not grow with the bag's length (the two lengths show whether
it does); ``info`` counts every message back (zero drops: the writer is synchronous, nothing
is queued and discarded).

Run: ``.venv/bin/python benchmarks/bench_bag.py`` (about 6 minutes; part of ``./dev bench``).
"""
from __future__ import annotations

import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from hasel_wheel_common import samples
from hasel_wheel_common import topics
from hasel_wheel_bag.writer import BagWriter
from hasel_wheel_common.samples import Command, TelemetrySample

NS = "/wheel0"
PROFILE = (1.0, 1.5, 2.0, 2.5, 2.6, 2.0)

TOOL = r"""
import resource, sys, time
t0 = time.perf_counter()
if sys.argv[1] == "info":
    from hasel_wheel_bag.info import bag_info
    n = bag_info(sys.argv[2]).messages
else:
    from hasel_wheel_bringup.bag_metrics import bag_metrics
    n = bag_metrics(sys.argv[2])[0].telemetry_samples
print(time.perf_counter() - t0, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, n)
"""


def write(path: Path, seconds: float) -> tuple[int, float]:
    """Write the recording; (messages, wall seconds)."""
    n = 0
    t_start = time.perf_counter()
    with BagWriter(path) as b:
        for tp in (topics.TELEMETRY, topics.JOINT_STATES, topics.STATE_ESTIMATE,
                   topics.TRUE_STATE, topics.MPC_STATUS, topics.COMMAND, topics.REFERENCE):
            b.add_topic(topics.qualified(tp, NS), tp.type, tp.qos)
        for k in range(int(seconds * 300)):
            t = k / 300
            t_ns = round(t * 1e9)
            ref = PROFILE[int(t // 40) % len(PROFILE)]
            if k % 12000 == 0:
                b.write(NS + "/reference_speed", {"data": ref}, t_ns)
                n += 1
            v = ref * (1.0 + 0.01 * math.sin(t))
            s = TelemetrySample(t=t, device_time_us=round(t * 1e6), sequence=k,
                                encoder_raw=k % 1024, angle=v * t, q=k % 2, eta=k % 16,
                                eta_unwrapped=k // 20, active_mask=1 << (k % 16),
                                hv_monitor=9000.0, current_monitor=3e-4,
                                last_command_sequence=k // 60, fault_flags=0)
            b.write(NS + "/telemetry", samples.telemetry_msg(s), t_ns)
            b.write(NS + "/joint_states", samples.joint_state_msg(s), t_ns)
            b.write(NS + "/state_estimate", samples.state_msg(t, v * t, v, k % 2, 0.0, 0.0, 0), t_ns)
            b.write(NS + "/sim/true_state", samples.state_msg(t, v * t, v, k % 2, 0.0, 0.0, 0), t_ns)
            n += 4
            if k % 60 == 0:
                c = Command((k // 20 + 2) % 200, 0.17, 0.38, k // 60)
                b.write(NS + "/mpc_status", samples.mpc_status_msg(t, c, ref, v, 0.0, 1e-3, 0.02,
                                                                    36, False, False), t_ns)
                b.write(NS + "/command", samples.command_msg(c, t), t_ns)
                n += 2
    return n, time.perf_counter() - t_start


def tool(name: str, path: Path) -> tuple[float, float, int]:
    """(wall seconds, peak memory [MiB], messages it read: all for info, telemetry for
    metrics) of one tool in a fresh process."""
    out = subprocess.run([sys.executable, "-c", TOOL, name, str(path)], check=True,
                         capture_output=True, text=True).stdout.split()
    return float(out[0]), float(out[1]), int(out[2])


def main() -> None:
    with tempfile.TemporaryDirectory() as tmp:
        for minutes in (14, 28):
            path = Path(tmp) / f"bag_{minutes}min"
            n, dt = write(path, minutes * 60.0)
            size = (path / f"{path.name}_0.mcap").stat().st_size / 2 ** 20
            print(f"{minutes} min of bag time: {n:,} messages, {size:.0f} MiB, written in "
                  f"{dt:.1f} s ({n / dt:,.0f} messages/s = {n / dt / 1200:.1f}x the 1,200/s "
                  f"of four 300 Hz topics)")
            for name in ("info", "metrics"):
                sec, rss, read = tool(name, path)
                extra = ""
                if name == "info":      # every message written comes back: zero drops
                    extra = f"; read back {read:,} of {n:,} written ({n - read} dropped)"
                else:
                    extra = "  (target 30 s for 1 M messages)"
                print(f"  bag {name}: {sec:.1f} s ({n / sec:,.0f} messages/s), peak memory "
                      f"{rss:.0f} MiB{extra}")
            if minutes == 14:   # no metadata.yaml (a killed recording): both speeds followed
                sec, rss, _ = tool("metrics", path / f"{path.name}_0.mcap")
                print(f"  bag metrics on the lone .mcap file (no metadata.yaml): {sec:.1f} s, "
                      f"peak memory {rss:.0f} MiB")


if __name__ == "__main__":
    main()
