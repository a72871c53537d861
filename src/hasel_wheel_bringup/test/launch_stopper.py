"""Run a launch, stop it one way, and report how every process ended (a helper of
``test_launch_stops.py``, run as a script so that it can adopt orphaned processes).

    python launch_stopper.py WAY WORKDIR [--references NS] [launch file and arguments ...]

WAY is ``ctrl-c`` (0x03 on the launch's terminal: SIGINT to its foreground group),
``sigint-group`` (SIGINT to the launch's process group, the launch itself ignoring SIGINT
as a background job of a script does), ``sigterm-node`` (SIGTERM to the MPC node),
``sigterm-launch`` (SIGTERM to ``ros2 launch``) or ``launch-ends`` (wait for the launch to
shut itself down).  With ``--references NS``, once the wheel has started, the user's two
ways of setting the reference are run first, as the docs show them: ``ros2 topic pub
--once NS/reference_speed`` (1.5 rad/s) and ``ros2 param set NS/mpc_node reference_speed
2.0``, each followed by 5 s of running.  Prints one JSON object: the launch's exit status, each started
process's outcome as launch reported it, the exit status of processes the launch left
behind, and the lines that contain ERROR.
"""
from __future__ import annotations

import ctypes
import json
import os
import pty
import re
import select
import signal
import subprocess
import sys
import time

PR_SET_CHILD_SUBREAPER = 36
STARTED = re.compile(r"\[INFO\] \[([^\]]+)\]: process started with pid \[(\d+)\]")
ENDED = re.compile(r"\[(?:INFO|ERROR)\] \[([^\]]+)\]: process (has finished cleanly|has died)"
                   r"(?:[^\n]*?exit code (-?\d+))?")


class Launch:
    """``ros2 launch`` with its output collected (on a pty for ``ctrl-c``)."""

    def __init__(self, way: str, args: list[str]) -> None:
        cmd = ["ros2", "launch", "hasel_wheel_bringup", *args]
        self.text = b""
        if way == "ctrl-c":
            self.pid, self.fd = pty.fork()
            if self.pid == 0:
                signal.signal(signal.SIGINT, signal.SIG_DFL)
                os.execvp(cmd[0], cmd)
        else:
            disposition = signal.SIG_IGN if way == "sigint-group" else signal.SIG_DFL
            rfd, wfd = os.pipe()
            proc = subprocess.Popen(cmd, stdout=wfd, stderr=wfd, start_new_session=True,
                                    preexec_fn=lambda: signal.signal(signal.SIGINT,
                                                                     disposition))
            os.close(wfd)
            self.pid, self.fd = proc.pid, rfd
        self.status: int | None = None

    def read(self, seconds: float) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            ready, _, _ = select.select([self.fd], [], [], 0.1)
            if ready:
                try:
                    data = os.read(self.fd, 65536)
                except OSError:
                    data = b""
                if not data:
                    time.sleep(0.1)
                self.text += data
            if self.status is None:
                done, status = os.waitpid(self.pid, os.WNOHANG)
                if done:
                    self.status = os.waitstatus_to_exitcode(status)

    def wait_for(self, pattern: bytes, seconds: float) -> bool:
        end = time.monotonic() + seconds
        while pattern not in self.text and time.monotonic() < end and self.status is None:
            self.read(0.5)
        return pattern in self.text


def send_references(launch: Launch, ns: str) -> None:
    """The reference by topic (1.5 rad/s), then by parameter (2.0 rad/s), as a user sends
    them; the launch keeps running (and its output is read) meanwhile."""
    for cmd in (["ros2", "topic", "pub", "--once", f"{ns}/reference_speed",
                 "std_msgs/msg/Float64", "{data: 1.5}"],
                ["ros2", "param", "set", f"{ns}/mpc_node", "reference_speed", "2.0"]):
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        while proc.poll() is None:
            launch.read(0.2)
        launch.read(5.0)


def reap_orphans(seconds: float) -> list[int]:
    """Exit statuses of adopted processes that end within ``seconds``."""
    out, end = [], time.monotonic() + seconds
    while time.monotonic() < end:
        try:
            pid, status = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            break
        if pid == 0:
            time.sleep(0.1)
        else:
            out.append(os.waitstatus_to_exitcode(status))
    return out


def main() -> None:
    way, workdir, args = sys.argv[1], sys.argv[2], sys.argv[3:]
    references = None
    if args[:1] == ["--references"]:
        references, args = args[1], args[2:]
    os.chdir(workdir)
    ctypes.CDLL(None).prctl(PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0)
    launch = Launch(way, args)
    started = launch.wait_for(b"start: actuator", 300.0) or way == "launch-ends"
    launch.read(3.0)
    if references is not None:
        send_references(launch, references)
    if way == "ctrl-c":
        os.write(launch.fd, b"\x03")
    elif way == "sigint-group":
        os.killpg(launch.pid, signal.SIGINT)
    elif way == "sigterm-launch":
        os.kill(launch.pid, signal.SIGTERM)
    elif way == "sigterm-node":
        pids = {name: int(pid) for name, pid in STARTED.findall(launch.text.decode())}
        os.kill(next(pid for name, pid in pids.items() if name.startswith("mpc_node")),
                signal.SIGTERM)
    end = time.monotonic() + 120.0
    while launch.status is None and time.monotonic() < end:
        launch.read(0.5)
    launch.read(1.0)
    orphans = reap_orphans(5.0 if way == "sigterm-launch" else 0.0)
    text = launch.text.decode(errors="replace")
    print(json.dumps({
        "started": started, "launch_status": launch.status,
        "processes": sorted(name for name, _ in STARTED.findall(text)),
        "ended": {name: (how, int(code) if code else 0)
                  for name, how, code in ENDED.findall(text)},
        "orphan_statuses": orphans,
        "error_lines": [line for line in text.splitlines() if "ERROR" in line]}))


if __name__ == "__main__":
    main()
