"""A node process stops on its first SIGINT or SIGTERM, or when its parent exits; later
signals change nothing; before the node is built a request aborts the build at once."""
import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from hasel_wheel_common.stop_request import StopRequest, StopRequested


@pytest.fixture
def request_():
    stop = StopRequest()
    yield stop
    stop.restore()


def test_a_signal_while_the_node_is_built_aborts_the_build(request_):
    with pytest.raises(StopRequested, match="SIGTERM"):
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(1.0)                      # the handler runs before this ends
    assert request_.reason == "SIGTERM" and request_.stopped()


def test_once_armed_the_first_signal_is_recorded_and_later_ones_change_nothing(request_):
    request_.arm()
    assert not request_.stopped()
    os.kill(os.getpid(), signal.SIGINT)
    os.kill(os.getpid(), signal.SIGTERM)
    os.kill(os.getpid(), signal.SIGINT)
    assert request_.stopped() and request_.reason == "SIGINT"


def test_after_finish_a_late_signal_neither_kills_nor_raises(request_):
    request_.arm()
    request_.finish()
    os.kill(os.getpid(), signal.SIGINT)
    os.kill(os.getpid(), signal.SIGTERM)
    assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    assert request_.reason is None


def test_restore_puts_back_the_previous_handlers():
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    stop = StopRequest()
    assert signal.getsignal(signal.SIGTERM) != before[signal.SIGTERM]
    stop.restore()
    assert {s: signal.getsignal(s) for s in before} == before


CHILD = textwrap.dedent("""
    import sys, time
    from hasel_wheel_common.stop_request import StopRequest
    stop = StopRequest()
    stop.arm()
    print("ready", flush=True)
    end = time.monotonic() + 20.0
    while not stop.stopped() and time.monotonic() < end:
        time.sleep(0.05)
    print(stop.reason, flush=True)
""")


def test_a_process_whose_parent_exits_stops_itself(tmp_path):
    """The launch process killed outright: its node is re-parented and must notice."""
    out = tmp_path / "child.txt"
    middle = (f"import subprocess, sys, time\n"
              f"p = subprocess.Popen([sys.executable, '-c', {CHILD!r}], "
              f"stdout=open({str(out)!r}, 'w'))\n"
              f"while 'ready' not in open({str(out)!r}).read(): time.sleep(0.05)\n")
    subprocess.run([sys.executable, "-c", middle], check=True, timeout=60)   # middle exits
    end = time.monotonic() + 20.0
    while time.monotonic() < end and len(out.read_text().split()) < 2:
        time.sleep(0.1)
    assert out.read_text().split("\n")[:2] == ["ready", "parent exited"]
