"""The speed controller of the embedded runner: the observer, then the control core.

:class:`SpeedController` takes device samples one at a time (``step(sample, reference)``):
the observer (:class:`~hasel_wheel_mpc.observer.Observer`) estimates the six hybrid states,
and the control core (:class:`~hasel_wheel_mpc.core.ControlCore`) runs the disturbance
estimator and decides.  ``observer_node`` and ``mpc_node`` split the same two calls across
two processes.  The closed loop (:mod:`~hasel_wheel_mpc.closed_loop`) feeds it from the plant,
the bag replay (:mod:`~hasel_wheel_bringup.replay`) from a recording, both with the sample
as a node receives it (:func:`hasel_wheel_common.samples.as_received`), so a recorded run
can be re-computed exactly.  Test: ``test_core.py``.
"""
from __future__ import annotations

from typing import Callable, NamedTuple

from hasel_wheel_common.samples import Command, TelemetrySample

from hasel_wheel_mpc.config import ControllerConfig
from hasel_wheel_mpc.core import ControlCore
from hasel_wheel_mpc.mpc import Decision
from hasel_wheel_mpc.observer import Estimate, Observer


class ControlStep(NamedTuple):
    """What the controller made of one sample."""

    estimate: Estimate
    d_before: float              # the estimator's d [rad/s] when the sample arrived
    d: float                     # d [rad/s] after this sample (changes at switch-offs)
    speed: float                 # xi2 the MPC sees [rad/s] (observer or finite difference)
    decision: Decision | None    # the MPC's decision at this sample, if it decided
    command: Command | None      # the command to send now (a decision's or a start command)
    hv_off: bool = False         # the core gave up a stalled wheel: switch HV off now


class SpeedController:
    """Observer and control core of one wheel, stepped per device sample.  ``clock`` [s] is
    the MPC's clock for its deadline (default wall time)."""

    def __init__(self, config: ControllerConfig | None = None,
                 clock: Callable[[], float] | None = None) -> None:
        cfg = self.config = config or ControllerConfig()
        self.observer = Observer(cfg.params, cfg.extensions, config=cfg.observer)
        self.core = ControlCore(cfg, clock)
        self.mpc = self.core.mpc
        self.observer.command_sent(0, *self.core.angles_of(0))

    @property
    def d(self) -> float:
        """The disturbance estimate [rad/s] (0 without an estimator)."""
        return self.core.d

    def start(self, angle: float, speed: float) -> Command | None:
        """The first start command, sent before the first sample, for a wheel at ``angle``
        [rad] turning at ``speed`` [rad/s]; None for a standing or slow wheel, which the core
        starts from its first samples with a START (the pad in contact is the one the encoder
        reads, so a replay of the recording starts it alike)."""
        cmd = self.core.start_command(angle, speed)
        if cmd is None or cmd.now:
            return None
        cmd = self.core.sent_start(cmd, angle)
        self.observer.command_sent(cmd.sequence, cmd.phi_a, cmd.phi_d, cmd.now)
        return cmd

    def step(self, s: TelemetrySample, reference: float) -> ControlStep:
        """One device sample ``s`` with the reference [rad/s] in force at its time."""
        e = self.observer.step(s)
        self.core.telemetry(s.t, s.angle, s.last_command_sequence)
        r = self.core.step(e, reference)
        if r.command is not None:
            c = r.command
            self.observer.command_sent(c.sequence, c.phi_a, c.phi_d, c.now)
        return ControlStep(e, r.d_before, r.d, r.speed, r.decision, r.command, r.hv_off)
