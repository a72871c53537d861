"""The virtual Teensy's board: a device core wired to a :class:`~.plant.Plant` (pure, no I/O).

At every tick the board reads the plant's encoder (its raw 10-bit reading, noise and glitches
included) and its HV and current monitors, hands them to the device core, and applies what
the core decides (which pad gets HV) to the wheel for the tick's physics.  The core is the
Python reference (:class:`~.device_core.DeviceCore`) or the C++ firmware core built for the
host (:class:`~.device_cpp.CppDeviceCore`); either decides switching from its own readings,
as the Teensy does.  :mod:`.pty_device` serves a board on a pseudo-terminal;
``test_firmware.py`` holds the board, ``test_device_rules.py`` the device rules.
"""
from __future__ import annotations

import math
from typing import Protocol

from hasel_wheel_common import protocol as P

from hasel_wheel_sim.device_core import (COUNTS_PER_SECTOR, ENCODER_COUNTS, DeviceCore,
                                         DeviceState, Latched, Outputs, Sensors)
from hasel_wheel_sim.plant import ACTUATOR_CURRENT_A, HV_SUPPLY_V, Plant


def rise_angle(target: Latched) -> float:
    """The contact angle [rad] at which the model's force law rises for the pad the device
    switched on: a COMMAND's phi_a; for a START (protocol rule 8) the pad's contact angle on
    the reading it switched on at, c * 2 pi / 1024 - N * pi / 8.  ``test_firmware.py`` holds it."""
    if not target.now:
        return target.phi_a
    return (target.on_count - COUNTS_PER_SECTOR * target.sector) * 2.0 * math.pi / ENCODER_COUNTS


class Core(Protocol):
    """What a board needs of a device core (:class:`DeviceCore` and ``CppDeviceCore``)."""

    def reset(self) -> None: ...
    def receive(self, data: bytes) -> int: ...
    def tick(self, now_us: int, sensors: Sensors) -> tuple[list[bytes], Outputs]: ...
    def state(self) -> DeviceState: ...


class Firmware:
    """A device core (default: :class:`DeviceCore`) driving a :class:`Plant`'s wheel."""

    def __init__(self, plant: Plant, core: Core | None = None) -> None:
        self.plant = plant
        self.core = core or DeviceCore()
        self.reset()

    def reset(self) -> None:
        """Power-up: the core restarts (HV off, nothing latched), every pad is off."""
        self.core.reset()
        self.plant.wheel.cut_hv()
        self.plant.wheel.drive(None)
        self.outputs = Outputs()
        self.state = self.core.state()
        self.watchdog_trips = 0                 # times the device's watchdog switched HV off
        self.hv_off_t: float | None = None      # simulated time HV was last switched off [s]

    @property
    def hv_enabled(self) -> bool:
        return self.state.hv_enabled

    @property
    def estop(self) -> bool:
        return self.state.estop

    @property
    def faults(self) -> int:
        return self.state.faults

    @property
    def tick_period(self) -> float:
        """Seconds to the next tick at the configured telemetry rate."""
        return 1.0 / self.outputs.telemetry_rate_hz

    def receive(self, data: bytes) -> int:
        """Host bytes for the next tick; returns how many the device took."""
        return self.core.receive(data)

    def sensors(self) -> Sensors:
        """What the board reads now: the encoder, and the monitors of what it drove."""
        out = self.outputs
        return Sensors(self.plant.encoder_raw, True, HV_SUPPLY_V if out.hv_supply else 0.0,
                       ACTUATOR_CURRENT_A if out.active_mask else 0.0)

    def tick(self, sensors: Sensors | None = None) -> list[bytes]:
        """One tick: the core decides on ``sensors`` (default :meth:`sensors`), the wheel
        gets HV as decided for one tick period; returns the frames the device sent."""
        frames, out = self.core.tick(int(round(self.plant.t * 1e6)), sensors or self.sensors())
        before = self.state
        self.state = st = self.core.state()
        self.outputs = out
        if st.faults & P.F_WATCHDOG and not before.faults & P.F_WATCHDOG:
            self.watchdog_trips += 1
        if before.hv_enabled and not st.hv_enabled:
            self.hv_off_t = self.plant.t
        wheel = self.plant.wheel
        if out.active_mask:
            wheel.drive(st.eta_unwrapped, rise_angle(st.target), st.target.seq)
        else:
            wheel.drive(None)
        self.plant.step(None, self.tick_period)
        return frames

    def cut_power(self) -> None:
        """The board loses power: every pad off, the wheel coasts for one tick period."""
        self.plant.wheel.drive(None)
        self.outputs = Outputs()
        self.plant.step(None, self.tick_period)
