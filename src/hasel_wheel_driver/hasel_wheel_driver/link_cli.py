"""``hasel_wheel_link``: the serial driver without ROS (bring-up, bench tests, scripts).

Connects to the wheel, optionally enables HV, prints link health once a second, and on
SIGINT/SIGTERM sends ESTOP then HV(0) (the last frame on the wire) before exiting.
"""
from __future__ import annotations

import argparse
import signal
import sys
import threading
import time
from typing import Sequence

from hasel_wheel_driver.link import DriverCore, LinkConfig


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="hasel_wheel_link", description=__doc__)
    ap.add_argument("--port", required=True,
                    help="serial device, e.g. /dev/serial/by-id/usb-Teensyduino_... or /dev/ttyACM0")
    ap.add_argument("--enable-hv", action="store_true", help="send HV on after connecting")
    ap.add_argument("--seconds", type=float, default=0.0, help="stop after this long (0: run until signalled)")
    ap.add_argument("--heartbeat", type=float, default=0.02, help="heartbeat period [s]")
    args = ap.parse_args(argv)

    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    core = DriverCore(LinkConfig(args.port, heartbeat_period=args.heartbeat,
                                 enable_hv_on_connect=args.enable_hv),
                      on_event=lambda e: print(f"link: {e}", flush=True)).start()
    t_end = time.monotonic() + args.seconds if args.seconds > 0 else float("inf")
    try:
        while not stop.wait(1.0 if args.seconds <= 0 else min(1.0, max(t_end - time.monotonic(), 0))):
            if time.monotonic() >= t_end:
                break
            print("link: " + ", ".join(f"{k}={v}" for k, v in core.diagnostics().items()), flush=True)
    finally:
        acked = core.shutdown()
        print(f"link: shut down, HV off {'confirmed' if acked else 'NOT confirmed (no link)'}",
              flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
