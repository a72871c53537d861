"""The simulation error of a fitted model, trial by trial: the paper's Table III metrics.

Each trial is simulated from its first state to its end with **model switching**
(:func:`~.simulate.free_run`): the recorded activations (pad, phi_a, phi_d) switch on and
off where the *simulated* contact angle, as the model's sensor reads it, reaches their
angles.  Nothing measured enters after
the first sample, so every error the model makes accumulates, as in the paper's Fig. 9.

The speed is compared (the paper compares speed).  The measured speed is the trial's
``speed`` column when it has one (motion capture), else the Savitzky-Golay derivative of the
measured angle (``SPEED_WINDOW``, quadratic) with isolated glitches bridged
(:func:`measured_speed`).  The simulated angle goes through the same
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

**An ensemble, not one run.**  With switching on the firmware's ticks a free run is not a
smooth function of its start or its parameters: a contact angle that reaches its threshold
just before or just after a tick moves that switch by 3.3 ms, and from then on the two runs
drift apart: a change of 1e-6 in the force law can move a trial's RMSE by half.  A reading
from an encoder says only that the angle lies within one count, so each metric is the
expectation over ``ENSEMBLE`` free runs whose start angles span one count's width evenly,
centred on the fitted start (any spread above ~1e-6 rad decorrelates the switching over a
trial, so the width matters little): the mean squared error (rmse = its root, r2 and nrmse
from it) and the mean steady-state error.  One run's error is one draw of a noisy
quantity; the ensemble's mean is what a model change can be judged by.  Angles without a
count (motion capture) give a single run.  Tested in ``test_ident_threads.py``
(``test_a_sub_count_shift_of_the_start_barely_moves_the_ensemble``).

The error has a floor: even the true model, run this way, drifts from the recording once a
switch falls on the other side of a tick.  :func:`model_error` measures it for given values.
A fitted model can land a little below it on held-out data by chance,
never far.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from scipy import signal

from hasel_wheel_sim import layout as L
from hasel_wheel_sim.model import angle_readings
from hasel_wheel_sim.params import WheelParams

from hasel_wheel_ident.candidates import Candidate
from hasel_wheel_ident.data import Trial, bridged_angle
from hasel_wheel_ident.fit import FitResult, Problem
from hasel_wheel_ident.session import prior_charge
from hasel_wheel_ident.simulate import free_run
from hasel_wheel_ident.threads import run_split

SPEED_WINDOW = 0.1      # [s] Savitzky-Golay window of the speed from the angle
STEADY = 10.0           # [s] at the end of the drive, for the steady-state error
EXTRA_ACTIVATIONS = 64  # continuation of the schedule for a simulation that runs ahead
ENSEMBLE = 64           # free runs per trial, start angles spread over one encoder count


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
    """(..., n) speed [rad/s] of angles (..., n) [rad] sampled at t (n,) [s] (Savitzky-Golay
    along the last axis)."""
    dt = float(np.median(np.diff(t)))
    n = max(5, int(round(SPEED_WINDOW / dt)) | 1)
    if angle.shape[-1] <= n:
        return np.gradient(angle, t, axis=-1)
    return signal.savgol_filter(angle, n, 2, deriv=1, delta=dt, mode="interp", axis=-1)


def measured_speed(trial: Trial) -> np.ndarray:
    """The trial's measured speed (n,) [rad/s]: its ``speed`` column when it has one, else
    :func:`speed_from_angle` of its angle with isolated glitches (:func:`~.data.clean_mask`,
    the samples the fit leaves out) bridged by linear interpolation.  One glitched count
    would otherwise put a spike of ~angle jump / filter window into the compared speed."""
    if trial.speed is not None:
        return trial.speed
    return speed_from_angle(trial.t, bridged_angle(trial.t, trial.angle))


def simulate_trial(problem: Problem, theta: np.ndarray, trial: Trial,
                   x0: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """Free run of ``trial`` from x0 = (xi1 [rad], xi2 [rad/s]) with the model of ``problem``
    at its free parameters ``theta`` (g,).  Returns (xi1 (n,) [rad] as its sensor reads it,
    q (n,) 0/1)."""
    x1, q = simulate_ensemble(problem, theta, trial, np.asarray([x0], dtype=float))
    return x1[0], q[0]


def simulate_ensemble(problem: Problem, theta: np.ndarray, trial: Trial,
                      starts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Free runs of ``trial`` (n samples) with the model of ``problem`` at its free parameters
    ``theta`` (g,), from each row of ``starts`` (k, 2) = (xi1 [rad], xi2 [rad/s]); the runs
    are shared over at least two threads of :func:`~.threads.window_pool`.
    Returns (xi1 (k, n) [rad] as the model's sensor reads it, q (k, n) 0/1)."""
    pv, extra = problem.model(problem.full_theta(theta))
    if trial.friction_scale != 1.0:                  # friction along the session's trend
        pv = pv.copy()
        pv[L.P_FRICTION] *= trial.friction_scale
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
    k, n = starts.shape[0], trial.t.shape[0]
    x1, x2, q = np.zeros((k, n)), np.zeros((k, n)), np.zeros((k, n))
    args = (np.array(eta), np.array(pa), np.array(pd), 0, on0)
    offset = float(extra.get("eta_offset", 0.0))
    charge0 = prior_charge(trial, float(pv[L.P_RET_RECOVERY]))

    def run(rows: np.ndarray) -> None:
        for i in rows:
            free_run(trial.t, *args, starts[i].copy(), offset, t_last_on, pv, charge0, x1[i],
                     x2[i], q[i])

    run_split(run, np.array_split(np.arange(k), min(k, max(problem.threads, 2))))
    return angle_readings(x1, pv), q


def steady_tail(trial: Trial) -> np.ndarray:
    """(n,) bool: the samples of the steady-state error, the last ``STEADY`` s of the drive
    (the last half of it when shorter)."""
    driven = np.flatnonzero(trial.n_a >= 0)
    end = int(driven[-1]) + 1 if driven.size else trial.t.shape[0]
    t_end = trial.t[end - 1]
    length = min(STEADY, 0.5 * (t_end - trial.t[0]))
    return (trial.t > t_end - length) & (np.arange(trial.t.shape[0]) < end)


def drift_text(trials: list[Trial], metrics: dict[str, TrialMetrics]) -> str:
    """The free run's steady-state error trial by trial, slowest trial first, in words:
    "+0.072 rad/s at 1.14 rad/s (phi_a_1deg), ..." (the measured steady speed over
    :func:`steady_tail`)."""
    rows = []
    for tr in trials:
        m = metrics.get(tr.name)
        tail = steady_tail(tr)
        if m is None or not tail.any() or not math.isfinite(m.steady_state_error):
            continue
        rows.append((float(np.mean(measured_speed(tr)[tail])), m.steady_state_error, tr.name))
    return ", ".join(f"{e:+.3f} rad/s at {v:.2f} rad/s ({name})" for v, e, name in sorted(rows))


def trial_metrics(problem: Problem, theta: np.ndarray, trial: Trial,
                  x0: tuple[float, float], ensemble: int = ENSEMBLE) -> TrialMetrics:
    """The simulation error of ``trial`` (see :func:`simulate_trial` for the arguments),
    averaged over ``ensemble`` start angles spread evenly over one encoder count around
    the fitted start x0[0] (see the module docstring).  Angles without a count (motion
    capture, exact data) give one run from x0."""
    if ensemble < 1:
        raise ValueError(f"ensemble must be a whole number of runs >= 1, got {ensemble}")
    v_meas = measured_speed(trial)
    count = problem.quantum
    if not count:
        ensemble, count = 1, 0.0
    shifts = count * ((np.arange(ensemble) + 0.5) / ensemble - 0.5)
    starts = np.column_stack([x0[0] + shifts, np.full(ensemble, x0[1])])
    x1, _ = simulate_ensemble(problem, theta, trial, starts)
    e = speed_from_angle(trial.t, x1) - v_meas                     # (ensemble, n)
    tail = steady_tail(trial)
    n = v_meas.shape[0]
    sse = float(np.sum(e * e)) / ensemble                          # mean over the ensemble
    ess = float(np.mean(e[:, tail])) if tail.any() else math.nan
    rmse = math.sqrt(sse / n)
    ss_tot = float(np.sum((v_meas - v_meas.mean()) ** 2))
    span = float(np.ptp(v_meas))
    return TrialMetrics(trial.name, rmse, 1.0 - sse / ss_tot if ss_tot > 0 else math.nan,
                        rmse / span if span > 0 else math.nan, ess, n)


def fitted_metrics(problem: Problem, fit: FitResult, trials: list[Trial]
                   ) -> dict[str, TrialMetrics]:
    """The simulation error of each of ``trials`` (the trials ``problem`` was built on, in
    its order) with the parameters of ``fit`` (a fit of ``problem`` on all of them), each
    trial run from its first window's fitted start; keyed by trial name."""
    x = fit.x0
    return {tr.name: trial_metrics(problem, fit.theta, tr, x[problem.trial_windows[i][0]])
            for i, tr in enumerate(trials)}


def pooled_rmse(metrics: dict[str, TrialMetrics]) -> float:
    """RMSE [rad/s] over all samples of all trials in ``metrics``."""
    n = sum(m.samples for m in metrics.values())
    return math.sqrt(sum(m.rmse ** 2 * m.samples for m in metrics.values()) / n) if n else math.nan


def model_error(trials: list[Trial], base: WheelParams, effects: tuple[Candidate, ...],
                values: dict[str, float]) -> float:
    """Pooled simulation error [rad/s] (:func:`trial_metrics`, over all samples) of one
    given model on ``trials``, each trial run from its own fitted start.  The model is the
    force law about ``base`` (WheelParams) plus the candidate ``effects``; ``values`` names
    every parameter (the coordinates of :func:`~.fit.force_coordinates`, ``tau_f`` and the
    effects' own).  With a plant's true values it is the reference an identified model is
    judged against: on held-out data a fitted model scores near it, rarely far below."""
    per = {}
    for tr in trials:
        pt = Problem([tr], base, effects)
        theta = np.array([values[n] for n in pt.names])
        x0, _, _, _ = pt.solve_starts(pt.full_theta(theta), pt.initial_starts())
        per[tr.name] = trial_metrics(pt, theta, tr, (float(x0[0, 0]), float(x0[0, 1])))
    return pooled_rmse(per)
