"""The closed speed loop in the embedded runner: plant -> observer -> estimator -> MPC -> plant.

Everything runs in lockstep simulated time at 300 Hz.  The controller decides at each
switch-on reported in telemetry (paper Sec. V-B); the command reaches the plant through its
serial-latency effect and is latched at the current actuator's switch-off.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, NamedTuple

import numpy as np

from hasel_wheel_driver.samples import Command
from hasel_wheel_sim.model import Extensions
from hasel_wheel_sim.params import WheelParams
from hasel_wheel_sim.plant import Plant, PlantConfig
from hasel_wheel_sim.wheel import TICK

from .disturbance import IntegralEstimator
from .mpc import Mpc, MpcConfig
from .observer import Observer

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
                    estimator_gain: float | None = 0.1, speed_source: str = "observer",
                    mpc_config: MpcConfig | None = None, w0: float = 1.0,
                    estimator_mode: str = "tracking", observer_config=None,
                    recorder=None, ns: str = "/wheel0",
                    controller_params: WheelParams | None = None,
                    controller_extensions: Extensions | None = None,
                    clock: Callable[[], float] | None = None) -> LoopLog:
    """Run the loop on ``profile`` ((start [s], reference [rad/s]), ...) for ``duration`` [s].

    ``params`` are the plant's; its extensions come from ``plant_config``'s effects.  The
    observer and the MPC use ``controller_params`` and ``controller_extensions`` (default: the
    plant's ``params`` and no extensions, the paper's model), so a controller model other than
    the plant (e.g. an identified one) can be tried against the same plant.
    ``estimator_gain`` None disables the disturbance estimator (``estimator_mode`` 'tracking'
    or 'paper'); ``speed_source`` 'observer' or 'finite_difference' (what the MPC sees as xi2;
    with the finite difference the observer's disturbance is not used either).  With a
    ``recorder`` (recorder.Recorder) every sample, estimate, decision and reference change is
    written under namespace ``ns``.  ``clock`` [s] is the MPC's clock for its deadline
    (default wall time; a constant clock makes the run independent of the machine's speed).
    """
    params = params or WheelParams()
    plant = Plant(params, plant_config or PlantConfig(switching="tick"), xi2=w0)
    model = controller_params or params
    obs = Observer(model, controller_extensions, config=observer_config)
    mpc = Mpc(model, controller_extensions, config=mpc_config,
              **({"clock": clock} if clock is not None else {}))
    est = IntegralEstimator(gain=estimator_gain, mode=estimator_mode) if estimator_gain else None
    log = LoopLog()
    pending: Command | None = Command(1, D(3), D(22), 0)       # start the wheel
    obs.command_sent(0, D(3), D(22))
    latched = (D(3), D(22))
    angles = {0: latched}
    prev_q = 0
    idle = 0
    cycle_speeds: list[float] = []
    queued: list[float | None] = []      # predictions of the cycles that start at switch-offs
    window_pred: float | None = None
    prev_angle = prev_t = None
    fd = 0.0
    last_ref = reference_at(profile, 0.0)
    for _ in range(int(duration / TICK)):
        s = plant.step(pending)
        pending = None
        if s is None:
            continue
        e = obs.step(s)
        if recorder is not None:
            recorder.telemetry(ns, s)
            recorder.true_state(ns, plant.t, plant.wheel.state)
            recorder.estimate(ns, e, est.d if est else 0.0)
        if prev_angle is not None and s.t > prev_t:
            fd = (s.angle - prev_angle) / (s.t - prev_t)
        prev_angle, prev_t = s.angle, s.t
        speed = e.xi2 if speed_source == "observer" else fd
        ref = reference_at(profile, s.t)
        d = est.d if est else 0.0
        cycle_speeds.append(speed)
        log.t.append(s.t)
        log.true_speed.append(plant.wheel.s[2])
        log.est_speed.append(speed)
        log.reference.append(ref)
        log.d.append(d)
        idle = 0 if s.q else idle + 1
        switched_on = s.q == 1 and prev_q == 0
        switched_off = s.q == 0 and prev_q == 1
        prev_q = s.q
        if switched_off:
            # the window [previous switch-off, this one) is a cycle some decision predicted
            if est and window_pred is not None and len(cycle_speeds) > 1:
                est.step(float(np.mean(cycle_speeds[:-1])), window_pred, ref)
                d = est.d
            window_pred = queued.pop(0) if queued else None
            cycle_speeds = [speed]
        # a new reference while the current actuator is on: decide again at once (the waiting
        # command is replaced before it latches at the switch-off), so a step is met a cycle early
        # (only with time to spare before the switch-off: 20 ms; otherwise the next one decides)
        redecide = (ref != last_ref and s.q == 1 and not switched_on
                    and e.deact_counter > 0.02 * max(speed, 0.1))
        if recorder is not None and (ref != last_ref or len(log.t) == 1):
            recorder.reference(ns, s.t, ref)
        last_ref = ref
        if switched_on or idle == 150 or redecide:
            pa_now, pd_now = angles.get(s.last_command_sequence, latched)
            dec = mpc.decide(e.xi1, speed, s.eta_unwrapped, pa_now, pd_now, ref, d,
                             e.accel_coefficients if speed_source == "observer" else (0.0, 0.0, 0.0))
            if not switched_on:      # idle wheel: the next pad from the measured sector
                n_a = (int(math.floor(e.xi1 / (math.pi / 8))) + 1) % 16
                dec = dec._replace(command=dec.command._replace(n_a=n_a))
            pending = dec.command
            angles[dec.command.sequence] = (dec.command.phi_a, dec.command.phi_d)
            obs.command_sent(dec.command.sequence, dec.command.phi_a, dec.command.phi_d)
            prediction = None if dec.braking else dec.predicted_speed - d   # model-only mean
            if redecide and queued:
                queued[-1] = prediction
            else:
                queued.append(prediction)
            log.decisions.append((s.t, dec))
            if recorder is not None:
                recorder.decision(ns, s.t, dec, ref)
            idle = 0
    return log


class SegmentMetrics(NamedTuple):
    reference: float       # [rad/s]
    steady_error: float    # |mean(speed) - ref| / ref over the steady window [%]
    nrmse: float           # RMSE(speed - ref) / ref over the steady window [1]
    transition: float      # from the step until the speed first reaches ref [s] (rise/fall)
    settle: float          # from the step until the speed first comes within 2 % of ref [s]


def segment_metrics(log: LoopLog, profile=FIG11_PROFILE, duration: float = FIG11_DURATION,
                    window: float = 10.0) -> list[SegmentMetrics]:
    """Per reference segment, on the true speed (see :class:`SegmentMetrics`).

    Steady window: the last ``window`` seconds of the segment.  The transition time is the
    rise time of a step up and the fall time of a step down, measured as the braking
    calibration does (from the step until the new reference is first reached); NaN for the
    first segment (no step).
    """
    a = log.arrays()
    t, v = a["t"], a["true_speed"]
    out = []
    bounds = [p[0] for p in profile] + [duration]
    prev = None
    for (t0, ref), t1 in zip(profile, bounds[1:]):
        seg = (t >= t0) & (t < t1)
        steady = seg & (t >= t1 - window)
        # relative to the reference: undefined for a stop (ref = 0)
        ss = abs(np.mean(v[steady]) - ref) / ref * 100.0 if ref else math.nan
        nrmse = float(np.sqrt(np.mean((v[steady] - ref) ** 2))) / ref if ref else math.nan
        inside = np.flatnonzero(seg & (np.abs(v - ref) <= 0.02 * ref))
        settle = float(t[inside[0]] - t0) if inside.size else math.nan
        trans = math.nan
        if prev is not None and prev != ref:
            hit = np.flatnonzero(seg & ((v >= ref) if ref > prev else (v <= ref)))
            trans = float(t[hit[0]] - t0) if hit.size else math.nan
        out.append(SegmentMetrics(ref, float(ss), nrmse, trans, settle))
        prev = ref
    return out
