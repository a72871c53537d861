"""The closed speed loop in the embedded runner: plant -> observer -> estimator -> MPC -> plant.

Everything runs in lockstep simulated time at 300 Hz.  The controller
(:class:`~hasel_wheel_mpc.controller.SpeedController`) decides at each switch-on reported in
telemetry (paper Sec. V-B); the command reaches the plant through its serial-latency effect
and is latched at the current actuator's switch-off.  The ROS nodes call the same control
core and send the same commands
(``test_core.py::test_the_node_path_sends_the_embedded_runners_commands``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from hasel_wheel_common import samples
from hasel_wheel_common.samples import Command
from hasel_wheel_sim.model import Extensions
from hasel_wheel_sim.params import WheelParams
from hasel_wheel_sim import layout as L
from hasel_wheel_sim.plant import Plant, PlantConfig
from hasel_wheel_sim.wheel import TICK

from hasel_wheel_mpc.config import ControllerConfig
from hasel_wheel_mpc.controller import SpeedController
from hasel_wheel_mpc.disturbance import TRACKING_GAIN
from hasel_wheel_mpc.mpc import MpcConfig
from hasel_wheel_mpc.observer import ObserverConfig
from hasel_wheel_mpc.segments import SegmentMetrics, SegmentTracker  # noqa: F401  (SegmentMetrics: re-export)

D = math.radians

#: Fig. 11-like profile: (start time [s], reference [rad/s]).
FIG11_PROFILE = ((0.0, 1.0), (40.0, 1.5), (80.0, 2.0), (120.0, 2.5), (160.0, 2.6), (200.0, 2.0))
FIG11_DURATION = 230.0


def reference_at(profile, t: float) -> float:
    ref = profile[0][1]
    for t0, r in profile:
        if t >= t0:
            ref = r
    return ref


@dataclass
class LoopLog:
    t: list = field(default_factory=list)
    true_speed: list = field(default_factory=list)
    est_speed: list = field(default_factory=list)
    reference: list = field(default_factory=list)
    d: list = field(default_factory=list)
    decisions: list = field(default_factory=list)     # (t, Decision)

    def arrays(self):
        return {k: np.asarray(v) for k, v in self.__dict__.items() if k != "decisions"}


def run_closed_loop(profile=FIG11_PROFILE, duration: float = FIG11_DURATION,
                    plant_config: PlantConfig | None = None, params: WheelParams | None = None,
                    estimator_gain: float | None = TRACKING_GAIN, speed_source: str = "observer",
                    mpc_config: MpcConfig | None = None, w0: float = 1.0,
                    estimator_mode: str = "tracking", observer_config=None,
                    recorder=None, ns: str = "/wheel0",
                    controller_params: WheelParams | None = None,
                    controller_extensions: Extensions | None = None,
                    clock: Callable[[], float] | None = None) -> LoopLog:
    """Run the loop on ``profile`` ((start [s], reference [rad/s]), ...) for ``duration`` [s].

    ``params`` are the plant's; its extensions come from ``plant_config``'s effects.  The
    controller (:class:`~hasel_wheel_mpc.controller.SpeedController`) uses
    ``controller_params`` and ``controller_extensions`` (default: the plant's ``params`` and
    no extensions, the paper's model), so a controller model other than the plant (e.g. an
    identified one) can be tried against the same plant.  ``estimator_gain`` None disables
    the disturbance estimator (``estimator_mode`` 'tracking' or 'paper'); ``speed_source``
    'observer' or 'finite_difference'.  With a ``recorder`` (recorder.Recorder) every sample,
    estimate, decision and reference change is written under namespace ``ns``, and the
    controller's configuration as ``<ns>/controller.yaml`` in the bag's configuration (what
    :func:`~hasel_wheel_bringup.replay.replay_bag` reads).  ``clock`` [s] is the MPC's clock for
    its deadline (default wall time; a constant clock makes the run independent of the
    machine's speed).
    """
    params = params or WheelParams()
    cfg = controller_config(estimator_gain, speed_source, mpc_config, estimator_mode,
                            observer_config, controller_params or params, controller_extensions)
    return run_controller(cfg, profile, duration, plant_config, params, w0, recorder, ns, clock)


def controller_config(estimator_gain: float | None = TRACKING_GAIN, speed_source: str = "observer",
                      mpc_config: MpcConfig | None = None, estimator_mode: str = "tracking",
                      observer_config: ObserverConfig | None = None,
                      controller_params: WheelParams | None = None,
                      controller_extensions: Extensions | None = None) -> ControllerConfig:
    """The :class:`ControllerConfig` that :func:`run_closed_loop`'s keyword arguments mean."""
    return ControllerConfig(controller_params or WheelParams(),
                            controller_extensions or Extensions(),
                            observer_config or ObserverConfig(), mpc_config or MpcConfig(),
                            estimator_gain, estimator_mode, speed_source=speed_source)


def run_controller(cfg: ControllerConfig, profile=FIG11_PROFILE,
                   duration: float = FIG11_DURATION, plant_config: PlantConfig | None = None,
                   params: WheelParams | None = None, w0: float = 1.0, recorder=None,
                   ns: str = "/wheel0", clock: Callable[[], float] | None = None,
                   progress: str | None = None) -> LoopLog:
    """:func:`run_closed_loop` with the controller given as a :class:`ControllerConfig`;
    ``progress`` as :func:`run_wheels`'s."""
    return run_wheels([WheelLoop(cfg, profile, plant_config, params, w0, recorder, ns, clock)],
                      duration, progress)[0]


def run_wheels(wheels: list["WheelLoop"], duration: float,
               progress: str | None = None) -> list[LoopLog]:
    """Step several wheels in lockstep for ``duration`` [s] (one tick each, in turn), so a
    shared recorder writes their messages in time order; returns each wheel's log.
    ``progress``, when given, labels a bar of the simulated seconds on stderr (on a terminal)."""
    ticks = range(int(duration / TICK))
    if progress:
        from hasel_wheel_bag.progress import progress_bar
        ticks = progress_bar(ticks, progress, unit=" s", scale=TICK)
    for _ in ticks:
        for w in wheels:
            w.step()
    return [w.log for w in wheels]


class WheelLoop:
    """One wheel's closed loop (plant, controller, recording), advanced one tick per
    :meth:`step`.  Arguments as :func:`run_controller`'s."""

    def __init__(self, cfg: ControllerConfig, profile=FIG11_PROFILE,
                 plant_config: PlantConfig | None = None, params: WheelParams | None = None,
                 w0: float = 1.0, recorder=None, ns: str = "/wheel0",
                 clock: Callable[[], float] | None = None) -> None:
        self.profile = profile
        self.plant = Plant(params or WheelParams(), plant_config or PlantConfig(switching="tick"),
                           xi2=w0)
        self.ctrl = SpeedController(cfg, clock)
        self.recorder, self.ns = recorder, ns
        if recorder is not None:
            recorder.configuration({f"{ns}/controller.yaml": cfg.to_yaml()})
        self.log = LoopLog()
        # the start command goes out before the first sample; recorded as mpc_node publishes
        # it, so every pad a bag's commands drive has its angles
        self._pending: Command | None = self.ctrl.start(self.plant.wheel.s[L.S_XI1], w0)
        if recorder is not None and self._pending is not None:
            recorder.command(ns, self._pending, 0.0)
        self._last_ref = None

    def step(self) -> None:
        """One 300 Hz tick: plant, then (if a sample came) controller and recording."""
        s = self.plant.step(self._pending)
        self._pending = None
        if s is None:
            return
        ref = reference_at(self.profile, s.t)
        r = self.ctrl.step(samples.as_received(s), ref)
        if r.hv_off:             # the core gave up a stalled wheel: HV off, as the driver does
            self.plant.wheel.cut_hv()
        rec, ns, log = self.recorder, self.ns, self.log
        if rec is not None:
            rec.telemetry(ns, s)
            rec.true_state(ns, self.plant.t, self.plant.wheel.state)
            rec.estimate(ns, r.estimate, s.t)
            if ref != self._last_ref:
                rec.reference(ns, s.t, ref)
        self._last_ref = ref
        log.t.append(s.t)
        log.true_speed.append(self.plant.wheel.s[2])
        log.est_speed.append(r.speed)
        log.reference.append(ref)
        log.d.append(r.d_before)
        if r.command is not None:
            self._pending = r.command
        if r.decision is not None:
            log.decisions.append((s.t, r.decision))
            if rec is not None:
                rec.decision(ns, s.t, r.decision, ref, r.d)
        elif r.command is not None and rec is not None:
            rec.command(ns, r.command, s.t)


def start_time(log: LoopLog, reference: float) -> float:
    """Time [s] from the start of the run until the true speed first reaches ``reference``
    [rad/s]; nan if it never does (``test_start_stall.py``)."""
    v = np.asarray(log.true_speed)
    hit = np.flatnonzero(v >= reference)
    return float(log.t[hit[0]]) if len(hit) else math.nan


def segment_metrics(log: LoopLog, profile=FIG11_PROFILE, duration: float = FIG11_DURATION,
                    window: float = 10.0) -> list[SegmentMetrics]:
    """Per reference segment of ``profile``, on the true speed (see
    :mod:`~hasel_wheel_mpc.segments`); the last segment ends at ``duration`` [s].  The steady
    window is the last ``window`` seconds of each segment; the transition time is the rise
    time of a step up and the fall time of a step down, measured as the braking calibration
    does (from the step until the new reference is first reached); NaN for the first segment.
    """
    tracker = SegmentTracker(window)
    refs = iter(profile)
    nxt = next(refs, None)
    for t, v in zip(log.t, log.true_speed):
        while nxt is not None and nxt[0] <= t:
            tracker.reference(*nxt)
            nxt = next(refs, None)
        tracker.sample(t, v)
    while nxt is not None:
        tracker.reference(*nxt)
        nxt = next(refs, None)
    return tracker.finish(duration)
