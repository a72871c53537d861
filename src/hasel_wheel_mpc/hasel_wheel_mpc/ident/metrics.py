"""The simulation error of a fitted model, trial by trial: the paper's Table III metrics.

Each trial is simulated from its first state to its end with **model switching**
(:func:`~.simulate.free_run`): the recorded activations (pad, phi_a, phi_d) switch on and
off where the *simulated* contact angle reaches their angles.  Nothing measured enters after
the first sample, so every error the model makes accumulates, as in the paper's Fig. 9.

The speed is compared (the paper compares speed).  The measured speed is the trial's
``speed`` column when it has one (motion capture), else the Savitzky-Golay derivative of the
measured angle (``SPEED_WINDOW``, quadratic).  The simulated angle goes through the same
filter, so both carry the same smoothing of the 16-per-turn ripple.

Per trial:

==================  ======================================================================
rmse                sqrt(mean((v_sim - v_meas)^2))                               [rad/s]
r2                  1 - sum((v_sim - v_meas)^2) / sum((v_meas - mean v_meas)^2)  [1]
nrmse               rmse / (max v_meas - min v_meas)                               [1]
steady_state_error  mean(v_sim) - mean(v_meas) over the last ``STEADY`` s of the drive
                    (the last half of it when shorter)                          [rad/s]
==================  ======================================================================

The paper's Table III gives linear speed [m/s]; multiply by the wheel radius r to compare.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from scipy import signal

from .data import Trial
from .fit import Problem
from .simulate import free_run

SPEED_WINDOW = 0.1      # [s] Savitzky-Golay window of the speed from the angle
STEADY = 10.0           # [s] at the end of the drive, for the steady-state error
EXTRA_ACTIVATIONS = 64  # continuation of the schedule for a simulation that runs ahead


@dataclass
class TrialMetrics:
    """The simulation error of one trial (see the module docstring for the definitions)."""

    trial: str
    rmse: float                    # [rad/s]
    r2: float                      # [1]
    nrmse: float                   # [1]
    steady_state_error: float      # [rad/s]
    samples: int

    def as_dict(self) -> dict:
        return asdict(self)


def speed_from_angle(t: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """(n,) speed [rad/s] of an angle (n,) [rad] sampled at t (n,) [s] (Savitzky-Golay)."""
    dt = float(np.median(np.diff(t)))
    n = max(5, int(round(SPEED_WINDOW / dt)) | 1)
    if angle.shape[0] <= n:
        return np.gradient(angle, t)
    return signal.savgol_filter(angle, n, 2, deriv=1, delta=dt, mode="interp")


def simulate_trial(problem: Problem, theta: np.ndarray, trial: Trial,
                   x0: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """Free run of ``trial`` from x0 = (xi1 [rad], xi2 [rad/s]) with the model of ``problem``
    at its free parameters ``theta`` (g,).  Returns (xi1 (n,) [rad], q (n,) 0/1)."""
    pv, extra = problem.model(problem.full_theta(theta))
    acts = trial.activations
    eta = [float(a.eta) for a in acts]
    pa = [a.phi_a for a in acts]
    pd = [a.phi_d for a in acts]
    if acts:
        # a simulation that runs faster than the wheel reaches the end of the recorded
        # activations early: it goes on the way the schedule did (next pads, last angles)
        # until the recording's last switch-on time, instead of coasting early
        last = acts[-1]
        eta += [last.eta + k for k in range(1, EXTRA_ACTIVATIONS + 1)]
        pa += [last.phi_a] * EXTRA_ACTIVATIONS
        pd += [last.phi_d] * EXTRA_ACTIVATIONS
    t_last_on = float(trial.t[acts[-1].start]) if acts else -math.inf
    on0 = 1 if acts and acts[0].start == 0 else 0
    n = trial.t.shape[0]
    x1, x2, q = np.zeros(n), np.zeros(n), np.zeros(n)
    free_run(trial.t, np.array(eta), np.array(pa), np.array(pd), 0, on0,
             np.asarray(x0, dtype=float), float(extra.get("eta_offset", 0.0)), t_last_on, pv,
             x1, x2, q)
    return x1, q


def trial_metrics(problem: Problem, theta: np.ndarray, trial: Trial,
                  x0: tuple[float, float]) -> TrialMetrics:
    """The simulation error of ``trial`` (see :func:`simulate_trial` for the arguments)."""
    x1, _ = simulate_trial(problem, theta, trial, x0)
    v_sim = speed_from_angle(trial.t, x1)
    v_meas = trial.speed if trial.speed is not None else speed_from_angle(trial.t, trial.angle)
    e = v_sim - v_meas
    rmse = float(np.sqrt(np.mean(e ** 2)))
    ss_tot = float(np.sum((v_meas - v_meas.mean()) ** 2))
    span = float(np.ptp(v_meas))
    driven = np.flatnonzero(trial.n_a >= 0)
    end = int(driven[-1]) + 1 if driven.size else trial.t.shape[0]
    t_end = trial.t[end - 1]
    length = min(STEADY, 0.5 * (t_end - trial.t[0]))
    tail = (trial.t > t_end - length) & (np.arange(trial.t.shape[0]) < end)
    ess = float(np.mean(v_sim[tail]) - np.mean(v_meas[tail])) if tail.any() else math.nan
    return TrialMetrics(trial.name, rmse, 1.0 - float(e @ e) / ss_tot if ss_tot > 0 else math.nan,
                        rmse / span if span > 0 else math.nan, ess, int(e.size))


def pooled_rmse(metrics: dict[str, TrialMetrics]) -> float:
    """RMSE [rad/s] over all samples of all trials in ``metrics``."""
    n = sum(m.samples for m in metrics.values())
    return math.sqrt(sum(m.rmse ** 2 * m.samples for m in metrics.values()) / n) if n else math.nan
