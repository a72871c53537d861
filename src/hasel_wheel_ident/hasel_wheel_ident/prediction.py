"""The one-step prediction residual: the observer's innovations with the fitted model.

The observer (:class:`~hasel_wheel_mpc.observer.Observer`, an extended Kalman filter on
(xi1, xi2)) runs over each trial with the model under test and *no* disturbance state, so
every prediction comes from the model alone.  At each sample it predicts the angle from its
estimate at the previous sample; the innovation nu_k = y_k - y_hat(k | k-1) [rad] is the
one-step prediction error (Ljung's ``resid`` on a predictor).  For a right model it is white;
normalised by its predicted standard deviation it has unit variance.  Structure the model
lacks makes it correlated over many samples.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hasel_wheel_common.samples import TelemetrySample
from hasel_wheel_sim.model import Extensions
from hasel_wheel_sim.params import WheelParams

from hasel_wheel_mpc.observer import Observer, ObserverConfig
from hasel_wheel_ident.data import Trial
from hasel_wheel_ident.residual import correlation


PREDICTION_SPAN = 20.0     # [s] of each trial the one-step prediction residual covers


@dataclass
class PredictionResidual:
    """Innovations of one trial and their summary."""

    trial: str
    nu: np.ndarray              # (n,) one-step prediction error [rad] (nan before the first)
    normalised: np.ndarray      # (n,) nu / predicted std [1]
    rms: float                  # [rad]
    normalised_rms: float       # [1]: ~1 when the model and the noise model are right
    acf: np.ndarray             # (max_lag + 1,) autocorrelation of nu
    whiteness_outside: float    # share of lags 1..max_lag outside the 99 % band


def _samples(trial: Trial):
    """The trial as telemetry, each activation its own command sequence number."""
    seq = np.full(trial.t.shape[0], -1, dtype=np.int64)
    for i, a in enumerate(trial.activations):
        seq[a.start:] = i
    for k in range(trial.t.shape[0]):
        q = int(trial.q[k])
        yield TelemetrySample(float(trial.t[k]), int(round(trial.t[k] * 1e6)), k, 0,
                              float(trial.angle[k]), q, int(trial.eta[k]),
                              int(trial.eta_unwrapped[k]), (1 << int(trial.eta[k])) if q else 0,
                              0.0, 0.0, int(seq[k]))


def prediction_residual(trial: Trial, params: WheelParams, ext: Extensions | None = None,
                        max_lag: int = 60, accel_noise: float = 0.005,
                        duration: float | None = PREDICTION_SPAN) -> PredictionResidual:
    """One-step prediction residual of ``trial`` under the model (params, ext), over its first
    ``duration`` [s] (None: all of it; the observer runs in Python, ~150 us a sample).

    The observer takes the angles as 10-bit encoder readings.  Its process noise is small
    (``accel_noise`` [rad/s^2], a tenth of the tuning for control) so that it trusts the
    model: a missing torque of 0.1 rad/s^2 then shows as innovations correlated over many
    samples instead of being tracked away."""
    if duration is not None and trial.duration > duration:
        trial = trial.slice(0, int(np.searchsorted(trial.t, trial.t[0] + duration)), trial.name)
    obs = Observer(params, ext, ObserverConfig(disturbance_rate=0.0, pivot_rate=0.0,
                                              accel_noise=accel_noise))
    for i, a in enumerate(trial.activations):
        obs.command_sent(i, a.phi_a, a.phi_d)
    n = trial.t.shape[0]
    nu = np.full(n, np.nan)
    var = np.full(n, np.nan)
    for k, z in enumerate(_samples(trial)):
        obs.step(z)
        if obs.innovation is not None and k > 0:
            nu[k], var[k] = obs.innovation
    ok = np.isfinite(nu)
    c = correlation(nu[ok], nu[ok], max_lag)[max_lag:]
    band = 2.576 / math.sqrt(max(int(ok.sum()), 1))
    norm = np.where(ok, nu / np.sqrt(var), np.nan)
    return PredictionResidual(trial.name, nu, norm, float(np.sqrt(np.mean(nu[ok] ** 2))),
                              float(np.sqrt(np.nanmean(norm ** 2))), c,
                              float(np.mean(np.abs(c[1:]) > band)))
