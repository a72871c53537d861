"""The virtual Teensy's transmit path on a real pty, in-process and without its thread: a host
that stops reading loses whole frames, never parts of one, and what was queued arrives."""
import os

import pytest

from hasel_wheel_common import protocol as P
from hasel_wheel_sim.plant import Plant, PlantConfig
from hasel_wheel_sim.firmware import Firmware
from hasel_wheel_sim.pty_device import TX_BUFFER_BYTES, VirtualTeensy


@pytest.fixture
def device(tmp_path):
    vt = VirtualTeensy(Firmware(Plant(config=PlantConfig(switching="tick"), xi2=2.0)),
                       tmp_path / "teensy")
    vt.plug()
    host = os.open(vt.link, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    yield vt, host
    os.close(host)
    vt.unplug()


def read_all(fd):
    out = bytearray()
    while True:
        try:
            chunk = os.read(fd, 65536)
        except BlockingIOError:
            return bytes(out)
        if not chunk:
            return bytes(out)
        out += chunk


def test_a_host_that_does_not_read_loses_whole_frames_and_then_gets_the_queue(device):
    vt, host = device
    n = 6000                                   # ~290 kB of telemetry: far beyond every buffer
    for _ in range(n):
        [vt._send(w) for w in vt.fw.tick()]
    tel = [f for f in vt.sent if f.type == P.TELEMETRY]
    kept = [f.message.sample_seq for f in tel if f.intact]
    frame_len = len(P.encode(tel[0].message, 1)) + 1
    # the queue took frames until it was full, then dropped every later one whole
    assert vt.write_drops == n - len(kept) > 0
    assert kept == list(range(1, len(kept) + 1))
    assert len(kept) * frame_len >= TX_BUFFER_BYTES       # the queue, and the pty besides
    # the host reads: everything that was kept arrives, in order, with no damaged frame
    d = P.FrameDecoder()
    got = []
    for _ in range(1000):
        vt._flush()
        data = read_all(host)
        got += [f.message.sample_seq for f in d.feed(data)]
        if not data and not vt._txq:
            break
    assert got == kept
    assert d.stats.dropped == 0
    # the stream is still framed: the next frame after the drops arrives intact
    [vt._send(w) for w in vt.fw.tick()]
    assert [f.message.sample_seq for f in d.feed(read_all(host))] == [n + 1]
    assert d.stats.sequence_gaps == n - len(kept)          # the gap the host sees is the drops


def test_frames_queued_at_unplug_are_counted_lost(device):
    vt, host = device
    for _ in range(3000):
        [vt._send(w) for w in vt.fw.tick()]
    queued = len(vt._txq_frames)
    assert queued > 0
    drops = vt.write_drops
    vt.unplug()
    assert vt.write_drops == drops + queued and not vt._txq
    assert sum(f.intact for f in vt.sent) == len(vt.sent) - vt.write_drops
