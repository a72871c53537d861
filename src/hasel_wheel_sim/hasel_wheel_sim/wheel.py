"""One wheel of the hybrid model, as a Python object over the compiled core.

:class:`HybridWheel` is what the plant and the MPC predictor hold.  It validates commands,
keeps the state vector (:mod:`.layout`) and advances it with :func:`.integrator.advance`.
:func:`initial_state` builds state rows for batches (:func:`.integrator.simulate_batch`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from hasel_wheel_common import protocol as P

from hasel_wheel_sim import layout as L
from hasel_wheel_sim.integrator import advance
from hasel_wheel_sim.model import (N_ACTUATORS, SECTOR, Extensions, angle_at_reading, angle_reading,
                                  param_vector)
from hasel_wheel_sim.params import WheelParams

#: The firmware / paper control period [s].
TICK = 1.0 / 300.0

SwitchMode = Literal["exact", "tick"]
SequentialRule = Literal["after_active", "after_measured"]

_NO_EVENTS = np.zeros((0, 4))
_NO_EVENTS.setflags(write=False)
_RULES = {"after_active": L.AUTO_AFTER_ACTIVE, "after_measured": L.AUTO_AFTER_MEASURED}
_MODES = {"exact": L.MODE_EXACT, "tick": L.MODE_TICK}


#: Slack on the +-pi/8 limit [rad]: angles travel as float32 (float32(pi/8) > pi/8 by 4e-9),
#: the same slack as the protocol's check.
ANGLE_TOLERANCE = 1e-6


class CommandError(ValueError):
    """An actuation command is not acceptable; the message says what would be, :attr:`code`
    is the protocol's reject reason (``R_N_A``, ``R_ANGLE`` or ``R_ORDER``)."""

    def __init__(self, message: str, code: int) -> None:
        super().__init__(message)
        self.code = code


def validate_command(n_a: int, phi_a: float, phi_d: float) -> None:
    """Check u = (n_a, phi_a, phi_d): n_a in 0..15, finite angles in [-pi/8, pi/8] rad,
    phi_a < phi_d, and both on the same side of 0 (both >= 0 accelerate, both <= 0 brake).
    """
    if isinstance(n_a, bool) or not isinstance(n_a, (int, np.integer)) or not 0 <= n_a < N_ACTUATORS:
        raise CommandError(f"n_a = {n_a!r} is not an actuator index; expected an integer 0..15",
                           P.R_N_A)
    for name, v in (("phi_a", phi_a), ("phi_d", phi_d)):
        if not isinstance(v, (int, float, np.floating)) or not math.isfinite(v):
            raise CommandError(f"{name} = {v!r} is not a finite angle; expected rad in "
                               f"[-pi/8, pi/8]", P.R_ANGLE)
        if abs(v) > SECTOR + ANGLE_TOLERANCE:
            raise CommandError(f"{name} = {v!r} rad is outside [-pi/8, pi/8] = "
                               f"[-{SECTOR:.6f}, {SECTOR:.6f}] rad", P.R_ANGLE)
    if not phi_a < phi_d:
        raise CommandError(f"phi_a = {phi_a!r} rad must be smaller than phi_d = {phi_d!r} rad",
                           P.R_ORDER)
    if phi_a < 0.0 < phi_d:
        raise CommandError(f"phi_a = {phi_a!r} and phi_d = {phi_d!r} rad straddle 0; use both "
                           f">= 0 to accelerate or both <= 0 to brake", P.R_ORDER)


def initial_state(xi1: float = 0.0, xi2: float = 0.0, mode: SwitchMode = "exact") -> np.ndarray:
    """A state vector (S_SIZE,) at rest in the paper's initial condition (q = 0, idle)."""
    if mode not in _MODES:
        raise ValueError(f"switching mode {mode!r} unknown; expected one of {sorted(_MODES)}")
    s = np.zeros(L.S_SIZE)
    s[L.S_XI1] = xi1
    s[L.S_XI2] = xi2
    s[L.S_ETA] = math.floor(xi1 / SECTOR)
    s[L.S_THETA_ON] = math.inf
    s[L.S_THETA_OFF] = math.inf
    s[L.S_ON_SPEED] = math.inf
    s[L.S_MODE] = _MODES[mode]
    return s


def set_open_loop(s: np.ndarray, phi_a: float, phi_d: float,
                  rule: SequentialRule = "after_active", priming: int = 0,
                  priming_phi_a: float = math.radians(3.0)) -> None:
    """Configure the built-in sequential schedule of a state vector (in place).

    Every switch-off latches n_a = next actuator, with (phi_a, phi_d).  ``rule`` picks how
    "next" is counted: after the actuator of interest (eta + 1), or after the sector measured
    at switch-off (eq. (40): floor(xi1 / (pi/8)) + 1).  ``priming`` first activations use
    ``priming_phi_a`` instead (the paper primes with six activations at 3 deg).
    """
    validate_command(0, phi_a, phi_d)
    validate_command(0, priming_phi_a, phi_d)
    if rule not in _RULES:
        raise ValueError(f"sequential rule {rule!r} unknown; expected one of {sorted(_RULES)}")
    s[L.S_AUTO] = _RULES[rule]
    s[L.S_AUTO_PHI_A] = phi_a
    s[L.S_AUTO_PHI_D] = phi_d
    s[L.S_PRIME_LEFT] = priming
    s[L.S_PRIME_PHI_A] = priming_phi_a


@dataclass(frozen=True)
class HybridState:
    """The six hybrid states (angles rad, speed rad/s); eta is the unwrapped sector."""

    xi1: float
    xi2: float
    q: int
    act_counter: float
    deact_counter: float
    eta: int

    @property
    def actuator(self) -> int:
        """Index 0..15 of the actuator of interest."""
        return self.eta % N_ACTUATORS


class HybridWheel:
    """One wheel: parameters, extensions, switching mode and state, advanced tick by tick."""

    def __init__(self, params: WheelParams | None = None, extensions: Extensions | None = None,
                 mode: SwitchMode = "exact", xi1: float = 0.0, xi2: float = 0.0) -> None:
        self.params = params or WheelParams()
        self.extensions = extensions or Extensions()
        self.pv = param_vector(self.params, self.extensions)
        self.s = initial_state(xi1, xi2, mode)
        self._ev = np.zeros((L.EV_MAX_PER_TICK, 4))

    # -- inputs ---------------------------------------------------------------------------
    def command(self, n_a: int, phi_a: float, phi_d: float, seq: int = 0) -> None:
        """Queue u.  While an actuator is on, it is latched when that actuator switches off;
        otherwise (idle, or a target that has not switched on yet) at the next step."""
        validate_command(n_a, phi_a, phi_d)
        s = self.s
        s[L.S_PEND] = 1.0
        s[L.S_PEND_NA] = n_a
        s[L.S_PEND_PHI_A] = phi_a
        s[L.S_PEND_PHI_D] = phi_d
        s[L.S_PEND_SEQ] = seq

    def start_now(self, n_a: int, phi_a: float, phi_d: float, seq: int = 0) -> int:
        """Switch pad ``n_a`` on now if its contact angle (as read) lies in [phi_a, phi_d)
        [rad]; it switches off at phi_d like a latched command (protocol v1.1 START).

        Returns 0 when it switched on, else the protocol's reject reason: R_ACTUATOR_ON while
        an actuator is on, R_NOT_IN_CONTACT outside the window; nothing changes then.  The
        pending command is forgotten.  Raises :class:`CommandError` on values a COMMAND would
        refuse.  Test: ``test_wheel_start.py``.
        """
        validate_command(n_a, phi_a, phi_d)
        s = self.s
        if s[L.S_Q] != 0.0:
            return P.R_ACTUATOR_ON
        reading = angle_reading(s[L.S_XI1], self.pv)
        k = math.floor((reading - phi_a) / SECTOR)            # last sector whose phi_a is passed
        n = k - (k - n_a) % N_ACTUATORS
        if reading >= n * SECTOR + phi_d:
            return P.R_NOT_IN_CONTACT
        s[L.S_PEND] = 0.0
        s[L.S_ETA] = n
        s[L.S_PHI_A] = reading - n * SECTOR
        s[L.S_PHI_D] = phi_d
        s[L.S_THETA_ON] = s[L.S_XI1]
        s[L.S_THETA_OFF] = angle_at_reading(n * SECTOR + phi_d, self.pv)
        s[L.S_CMD_SEQ] = seq
        s[L.S_ARMED] = 1.0
        s[L.S_Q] = 1.0
        s[L.S_ON_TIME] = 0.0
        s[L.S_ON_SPEED] = s[L.S_XI2]
        s[L.S_N_ON] += 1.0
        return 0

    def open_loop(self, phi_a: float, phi_d: float, rule: SequentialRule = "after_active",
                  priming: int = 0, priming_phi_a: float = math.radians(3.0)) -> None:
        """Run the built-in sequential schedule (see :func:`set_open_loop`)."""
        set_open_loop(self.s, phi_a, phi_d, rule, priming, priming_phi_a)

    def cut_hv(self) -> None:
        """Switch every actuator off now and forget the latched and the pending command.

        Not part of the paper's model: it is what HV-off, the watchdog and the emergency stop
        do on the device.  The wheel then coasts (idle) until a new command is latched.
        """
        s = self.s
        s[L.S_Q] = 0.0
        s[L.S_ARMED] = 0.0
        s[L.S_PEND] = 0.0
        s[L.S_AUTO] = L.AUTO_OFF
        s[L.S_THETA_ON] = math.inf
        s[L.S_THETA_OFF] = math.inf

    def drive(self, sector: int | None, phi_a: float = 0.0, seq: int = 0) -> None:
        """Apply HV as a device decided it: ``sector`` is the unwrapped sector of the pad that
        gets HV (None: no pad), ``phi_a`` [rad] the activation angle it was commanded with
        (the force law's rise starts there), ``seq`` its command's sequence number.

        For a wheel whose switching the device decides (:mod:`.firmware`): no command is ever
        latched in the model (it stays idle), so its own tick switching never acts.
        """
        s = self.s
        on = sector is not None
        if s[L.S_Q] and (not on or sector != s[L.S_ETA]):
            s[L.S_Q] = 0.0
            s[L.S_N_OFF] += 1.0
        if on and not s[L.S_Q]:
            s[L.S_Q] = 1.0
            s[L.S_ETA] = sector
            s[L.S_PHI_A] = phi_a
            s[L.S_ON_TIME] = 0.0
            s[L.S_ON_SPEED] = s[L.S_XI2]
            s[L.S_CMD_SEQ] = seq
            s[L.S_N_ON] += 1.0

    # -- flow -----------------------------------------------------------------------------
    def advance(self, h: float = TICK) -> np.ndarray:
        """Advance by h seconds; return the events (k, 4): time, xi1, kind, eta."""
        n = advance(self.s, self.pv, h, self._ev)
        if n == 0:
            return _NO_EVENTS
        return self._ev[:min(n, L.EV_MAX_PER_TICK)].copy()

    # -- read-out -------------------------------------------------------------------------
    @property
    def t(self) -> float:
        return float(self.s[L.S_T])

    @property
    def state(self) -> HybridState:
        """The six hybrid states; idle counters are +inf (no target latched)."""
        s = self.s
        q = int(s[L.S_Q])
        xi1 = float(s[L.S_XI1])
        if s[L.S_ARMED] == 0.0:
            act, deact = math.inf, math.inf
        else:
            act = 0.0 if q else float(s[L.S_THETA_ON]) - xi1
            deact = float(s[L.S_THETA_OFF]) - xi1
        return HybridState(xi1, float(s[L.S_XI2]), q, act, deact, int(s[L.S_ETA]))
