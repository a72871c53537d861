"""The virtual Teensy's firmware against protocol v1 section 4, frame by frame (no I/O)."""
import math
import struct

import pytest

from hasel_wheel_common import protocol as P
from hasel_wheel_sim import layout as L
from hasel_wheel_sim.model import SECTOR
from hasel_wheel_sim.plant import Plant, PlantConfig
from hasel_wheel_sim.firmware import Firmware

D = math.radians


def f32(x):
    return struct.unpack("<f", struct.pack("<f", x))[0]


@pytest.fixture
def fw():
    return Firmware(Plant(config=PlantConfig(switching="tick"), xi2=2.0))


def send(fw, msg, counter=1):
    return fw.receive(P.Frame(P.TYPE_OF[type(msg)], counter, msg))


def test_hv_is_off_at_power_up_and_commands_are_refused(fw):
    assert not fw.hv_enabled and fw.tick().hv_monitor == 0.0
    r = send(fw, P.Command(1, 2, D(3), D(22)))
    assert r == P.Reject(P.COMMAND, 1, 1, P.R_HV_DISABLED) and fw.faults & P.F_REJECTED
    assert all(fw.tick().q == 0 for _ in range(100))


def test_float32_pi_over_8_is_accepted_and_clamped(fw):
    # float32(pi/8) is 4e-9 above pi/8: legal, and it must not upset the device
    send(fw, P.Hv(1))
    assert f32(SECTOR) > SECTOR
    r = send(fw, P.Command(7, 1, f32(D(3)), f32(SECTOR)), 2)
    assert r == P.Ack(P.COMMAND, 2, 7)
    assert fw.plant.wheel.s[L.S_PEND_PHI_D] == SECTOR


@pytest.mark.parametrize("cmd, reason", [
    (P.Command(1, 16, 0.05, 0.3), P.R_N_A), (P.Command(1, 3, math.nan, 0.3), P.R_ANGLE),
    (P.Command(1, 3, 0.5, 0.6), P.R_ANGLE), (P.Command(1, 3, 0.3, 0.1), P.R_ORDER),
    (P.Command(1, 3, -0.1, 0.1), P.R_ORDER)])
def test_invalid_commands_are_rejected_and_change_nothing(fw, cmd, reason):
    send(fw, P.Hv(1))
    send(fw, P.Command(5, 3, D(3), D(22)), 2)
    pending = fw.plant.wheel.s[L.S_PEND_NA]
    assert send(fw, cmd, 3).reason == reason
    assert fw.plant.wheel.s[L.S_PEND_NA] == pending and fw.tick().fault_flags & P.F_REJECTED


def test_estop_latches_until_cleared(fw):
    send(fw, P.Hv(1))
    send(fw, P.Estop(), 2)
    assert not fw.hv_enabled and fw.tick().fault_flags & P.F_ESTOP
    assert send(fw, P.Hv(1), 3).reason == P.R_ESTOP
    assert send(fw, P.Command(1, 2, D(3), D(22)), 4).reason == P.R_ESTOP
    assert send(fw, P.ClearEstop(), 5) == P.Ack(P.CLEAR_ESTOP, 5, 0)
    assert not fw.hv_enabled                          # clearing does not enable HV
    assert isinstance(send(fw, P.Hv(1), 6), P.Ack) and fw.hv_enabled


def test_watchdog_cuts_hv_after_100_ms_of_silence(fw):
    send(fw, P.Hv(1))
    t0 = fw.plant.t
    while fw.hv_enabled:
        tel = fw.tick()
    assert fw.plant.t - t0 == pytest.approx(0.100, abs=1 / 300 + 1e-9)
    assert tel.fault_flags & P.F_WATCHDOG and tel.hv_monitor == 0.0 and tel.q == 0


def test_maximum_on_time_switches_the_actuator_off(fw):
    send(fw, P.Hv(1))
    send(fw, P.Config(300, 1000, 50, 0), 2)            # 50 ms maximum on-time
    send(fw, P.Command(1, fw.tick().eta_unwrapped % 16 + 1 & 15, D(3), D(22)), 3)
    on = []
    for k in range(600):
        if k % 10 == 0:
            send(fw, P.Heartbeat(0), 10 + k)            # keep the watchdog quiet
        tel = fw.tick()
        on.append(tel.q)
        if tel.fault_flags & P.F_MAX_ON:
            break
    assert tel.fault_flags & P.F_MAX_ON and tel.q == 0
    assert 15 <= sum(on) <= 16                          # 50 ms = 15 ticks (+1 at the cut)
    assert isinstance(send(fw, P.Command(9, 3, D(3), D(22)), 999), P.Ack)
    assert not fw.tick().fault_flags & P.F_MAX_ON       # cleared by the next accepted command


@pytest.mark.parametrize("cfg", [P.Config(10, 100, 2000, 0), P.Config(300, 5, 2000, 0),
                                 P.Config(300, 100, 2000, 1)])
def test_bad_configuration_is_rejected(fw, cfg):
    assert send(fw, cfg).reason == P.R_CONFIG and fw.config == P.Config()
