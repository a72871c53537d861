"""The driver's link, over a real pseudo-terminal, to a virtual Teensy that runs the C++
firmware core (built for the host) instead of the Python device: the MPC holds a reference
through it, so the firmware's own logic is in the closed loop."""
import gc
import signal
import subprocess
import sys
import time

import pytest

from hasel_wheel_common.samples import as_received
from hasel_wheel_driver.link import DriverCore, LinkConfig
from hasel_wheel_mpc.closed_loop import controller_config
from hasel_wheel_mpc.controller import SpeedController
from hasel_wheel_sim.device_process import DeviceProcess
from hasel_wheel_sim.params import packaged
from hasel_wheel_sim.plant import load_plant_config
from hasel_wheel_common import protocol as P

SCALE = 3.0                   # simulated seconds per wall second
REFERENCE = 1.5               # [rad/s]
#: Initial wheel speed [rad/s]: the device streams from power-up while the wheel coasts (the
#: paper's wheel, which has no start push), so it must still roll when the host connects
W0 = 4.0
#: the device's watchdog counts simulated time; scaled runs use the protocol's longest
SCALED_CONFIG = P.Config(telemetry_rate_hz=300, watchdog_ms=1000, max_on_ms=2000, drain_mode=0)


class Loop:
    """The MPC as the driver's sample consumer, recording every sample."""

    def __init__(self):
        self.ctrl = SpeedController(controller_config(), clock=lambda: 0.0)
        self.core = None
        self.samples = []

    def on_sample(self, s):
        self.samples.append(s)
        r = self.ctrl.step(as_received(s), REFERENCE)
        if r.command is not None:
            self.core.send_command(r.command)


def test_the_mpc_holds_a_reference_through_the_cpp_firmware_core(tmp_path, firmware_build):
    gc.collect()
    gc.freeze()                      # keep the collector from pausing the host's threads
    link = tmp_path / "usb-Teensyduino_HASEL_wheel-if00"
    realistic = load_plant_config(packaged("hasel_wheel_sim", "plant_realistic.yaml"))
    vt = DeviceProcess(link, realistic, w0=W0, time_scale=SCALE, core_build=firmware_build)
    loop = Loop()
    core = DriverCore(LinkConfig(str(link), heartbeat_period=0.02, link_timeout=0.25,
                                 enable_hv_on_connect=True, device_config=SCALED_CONFIG),
                      on_sample=loop.on_sample)
    loop.core = core
    core.start()
    try:
        t_end = time.monotonic() + 60.0
        while time.monotonic() < t_end and not (loop.samples and loop.samples[-1].t > 30.0):
            time.sleep(0.1)
    finally:
        core.shutdown()
        rep = vt.stop()
        gc.unfreeze()
    s = loop.samples
    assert s and s[-1].t > 30.0, "the device never ran 30 s"
    # the mean speed over the last 10 s, from the encoder's unwrapped angle
    last = [x for x in s if x.t >= s[-1].t - 10.0]
    mean = (last[-1].angle - last[0].angle) / (last[-1].t - last[0].t)
    assert mean == pytest.approx(REFERENCE, rel=0.02)
    switch_ons = sum(1 for a, b in zip(s, s[1:]) if b.q and not a.q)
    assert switch_ons > 60                                  # the firmware switched the pads
    assert not rep.faults_seen and rep.watchdog_trips == 0
    assert not rep.hv_enabled                               # the driver's shutdown: HV off


def test_virtual_teensy_command_serves_the_cpp_core_until_sigint(tmp_path, firmware_build):
    link = tmp_path / "teensy"
    proc = subprocess.Popen([sys.executable, "-m", "hasel_wheel_bringup.cli", "virtual-teensy",
                             str(link), "--device-core", "cpp"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    samples = []
    core = None
    try:
        t_end = time.monotonic() + 120.0
        while not link.is_symlink() and time.monotonic() < t_end and proc.poll() is None:
            time.sleep(0.05)
        core = DriverCore(LinkConfig(str(link), enable_hv_on_connect=True),
                          on_sample=samples.append)
        core.start()
        while time.monotonic() < t_end and not (len(samples) > 300 and samples[-1].hv_monitor > 0):
            time.sleep(0.05)
    finally:
        if core is not None:
            core.shutdown()
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=30)
    assert len(samples) > 300 and any(x.hv_monitor == 9000.0 for x in samples), out
    # the driver's shutdown reached the device (its monitor reads the tick before: not asked)
    assert samples[-1].fault_flags & P.F_ESTOP
    assert proc.returncode == 0, out
    assert not link.exists()                      # unplugged on the way out
