"""The closed speed loop in the embedded runner: plant -> observer -> estimator -> MPC -> plant.

Everything runs in lockstep simulated time at 300 Hz.  The controller decides at each
switch-on reported in telemetry (paper Sec. V-B); the command reaches the plant through its
serial-latency effect and is latched at the current actuator's switch-off.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from hasel_wheel_driver.samples import Command
from hasel_wheel_sim.params import WheelParams
from hasel_wheel_sim.plant import Plant, PlantConfig
from hasel_wheel_sim.wheel import TICK

from .disturbance import IntegralEstimator
from .mpc import Mpc, MpcConfig
from .observer import Observer, finite_difference_speed

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
                    estimator_gain: float | None = 0.3, speed_source: str = "observer",
                    mpc_config: MpcConfig | None = None, w0: float = 1.0) -> LoopLog:
    """Run the loop; ``estimator_gain`` None disables the disturbance estimator;
    ``speed_source`` 'observer' or 'finite_difference' (what the MPC sees as xi2)."""
    params = params or WheelParams()
    plant = Plant(params, plant_config or PlantConfig(switching="tick"), xi2=w0)
    obs = Observer(params)
    mpc = Mpc(params, config=mpc_config)
    est = IntegralEstimator(gain=estimator_gain) if estimator_gain else None
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
    for _ in range(int(duration / TICK)):
        s = plant.step(pending)
        pending = None
        if s is None:
            continue
        e = obs.step(s)
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
        if switched_on or idle == 150:
            pa_now, pd_now = angles.get(s.last_command_sequence, latched)
            dec = mpc.decide(e.xi1, speed, s.eta_unwrapped, pa_now, pd_now, ref, d)
            if not switched_on:      # idle wheel: the next pad from the measured sector
                n_a = (int(math.floor(e.xi1 / (math.pi / 8))) + 1) % 16
                dec = dec._replace(command=dec.command._replace(n_a=n_a))
            pending = dec.command
            angles[dec.command.sequence] = (dec.command.phi_a, dec.command.phi_d)
            obs.command_sent(dec.command.sequence, dec.command.phi_a, dec.command.phi_d)
            if not dec.braking:
                queued.append(dec.predicted_speed - d)   # model-only mean over its cycle
            else:
                queued.append(None)
            log.decisions.append((s.t, dec))
            idle = 0
    return log


def segment_metrics(log: LoopLog, profile=FIG11_PROFILE, duration: float = FIG11_DURATION,
                    window: float = 10.0):
    """Per reference segment: steady-state error [%], NRMSE [1], rise/fall time [s].

    Steady window: the last ``window`` seconds of the segment, on the true speed.
    NRMSE = RMSE(true - ref) / ref over that window.  Rise (fall) time: from the segment's
    start until the speed first comes within 2 % of the new reference.
    """
    a = log.arrays()
    t, v = a["t"], a["true_speed"]
    out = []
    bounds = [p[0] for p in profile] + [duration]
    for (t0, ref), t1 in zip(profile, bounds[1:]):
        seg = (t >= t0) & (t < t1)
        steady = seg & (t >= t1 - window)
        ss = abs(np.mean(v[steady]) - ref) / ref * 100.0
        nrmse = float(np.sqrt(np.mean((v[steady] - ref) ** 2))) / ref
        inside = np.flatnonzero(seg & (np.abs(v - ref) <= 0.02 * ref))
        settle = float(t[inside[0]] - t0) if inside.size else math.nan
        out.append((ref, ss, nrmse, settle))
    return out
