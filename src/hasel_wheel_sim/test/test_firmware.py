"""The virtual Teensy's board: a device core wired to the plant.  The device decides on its
own readings (noise and glitches included) and the wheel gets HV exactly as decided; the
rules themselves are in ``test_device_rules.py``."""
import math

import pytest

from hasel_wheel_common import protocol as P
from hasel_wheel_sim import layout as L
from hasel_wheel_sim.effects import effects_from_mapping
from hasel_wheel_sim.firmware import Firmware
from hasel_wheel_sim.plant import Plant, PlantConfig

D = math.radians
NOISY = effects_from_mapping({"encoder": {"enabled": True, "noise_std": {"value": 0.001, "unit": "rad"}},
                              "encoder_glitches": {"enabled": True, "probability": {
                                  "value": 0.02, "unit": "1"}}})


class Host:
    """Sends frames with counters, and a heartbeat every 10 ticks."""

    def __init__(self, fw):
        self.fw, self.counter, self.k = fw, 0, 0

    def send(self, msg):
        self.counter += 1
        self.fw.receive(P.encode(msg, self.counter))

    def tick(self):
        if self.k % 10 == 0:
            self.send(P.Heartbeat(0))
        self.k += 1
        frames = [f for w in self.fw.tick() for f in P.FrameDecoder().feed(w)]
        return frames[-1].message


@pytest.fixture
def noisy_board(make_core):
    return Firmware(Plant(config=PlantConfig(seed=3, effects=NOISY), xi2=3.0), make_core())


def test_the_wheel_gets_hv_exactly_when_and_where_the_device_switches(noisy_board):
    fw = noisy_board
    host = Host(fw)
    host.send(P.Hv(1))
    tels = []
    for k in range(900):
        if k % 30 == 5:               # the next pad after the one in contact (eq. (40))
            host.send(P.Command(k, (tels[-1].encoder_unwrapped // 64 + 1) % 16, D(3), D(22)))
        tels.append(host.tick())
        s = fw.plant.wheel.s
        assert int(s[L.S_Q]) == tels[-1].q                     # the wheel is driven as told
        if tels[-1].q:
            assert int(s[L.S_ETA]) == tels[-1].eta_unwrapped
    ons = [k for k in range(1, len(tels)) if tels[k].q and not tels[k - 1].q]
    assert len(ons) >= 10 and fw.plant.wheel.s[L.S_XI2] > 3.0     # it rolls and is driven
    for k in ons:                                               # on at the first reading past
        t = tels[k]
        a = math.ceil(D(3) / (2 * math.pi / 1024))
        assert t.encoder_unwrapped >= 64 * t.eta_unwrapped + a
    glitches = [t for t in tels if t.fault_flags & P.F_ENCODER]
    assert 5 <= len(glitches) <= 40                              # 2 % of 900, each not taken


def test_the_monitors_read_what_the_board_drove_and_hv_off_is_recorded(make_core):
    fw = Firmware(Plant(config=PlantConfig(), xi2=2.0), make_core())
    host = Host(fw)
    assert host.tick().hv_monitor == 0.0
    host.send(P.Hv(1))
    host.tick()
    assert host.tick().hv_monitor == 9000.0
    for _ in range(40):                                         # silence: the watchdog trips
        fw.tick()
    assert not fw.hv_enabled and fw.watchdog_trips == 1
    assert fw.hv_off_t == pytest.approx(0.0 + 31 / 300, abs=1 / 300 + 1e-9)


def test_reset_switches_every_pad_off(make_core):
    fw = Firmware(Plant(config=PlantConfig(), xi1=0.0, xi2=2.0), make_core())
    host = Host(fw)
    host.send(P.Hv(1))
    host.send(P.Command(1, 0, D(0), D(22)))
    for _ in range(3):
        host.tick()
    assert fw.plant.wheel.s[L.S_Q] == 1.0
    fw.reset()
    assert fw.plant.wheel.s[L.S_Q] == 0.0 and not fw.hv_enabled and fw.outputs.active_mask == 0


def test_a_start_drives_the_standing_wheel_from_the_contact_angle_it_read(make_core):
    # pad 0 in contact at 10 deg: a START switches it on, and the model's force law rises from
    # the contact angle of the reading (firmware.rise_angle), not from phi_a = 3 deg
    fw = Firmware(Plant(config=PlantConfig(), xi1=D(10), xi2=0.0), make_core())
    host = Host(fw)
    host.tick()                                                 # the first reading
    host.send(P.Hv(1))
    host.tick()
    host.send(P.Start(5, 0, D(3), D(22)))
    tel = host.tick()
    s = fw.plant.wheel.s
    assert (tel.q, tel.eta_unwrapped, tel.last_command_seq, int(s[L.S_Q])) == (1, 0, 5, 1)
    assert s[L.S_PHI_A] == tel.encoder_unwrapped * 2 * math.pi / 1024
    assert D(10) - 2 * math.pi / 1024 < s[L.S_PHI_A] <= D(10)
