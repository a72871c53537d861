"""The virtual Teensy's firmware: the device rules of ``docs/protocol.md`` section 4 around a
:class:`~.plant.Plant` in tick-switching mode (pure, no I/O).

HV interlock, command latching at switch-off, tick-sampled switching, watchdog, maximum
on-time, emergency stop.  :mod:`.pty_device` serves it on a pseudo-terminal;
``test_firmware.py`` holds the rules.
"""
from __future__ import annotations

import math

from hasel_wheel_common import protocol as P

from hasel_wheel_sim import layout as L
from hasel_wheel_sim.model import SECTOR, angle_reading
from hasel_wheel_sim.plant import COUNT, Plant


class Firmware:
    """Device behaviour (protocol section 4) around a :class:`Plant` in tick-switching mode."""

    def __init__(self, plant: Plant) -> None:
        if plant.config.switching != "tick":
            raise ValueError("the firmware switches on ticks: build the plant with switching='tick'")
        self.plant = plant
        self.reset()

    def reset(self) -> None:
        """Power-up state: HV off, nothing latched, estop clear, default configuration."""
        self.plant.wheel.cut_hv()
        self.config = P.Config()
        self.hv_enabled = False
        self.estop = False
        self.faults = 0
        self.counter = 0
        self.sample_seq = 0
        self.last_host_t = self.plant.t
        self.watchdog_trips = 0
        self.hv_off_t: float | None = None  # simulated time HV was last switched off

    # -- host frames --------------------------------------------------------------------
    def receive(self, frame: P.Frame) -> P.Message:
        """Handle one valid host frame; return the ACK or REJECT to send."""
        self.last_host_t = self.plant.t
        m = frame.message
        seq = m.command_seq if isinstance(m, P.Command) else 0

        def reject(reason: int) -> P.Reject:
            if isinstance(m, P.Command):
                self.faults |= P.F_REJECTED
            return P.Reject(frame.type, frame.counter, seq, reason)

        if isinstance(m, P.Command):
            reason = P.check_command(m.n_a, m.phi_a, m.phi_d)
            if reason:
                return reject(reason)
            if self.estop:
                return reject(P.R_ESTOP)
            if not self.hv_enabled:
                return reject(P.R_HV_DISABLED)
            # float32 angles may exceed pi/8 by a rounding step: clamp into the range
            pa = min(max(float(m.phi_a), -SECTOR), SECTOR)
            pd = min(max(float(m.phi_d), -SECTOR), SECTOR)
            self.plant.wheel.command(m.n_a, pa, pd, m.command_seq)
            self.faults &= ~(P.F_REJECTED | P.F_MAX_ON)
        elif isinstance(m, P.Hv):
            if m.enable:
                if self.estop:
                    return reject(P.R_ESTOP)
                self.hv_enabled = True
                self.faults &= ~P.F_WATCHDOG
            else:
                self.hv_off()
        elif isinstance(m, P.Estop):
            self.hv_off()
            self.estop = True
            self.faults |= P.F_ESTOP
        elif isinstance(m, P.ClearEstop):
            self.estop = False
            self.faults &= ~P.F_ESTOP
        elif isinstance(m, P.Config):
            if P.check_config(m):
                return reject(P.R_CONFIG)
            self.config = m
        return P.Ack(frame.type, frame.counter, seq)

    def hv_off(self) -> None:
        """Switch HV off now (disabled until a host HV enable) and note when."""
        if self.hv_enabled or self.plant.wheel.s[L.S_Q]:
            self.hv_off_t = self.plant.t
        self.hv_enabled = False
        self.plant.wheel.cut_hv()

    # -- ticks --------------------------------------------------------------------------
    def tick(self) -> P.Telemetry:
        """One firmware tick: watchdog, maximum on-time, physics, then the telemetry sample."""
        c = self.config
        if self.hv_enabled and self.plant.t - self.last_host_t >= c.watchdog_ms / 1000.0 - 1e-9:
            self.hv_off()
            self.faults |= P.F_WATCHDOG
            self.watchdog_trips += 1
        s = self.plant.wheel.s
        if s[L.S_Q] and s[L.S_ON_TIME] >= c.max_on_ms / 1000.0:
            self.plant.wheel.cut_hv()
            self.faults |= P.F_MAX_ON
        sample = self.plant.step(None, 1.0 / c.telemetry_rate_hz)
        self.sample_seq += 1
        xi1 = s[L.S_XI1]
        q = int(s[L.S_Q])
        eta_u = int(s[L.S_ETA])
        # a lost sample (plant dropout): the firmware still reads its sensor
        angle = sample.angle if sample is not None else angle_reading(xi1, self.plant.wheel.pv)
        return P.Telemetry(
            device_time_us=int(round(self.plant.t * 1e6)), sample_seq=self.sample_seq,
            encoder_raw=int(math.floor(angle / COUNT)) % 1024,
            encoder_unwrapped=int(math.floor(angle / COUNT)), q=q, eta=eta_u % 16,
            eta_unwrapped=eta_u, active_mask=(1 << (eta_u % 16)) if q else 0,
            hv_monitor=9000.0 if self.hv_enabled else 0.0, current_monitor=3e-4 if q else 0.0,
            last_command_seq=max(int(s[L.S_CMD_SEQ]), 0), fault_flags=self.faults)

    def next_counter(self) -> int:
        """The frame counter of the next frame the device sends (16 bits, wraps)."""
        self.counter = (self.counter + 1) & 0xFFFF
        return self.counter
