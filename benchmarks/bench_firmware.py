"""Benchmark of the firmware core (firmware/core, built for the host).

* instructions one 300 Hz tick costs the core (host frames handled, rules, encoder, switching,
  telemetry encoded), counted by valgrind's callgrind inside ``Device::tick`` and
  ``Device::receive`` only, as the difference of a 11,000- and a 1,000-tick run (start-up
  cancels): the typical tick (a heartbeat every 6th tick, a command every 20th), and the
  512-byte receive buffer full at every tick, of commands, of STARTs that go through every
  check of rule 8, or of the smallest frames (the most answers): the worst of these three is
  the worst tick;
* the same converted to the Teensy 3.6 (Cortex-M4F at 180 MHz) with a stated factor, plus the
  board's I/O per tick, against the tick period (target: worst case below the 3.33 ms tick);
* the lockstep of the C++ core with the Python device core over 60 s of the realistic plant
  under the MPC with faults: ticks, frames and bytes compared, first mismatch (target none),
  and the speed the MPC held between the faults.

Run: ``./dev bench`` or ``.venv/bin/python benchmarks/bench_firmware.py``.
"""
from __future__ import annotations

import re
import shutil
import subprocess

from hasel_wheel_bringup.lockstep import run_lockstep
from hasel_wheel_sim.device_cpp import build_core, default_build, BUILD_ROOT

#: Cortex-M4 cycles per x86-64 instruction counted on the host: Thumb-2 needs up to about
#: 1.5 instructions per x86-64 instruction of this integer code, and the M4 running from
#: flash with its cache averages at most about 2 cycles per instruction.
CYCLES_PER_HOST_INSTRUCTION = 3.0
TEENSY_HZ = 180e6
#: The board's I/O per tick [us], from the waits in firmware/teensy/hasel_wheel_fw/board.cpp:
#: the EMS22A's 16-bit read with 1 us clock phases (34), the 16-bit shift-out and latch with
#: 1 us edges (34), two 12-bit ADC reads (about 10 each), USB writes of the tick's frames
#: (about 1 us per 10 bytes: 5 typical, 100 with a full buffer's answers).
IO_US = {"typical": 34 + 34 + 20 + 5, "commands": 34 + 34 + 20 + 100,
         "starts": 34 + 34 + 20 + 100, "answers": 34 + 34 + 20 + 100}
TICK_US = 1e6 / 300


def instructions_per_tick(bench: str, mode: str) -> float:
    """Instructions per tick of the core, from two callgrind runs."""
    counts = []
    for n in (1000, 11000):
        r = subprocess.run(["valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null",
                            "--toggle-collect=hasel::Device::tick*",
                            "--toggle-collect=hasel::Device::receive*", bench, str(n), mode],
                           capture_output=True, text=True, check=True)
        counts.append(int(re.search(r"Collected : (\d+)", r.stderr).group(1)))
    return (counts[1] - counts[0]) / 10000


def main() -> None:
    build = build_core(BUILD_ROOT)
    print("firmware core, one tick (callgrind, inside Device::tick and Device::receive):")
    if shutil.which("valgrind") is None:
        print("  valgrind not found: install it (apt-get install valgrind) for this figure")
    else:
        for mode in ("typical", "commands", "starts", "answers"):
            n = instructions_per_tick(str(build / "hasel_tick_bench"), mode)
            core_us = n * CYCLES_PER_HOST_INSTRUCTION / TEENSY_HZ * 1e6
            total = core_us + IO_US[mode]
            print(f"  {mode:8s} {n:9,.0f} host instructions -> Teensy 3.6: core {core_us:6.1f} us"
                  f" + I/O {IO_US[mode]} us = {total:6.1f} us, {total / TICK_US:5.1%} of the "
                  f"{TICK_US:.0f} us tick")
    r = run_lockstep(default_build(), seconds=60.0, seed=1)
    held = [v for sec, v in enumerate(r.speeds[:50], start=1) if sec > 2 and sec % 10 not in (6, 7)]
    print(f"lockstep C++ core vs Python device, 60 s realistic plant, MPC, faults: "
          f"{r.ticks:,} ticks, {r.frames:,} frames, {r.bytes:,} bytes compared; "
          f"switch-ons {r.switch_ons}, mismatch: {r.first_mismatch or 'none'}; "
          f"speed at whole seconds 3-50 s but the two after each fault "
          f"{min(held):.3f}-{max(held):.3f} rad/s (reference {r.reference})")

if __name__ == "__main__":
    main()
