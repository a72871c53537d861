"""The driver core refuses bad commands locally and survives a failing consumer."""
import math
import os
import struct
import tty

import pytest

from hasel_wheel_common import protocol as P
from hasel_wheel_driver.link import DriverCore, LinkConfig, RefusalCode
from hasel_wheel_common.samples import Command


@pytest.mark.parametrize("cmd, code, field", [
    (Command(16, 0.05, 0.3), RefusalCode.N_A, "n_a = 16"),
    (Command(3, math.inf, 0.3), RefusalCode.ANGLE, "phi_a = inf"),
    (Command(3, 0.3, 0.05), RefusalCode.ORDER, "0.3"),
])
def test_bad_commands_are_refused_before_the_wire(cmd, code, field):
    core = DriverCore(LinkConfig("/nonexistent"))
    refusal = core.send_command(cmd)
    assert refusal.code == code == P.check_command(cmd.n_a, cmd.phi_a, cmd.phi_d)
    assert field in refusal
    assert core.stats.commands_sent == 0 and core.stats.commands_rejected_locally == 1


def test_no_link_no_command():
    core = DriverCore(LinkConfig("/nonexistent"))
    assert core.send_command(Command(3, 0.05, 0.3)).code == RefusalCode.NO_LINK


def test_a_raising_consumer_does_not_stop_the_link():
    master, slave = os.openpty()
    tty.setraw(slave)
    events = []

    def bad(_sample):
        raise RuntimeError("publisher's context is invalid")
    core = DriverCore(LinkConfig(os.ttyname(slave)), on_sample=bad, on_event=events.append)
    core._ser = None
    core._open()
    tel = P.Telemetry(1, 1, 0, 0, 0, 0, 0, 0, 0.0, 0.0, 0, 0)
    core._handle(P.encode(tel, 1) + P.encode(tel._replace(sample_seq=2), 2), 0.0)
    assert core.stats.samples == 2 and core.stats.callback_errors == 2
    assert sum("callback failed" in e for e in events) == 1
    core._close()
    os.close(master)
    os.close(slave)


def test_nothing_follows_hv_off_on_the_wire_during_shutdown():
    # another thread (the controller in the reader thread) tries to command while shutdown
    # waits for its ACKs: it is refused, and HV(0) stays the last frame
    master, slave = os.openpty()
    tty.setraw(slave)
    core = DriverCore(LinkConfig(os.ttyname(slave), ack_timeout=0.01))
    core._open()
    refused = []
    real_wait = core.wait_ack

    def wait_and_interfere(counter, timeout=None):
        refused.append(core.send_command(Command(3, 0.05, 0.3, 99)))
        return real_wait(counter, timeout)
    core.wait_ack = wait_and_interfere
    core.shutdown()
    os.set_blocking(master, False)
    frames = P.FrameDecoder().feed(os.read(master, 65536))
    assert [f.message for f in frames][-2:] == [P.Estop(), P.Hv(0)]
    assert not any(isinstance(f.message, P.Command) for f in frames)
    assert refused and all(r.code == RefusalCode.CLOSING for r in refused)
    os.close(master)
    os.close(slave)


def _read_all(fd, quiet=0.05):
    """Everything the host wrote, until the line has been quiet for ``quiet`` seconds."""
    import select
    out = b""
    while select.select([fd], [], [], quiet)[0]:
        out += os.read(fd, 65536)
    return out


def _pty_core(**kw):
    master, slave = os.openpty()
    tty.setraw(slave)
    os.set_blocking(master, False)
    return master, slave, DriverCore(LinkConfig(os.ttyname(slave), **kw))


def test_every_connect_first_switches_hv_off():
    # a short loss: the device did not reboot; its HV state must be made known (off) first
    master, slave, core = _pty_core(enable_hv_on_connect=True)
    core._open()
    frames = P.FrameDecoder().feed(_read_all(master))
    assert [f.message for f in frames][:3] == [P.Hv(0), P.ClearEstop(), P.Hv(1)]
    assert frames[0].counter == 1
    core._close()
    os.close(master)
    os.close(slave)


def test_a_dying_link_thread_leaves_hv_off_and_silences_everyone():
    master, slave, core = _pty_core()

    def broken(data, t):
        raise RuntimeError("decoder bug")
    core._handle = broken
    core.start()
    import time
    t_end = time.monotonic() + 30.0
    while not core.connected and time.monotonic() < t_end:
        time.sleep(0.005)
    os.write(master, P.encode(P.Telemetry(1, 1, 0, 0, 0, 0, 0, 0, 0.0, 0.0, 0, 0), 1))
    core._thread.join(30.0)
    assert not core._thread.is_alive() and "decoder bug" in core.reader_failed
    assert not core.connected
    assert core.send_command(Command(3, 0.05, 0.3)) is not None   # nothing more goes out
    frames = [f.message for f in P.FrameDecoder().feed(_read_all(master))]
    assert frames[-2:] == [P.Estop(), P.Hv(0)]
    assert "stopped" in core.diagnostics()["link_thread"]
    os.close(master)
    os.close(slave)


def test_a_device_restart_is_not_counted_as_lost_frames():
    d = P.FrameDecoder()
    d.feed(b"".join(P.encode(P.Hv(0), c) for c in (500, 501, 1, 2)))
    assert d.stats.sequence_gaps == 0 and d.stats.restarts == 1


# -- START (protocol v1.1): sent for Command(now=True); a v1.0 device answers none -------------

@pytest.mark.parametrize("cmd, code", [
    (Command(16, 0.05, 0.3, now=True), RefusalCode.N_A),
    (Command(3, math.nan, 0.3, now=True), RefusalCode.ANGLE),
    (Command(3, -0.1, 0.1, now=True), RefusalCode.ORDER),
])
def test_a_bad_start_is_refused_before_the_wire_as_a_command_is(cmd, code):
    core = DriverCore(LinkConfig("/nonexistent"))
    assert core.send_command(cmd).code == code
    assert core.stats.commands_sent == core.stats.starts_sent == 0


class Clock:
    """A clock the test moves [s]."""

    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


@pytest.fixture
def linked():
    """A connected link on a pty with a test clock: (master fd, core, clock, events)."""
    master, slave, core = _pty_core()
    events = []
    core.on_event, core.clock = events.append, Clock()
    core._open()
    _read_all(master)                                   # HV(0) of the connect
    yield master, core, core.clock, events
    core._close()
    os.close(master)
    os.close(slave)


def test_a_now_command_goes_out_as_a_start_and_an_answered_start_keeps_it_on(linked):
    master, core, clock, events = linked
    assert core.send_command(Command(3, 0.05, 0.3, 7, now=True)) is None
    assert core.send_command(Command(4, 0.05, 0.3, 8)) is None
    frames = P.FrameDecoder().feed(_read_all(master))
    f32 = [struct.unpack("<f", struct.pack("<f", v))[0] for v in (0.05, 0.3)]
    assert [(f.type, f.message) for f in frames] == [(P.START, P.Start(7, 3, *f32)),
                                                     (P.COMMAND, P.Command(8, 4, *f32))]
    assert (core.stats.commands_sent, core.stats.starts_sent) == (2, 1)
    # a v1.1 device answers (here: REJECT, the pad not in contact); nothing is concluded
    core._handle(P.encode(P.Reject(P.START, frames[0].counter, 7, P.R_NOT_IN_CONTACT), 1), 0.0)
    clock.t += 1.0
    core._check_starts(clock())
    assert not core.stats.device_v1_0 and core.stats.starts_unanswered == 0
    assert core.send_command(Command(3, 0.05, 0.3, 9, now=True)) is None


def test_an_unanswered_start_marks_the_device_v1_0_and_later_starts_are_refused(linked):
    master, core, clock, events = linked
    assert core.send_command(Command(3, 0.05, 0.3, 7, now=True)) is None
    # a v1.0 device answers the heartbeat after it, not the START
    core._handle(P.encode(P.Ack(P.HEARTBEAT, 2, 0), 1), 0.0)
    clock.t += 0.099
    core._check_starts(clock())
    assert not core.stats.device_v1_0                   # not yet: within ack_timeout
    clock.t += 0.002
    core._check_starts(clock())
    assert core.stats.device_v1_0 and core.stats.starts_unanswered == 1
    assert sum("v1.0" in e for e in events) == 1
    assert core.diagnostics()["device_protocol"].startswith("1.0")
    _read_all(master)
    refusal = core.send_command(Command(3, 0.05, 0.3, 8, now=True))
    assert refusal.code == RefusalCode.NO_START and core.stats.commands_rejected_locally == 1
    assert core.send_command(Command(3, 0.05, 0.3, 9)) is None    # COMMANDs still go
    assert [f.type for f in P.FrameDecoder().feed(_read_all(master))] == [P.COMMAND]
    core._close()
    core._open()                                        # a new connection may be a new device
    assert not core.stats.device_v1_0


def test_an_unanswered_start_on_a_stale_link_concludes_nothing(linked):
    master, core, clock, events = linked
    assert core.send_command(Command(3, 0.05, 0.3, 7, now=True)) is None
    core.stale = True
    clock.t += 1.0
    core._check_starts(clock())
    assert not core.stats.device_v1_0 and core.stats.starts_unanswered == 0 and not core._starts
