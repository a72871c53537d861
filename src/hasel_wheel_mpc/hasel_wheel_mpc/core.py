"""The control core: disturbance estimator, decision scheduling, start, stall and pad
policies, and the MPC.

One :class:`ControlCore` object holds everything the speed loop decides after the observer:
the estimator's cycle window and prediction queue, when the MPC decides (paper Sec. V-B),
how a wheel is started and restarted (:mod:`.start_policy`), which pads still push
(:mod:`.pad_health`), and which command angles each sequence number stands for.  The
embedded runner (:class:`~hasel_wheel_mpc.controller.SpeedController`) and ``mpc_node`` both
call it the same way, per device sample:

1. :meth:`ControlCore.telemetry` with the raw sample (encoder angle, latched command);
2. :meth:`ControlCore.step` with the observer's estimate of that sample and the reference;
   it answers with a command to send, or None.

Tests, without ROS: ``test_core.py`` (the start policy; the node path's commands equal to the
embedded runner's through a start, a step up and a braking step down), ``test_controller.py``
(decision points; a step down braked at the next switch-on with d unchanged across it) and
``test_start_stall.py`` (from rest, through an obstacle, past a dead pad).
"""
from __future__ import annotations

import math
from collections import OrderedDict, deque
from typing import Callable, NamedTuple

import numpy as np

from hasel_wheel_common.samples import Command, PadEdges
from hasel_wheel_sim import layout as L
from hasel_wheel_sim.model import N_ACTUATORS, SECTOR, acceleration
from hasel_wheel_sim.wheel import TICK

from hasel_wheel_mpc.config import ControllerConfig
from hasel_wheel_mpc.disturbance import IntegralEstimator
from hasel_wheel_mpc.mpc import Decision, Mpc, next_pad
from hasel_wheel_mpc.observer import Estimate, ObserverConfig
from hasel_wheel_mpc.pad_health import PadHealth, PadVerdict
from hasel_wheel_mpc.start_policy import StallMonitor, StallVerdict

#: (phi_a, phi_d) [rad] of the start command (sequence 0), and of any latched command whose
#: sequence number the core did not send: the observer's angles for an unknown command.
START_ANGLES = (ObserverConfig.default_phi_a, ObserverConfig.default_phi_d)
#: (phi_a, phi_d) [rad] window of a START (protocol v1.1) for a standing wheel: the pad in
#: contact, wherever it is in its sector; it switches off at the sector's end.
START_NOW_WINDOW = (0.0, SECTOR)
#: Decide on an idle wheel after this many samples with HV off [samples].
IDLE_SAMPLES = 150
#: Re-decide on a new reference only if the next switching is at least this far away [s].
REDECIDE_MIN_TIME = 0.02
#: Send the start command again after this many samples without its pad latched [samples].
START_PERIOD = 30
#: Extra lead of the start command over the MPC's deadline margin (its way to the device) [s].
START_LEAD = 0.1
#: Below this speed [rad/s] the start policy switches each pad on with a START as it comes
#: into contact (the most push a slow wheel can get); faster, with sequence-0 commands.
START_SLOW = 0.6
#: A rolling wheel's pad in contact gets a START only up to this contact angle [rad]; further
#: on it would push briefly before it switches off at the end of its sector.
START_MAX_CONTACT = SECTOR / 2
#: Encoder samples the start policy reads the wheel's speed from [samples].
START_SAMPLES = 30
#: The least time those samples must span before a start command is aimed [s].
START_WINDOW = 0.02
#: A pad's cycle (its switch-on to the next) longer than this says nothing of its push [s].
PAD_CYCLE_MAX = 1.0
#: Command angles remembered by sequence number (the latched one is always recent) [count].
ANGLES_KEPT = 64

#: Why the MPC decides at a sample (:func:`decision_point`).
SWITCH_ON, IDLE, NEW_REFERENCE, BETWEEN_PADS = "switch_on", "idle", "new_reference", "between_pads"
#: Why the core sends a start command (:attr:`CoreStep.why` while the wheel is not started).
START = "start"
#: :attr:`CoreStep.why` once the core has given up a stalled wheel (HV off, no commands).
STALLED = "stalled"


class CoreStatus(NamedTuple):
    """The core's health for ``/diagnostics``: ``level`` 0 OK, 1 WARN, 2 ERROR; ``code``
    one of 'ok', 'starting', 'restarting', 'pad_dead', 'stalled'; ``pads`` the pads it
    concerns (0..15); ``text`` the message."""

    level: int
    code: str
    pads: tuple[int, ...]
    text: str


def decision_point(reference_changed: bool, q: int, switched_on: bool, idle: int,
                   idle_samples: int, act_counter: float, deact_counter: float, speed: float,
                   min_time: float) -> str | None:
    """Why the MPC decides at this sample, or None.

    SWITCH_ON: the actuator of interest just switched on (paper Sec. V-B).  IDLE: HV has been
    off for ``idle_samples`` samples.  On a new reference, if there is at least ``min_time``
    [s] at ``speed`` [rad/s] before the next switching: NEW_REFERENCE while an actuator is on
    (``deact_counter`` [rad] to its switch-off; the waiting command is replaced), and
    BETWEEN_PADS while none is (``act_counter`` [rad] to the pending switch-on; that target
    is replaced, by a braking pad only, because the MPC predicts from a pad that is on).
    Test: ``test_controller.py::test_decision_points``.
    """
    if switched_on:
        return SWITCH_ON
    if idle == idle_samples:
        return IDLE
    if reference_changed:
        lead = min_time * max(speed, 0.1)
        if q == 1 and deact_counter > lead:
            return NEW_REFERENCE
        if q == 0 and act_counter > lead:
            return BETWEEN_PADS
    return None


def decide_at(mpc: Mpc, why: str, xi1: float, speed: float, eta_unwrapped: int,
              phi_a_now: float, phi_d_now: float, reference: float, d: float,
              disturbance: tuple, act_counter: float) -> Decision | None:
    """The MPC's decision at a :func:`decision_point` ``why``, or None.

    Between two pads only a braking command replaces the pending target, and only when the
    speed (+ d) is ``brake_threshold`` above the reference.  On an idle wheel a driving
    command latches on arrival and the telemetry's pad is stale, so its pad is the first whose
    switch-on is still ahead then (:func:`~hasel_wheel_mpc.mpc.next_pad`).  Angles rad (xi1
    unwrapped), speeds rad/s, ``act_counter`` rad to the pending switch-on, ``disturbance``
    the observer's a_d coefficients [rad/s^2].
    """
    if why == BETWEEN_PADS:
        if speed + d < reference + mpc.config.brake_threshold:
            return None
        return mpc.brake_now(xi1, speed, d, act_counter)
    dec = mpc.decide(xi1, speed, eta_unwrapped, phi_a_now, phi_d_now, reference, d,
                     disturbance, pad_on=why != IDLE)
    if why == IDLE and not dec.braking:
        n_a = next_pad(xi1, speed, dec.command.phi_a, TICK + mpc.config.deadline_margin)
        dec = dec._replace(command=dec.command._replace(n_a=n_a))
    return dec


class CoreStep(NamedTuple):
    """What the core made of one estimate."""

    command: Command | None      # the command to send now, if any
    why: str | None              # START, or the decision point (SWITCH_ON, IDLE, ...)
    decision: Decision | None    # the MPC's decision behind ``command`` (None for START)
    d_before: float              # the estimator's d [rad/s] when the estimate arrived
    d: float                     # d [rad/s] after this estimate (changes at switch-offs)
    speed: float                 # xi2 the MPC sees [rad/s] (observer or finite difference)
    hv_off: bool = False         # the core gave up a stalled wheel: switch HV off now


class ControlCore:
    """Disturbance estimator, decision scheduling, start policy and MPC of one wheel.

    The MPC decides where :func:`decision_point` says.  Until the first switch-on (not a
    START's: the MPC takes over at the switch-on after it, once the wheel rolls), at every
    other sample the core sends a start command, at most every ``START_PERIOD`` samples: to a
    standing wheel with no pad on, or a slow one (``START_SLOW``) whose pad in contact is no
    further than ``START_MAX_CONTACT``, a START (``now``) of that pad in the window
    ``START_NOW_WINDOW``; otherwise, whenever no pad is latched within the next two sectors,
    sequence 0 for the pad whose activation angle ``START_ANGLES[0]`` is next ahead of the
    encoder's angle and speed, at ``START_ANGLES``.  A stalled wheel is restarted the same
    way, and given up (HV off) after ``config.start.max_restarts`` restarts in a row
    (:mod:`.start_policy`).  A pad found dead (:mod:`.pad_health`) is planned with its
    measured gain and skipped.  The estimator updates at each switch-off of the actuator of
    interest from the mean speed over the cycle that ended and the prediction made for it.
    ``clock`` [s] is the MPC's clock for its deadline (default wall time).
    """

    def __init__(self, config: ControllerConfig | None = None,
                 clock: Callable[[], float] | None = None) -> None:
        cfg = self.config = config or ControllerConfig()
        self.mpc = Mpc(cfg.params, cfg.extensions, config=cfg.mpc,
                       **({"clock": clock} if clock is not None else {}))
        self.estimator = (IntegralEstimator(gain=cfg.estimator_gain, mode=cfg.estimator_mode,
                                            gate=cfg.estimator_gate)
                          if cfg.estimator_gain else None)
        self.idle_samples = IDLE_SAMPLES
        self.redecide_min_time = REDECIDE_MIN_TIME
        self.started = False
        self.starts = 0                    # start commands sent [count]
        self._angles: OrderedDict[int, tuple[float, float]] = OrderedDict({0: START_ANGLES})
        self._latched = 0
        self._edges = PadEdges()
        self._idle = 0
        self._cycle: list[float] = []
        self._queued: list[float | None] = []    # predictions of cycles starting at switch-offs
        self._window_pred: float | None = None
        self._encoder: deque[tuple[float, float]] = deque(maxlen=START_SAMPLES)
        self._fd = 0.0
        self._last_ref: float | None = None
        self._new_ref = False
        self._samples = 0                  # estimates stepped [count]
        self._start_sample = 0
        self._start_now = False            # the last start command was a START
        self.stall = StallMonitor(cfg.start)
        self.gave_up: StallVerdict | None = None
        self.pads = PadHealth()
        self._base_gains = self.mpc.pv[L.P_GAINS:L.P_GAINS + N_ACTUATORS].copy()
        self._on: tuple[int, float, float, bool] | None = None   # pad, t, speed, braking

    @property
    def d(self) -> float:
        """The disturbance estimate [rad/s] (0 without an estimator)."""
        return self.estimator.d if self.estimator else 0.0

    def set_estimator(self, gain: float, mode: str, gate: float, dry_run: bool = False) -> None:
        """Change the disturbance estimator at run time: gain K [1 per cycle] (0 = off), mode
        'tracking' or 'paper', gate [rad/s]; d is kept.  Raises ValueError on a bad value
        (``dry_run``: only check)."""
        est = IntegralEstimator(gain=gain, gate=gate, mode=mode) if gain > 0.0 else None
        if dry_run:
            return
        if est is not None and self.estimator is not None:
            est.d, est.updates = self.estimator.d, self.estimator.updates
        self.estimator = est

    def angles_of(self, sequence: int) -> tuple[float, float]:
        """(phi_a, phi_d) [rad] of the command with this sequence number (START_ANGLES for
        one the core did not send)."""
        return self._angles.get(sequence, START_ANGLES)

    def telemetry(self, t: float, angle: float, latched_sequence: int) -> None:
        """A raw device sample: device time ``t`` [s], encoder ``angle`` [rad] (unwrapped) and
        the sequence number of the latched command.  Feeds the finite-difference speed and
        the start policy's speed."""
        if self._encoder and t > self._encoder[-1][0]:
            self._fd = (angle - self._encoder[-1][1]) / (t - self._encoder[-1][0])
        self._encoder.append((t, angle))
        self._latched = latched_sequence

    def start_command(self, angle: float, speed: float) -> Command | None:
        """The start command for a wheel at ``angle`` [rad] turning at ``speed`` [rad/s]: a
        START of the pad in contact (window ``START_NOW_WINDOW``) when the wheel stands
        (slower than ``config.start.still_speed``), or rolls slower than ``START_SLOW`` with
        the pad in contact no further than ``START_MAX_CONTACT`` (None when it is further: the
        next pad comes into contact soon); faster, sequence 0 at ``START_ANGLES``."""
        contact = angle - contact_sector(angle) * SECTOR
        if abs(speed) < self.config.start.still_speed or (
                abs(speed) < START_SLOW and contact <= START_MAX_CONTACT):
            return Command(contact_pad(angle), *START_NOW_WINDOW, 0, now=True)
        if abs(speed) < START_SLOW:
            return None
        lead = self.mpc.config.deadline_margin + START_LEAD
        return Command(next_pad(angle, speed, START_ANGLES[0], lead), *START_ANGLES, 0)

    def status(self) -> CoreStatus:
        """The core's health now (:class:`CoreStatus`)."""
        if self.gave_up is not None:
            pad = self.gave_up.pad
            return CoreStatus(2, STALLED, (pad,), f"stalled at pad {pad}: HV off after "
                              f"{self.stall.restarts} restarts")
        if self.pads.dead:
            dead = tuple(sorted(self.pads.dead))
            gains = ", ".join(f"pad {p} gain {self.pads.dead[p].gain:.2f}" for p in dead)
            return CoreStatus(1, "pad_dead", dead, f"dead pads skipped: {gains}")
        if self.stall.total_restarts and self.stall.restarts:
            return CoreStatus(1, "restarting", (), f"restart {self.stall.restarts} of "
                              f"{self.config.start.max_restarts}")
        if not self.started:
            return CoreStatus(0, "starting", (), "starting the wheel")
        return CoreStatus(0, "ok", (), "deciding")

    def step(self, e: Estimate, reference: float) -> CoreStep:
        """One estimate ``e`` (of the sample last given to :meth:`telemetry`) with the
        reference [rad/s] in force at its time."""
        d_before = self.d
        observer = self.config.speed_source == "observer"
        speed = e.xi2 if observer else self._fd
        if self.gave_up is not None:
            return CoreStep(None, STALLED, None, d_before, d_before, speed)
        self._samples += 1
        self._cycle.append(speed)
        self._idle = 0 if e.q else self._idle + 1
        switched_on, switched_off = self._edges.step(e.q, e.eta_unwrapped)
        self._track_reference(reference)
        if switched_off:
            self._end_cycle(speed, reference)
        if switched_on:
            self._pad_cycle(e, speed)
            self._on = (e.eta_unwrapped % N_ACTUATORS, e.t, speed,
                        self.angles_of(self._latched)[0] < 0.0)
        d = self.d
        enc = self._encoder_speed()
        still = enc is not None and abs(enc) < self.config.start.still_speed
        if self.stall.step(e.t, still, speed, reference, self.started):
            self.started = False                  # stalled: the start policy takes over
        start_pad = switched_on and self._start_now   # a START's pad: the start policy goes on
        if start_pad:
            self._start_now = False
        self.started = self.started or (switched_on and not start_pad)
        why = None if start_pad else decision_point(
            self._new_ref, e.q, switched_on, self._idle, self.idle_samples, e.act_counter,
            e.deact_counter, speed, self.redecide_min_time)
        if why is None and not self.started:
            cmd = self._start(e)
            if self.gave_up is not None:
                return CoreStep(None, STALLED, None, d_before, d, speed, hv_off=True)
            return CoreStep(cmd, START if cmd else None, None, d_before, d, speed)
        if why is None:
            return CoreStep(None, None, None, d_before, d, speed)
        self._new_ref = False
        pa_now, pd_now = self.angles_of(self._latched)
        dec = decide_at(self.mpc, why, e.xi1, speed, e.eta_unwrapped, pa_now, pd_now,
                        reference, d, e.accel_coefficients if observer else (0.0, 0.0, 0.0),
                        e.act_counter)
        if dec is None:
            return CoreStep(None, why, None, d_before, d, speed)
        self._sent(dec.command)
        self._queue(why, None if dec.braking else dec.predicted_speed - d)
        self._idle = 0
        return CoreStep(dec.command, why, dec, d_before, d, speed)

    def _track_reference(self, reference: float) -> None:
        """A new reference counts until the next decision; cycles predicted for the old one
        say nothing about the model's error against the new one, the one ending now too."""
        last = reference if self._last_ref is None else self._last_ref
        self._last_ref = reference
        if reference != last:
            self._new_ref = True
            self._window_pred = None
            self._queued = [None] * len(self._queued)

    def _end_cycle(self, speed: float, reference: float) -> None:
        """At a switch-off: the window [previous switch-off, this one) is a cycle some
        decision predicted; the estimator compares its mean speed with that prediction."""
        if self.estimator and self._window_pred is not None and len(self._cycle) > 1:
            self.estimator.step(float(np.mean(self._cycle[:-1])), self._window_pred, reference)
        self._window_pred = self._queued.pop(0) if self._queued else None
        self._cycle = [speed]

    def _queue(self, why: str, prediction: float | None) -> None:
        """File a decision's model-only prediction [rad/s] (None: a braking cycle) for the
        cycle it starts."""
        if why == BETWEEN_PADS:           # the pending pad's cycle is now a braking one
            self._window_pred = None
        elif why == NEW_REFERENCE and self._queued:
            self._queued[-1] = prediction
        else:
            self._queued.append(prediction)

    def _sent(self, cmd: Command) -> None:
        self._angles[cmd.sequence] = (cmd.phi_a, cmd.phi_d)
        while len(self._angles) > ANGLES_KEPT:
            self._angles.popitem(last=False)

    def _encoder_speed(self) -> float | None:
        """The wheel's speed [rad/s] over the encoder window, None until it spans
        ``START_WINDOW`` (the start pad comes from the encoder, not from an observer still
        converging)."""
        if len(self._encoder) < 2 or self._encoder[-1][0] - self._encoder[0][0] < START_WINDOW:
            return None
        (t0, a0), (t1, a1) = self._encoder[0], self._encoder[-1]
        return (a1 - a0) / (t1 - t0)

    def _start(self, e: Estimate) -> Command | None:
        """The start policy's command at this estimate, or None: the encoder has not yet
        spanned ``START_WINDOW``, the last start command went out less than
        ``START_PERIOD`` samples ago (it may still be on its way; re-aiming at once would
        make the target flip between two pads), a pad is on, or (a rolling wheel) a pad is
        latched whose switch-on is within two sectors ahead or passed by less than the wheel
        turns in ``START_LEAD`` (the estimate may lead the wheel)."""
        speed = self._encoder_speed()
        if speed is None or (self.starts and self._samples - self._start_sample < START_PERIOD):
            return None
        if e.q or (abs(speed) >= START_SLOW
                   and -max(speed, 0.0) * START_LEAD < e.act_counter <= 2.0 * SECTOR):
            return None
        angle = self._encoder[-1][1]
        cmd = self.start_command(angle, speed)
        if cmd is None:
            return None
        if cmd.now and abs(speed) < self.config.start.still_speed:   # a restart
            self.gave_up = self.stall.start(cmd.n_a)
            if self.gave_up is not None:
                return None
        return self.sent_start(cmd, angle)

    def sent_start(self, cmd: Command, angle: float) -> Command:
        """Record that the start command ``cmd``, aimed at the encoder ``angle`` [rad], goes
        out now (the embedded runner sends the first one before the first sample); returns
        it.  A START's angles are kept as the pad's contact angle there (where it switches
        on) and its phi_d."""
        self._start_sample = self._samples
        self._start_now = cmd.now
        self._sent(cmd._replace(phi_a=angle - contact_sector(angle) * SECTOR) if cmd.now else cmd)
        self.starts += 1
        return cmd

    def _pad_cycle(self, e: Estimate, speed: float) -> None:
        """A pad switched on: the cycle of the pad before it (from its switch-on to this one,
        so that the speed estimate has caught up with what the encoder saw) goes to
        :attr:`pads`; a pad found dead is planned with its measured gain and skipped from now
        on.  Braking cycles and cycles longer than ``PAD_CYCLE_MAX`` do not count."""
        if self._on is None:
            return
        pad, t_on, v_on, braking = self._on
        self._on = None
        if braking or not 0.0 < e.t - t_on <= PAD_CYCLE_MAX:
            return
        coast = acceleration(e.xi1, max(speed, 1e-3), 0.0, 0.0, 0.0, 1.0, 0.0, self.mpc.pv, 1.0)
        verdict = self.pads.cycle(pad, e.t, e.t - t_on, speed - v_on, coast)
        if verdict is not None:
            self.dead_pad(verdict)

    def dead_pad(self, verdict: PadVerdict) -> None:
        """Plan with ``verdict.pad``'s measured gain and stop driving it."""
        self.mpc.pv[L.P_GAINS + verdict.pad] = self._base_gains[verdict.pad] * verdict.gain
        self.mpc.skip.add(verdict.pad)


def contact_sector(angle: float) -> int:
    """Unwrapped sector of the pad in contact at the encoder ``angle`` [rad] (eq. (40)); a
    reading on a sector boundary belongs to the sector it begins."""
    return math.floor(angle / SECTOR + 1e-9)


def contact_pad(angle: float) -> int:
    """Index 0..15 of the pad in contact at the encoder ``angle`` [rad]."""
    return contact_sector(angle) % N_ACTUATORS
