"""State observer: the six hybrid states from telemetry, with speed seen through a 10-bit encoder.

A 10-bit encoder sampled at 300 Hz resolves speed only in steps of 2 pi/1024 x 300 = 1.84 rad/s
by finite difference (model-notes.md).  This observer is an extended Kalman filter on
(xi1, xi2) whose prediction integrates the hybrid model itself (the same compiled RK4 flow as
the plant), driven by the known actuation: q and eta from telemetry, phi_a of the latched
command.  The measurement is the floor-quantised encoder angle, corrected to the middle of its
count, with variance count^2/12 (+ noise^2).

* Encoder glitches: an innovation beyond ``gate_sigma`` standard deviations is rejected and
  counted; the prediction carries on.
* Missing samples: the prediction spans the device-time gap.
* Quality: 1 when the recent innovations are consistent, falling with the share of rejected
  samples and with a stale link; 0 means unusable.

``Observer.step(sample) -> Estimate`` is the whole contract.  The disturbance estimate stays 0
here; the estimator that fills it is a separate core (issue: closing the speed loop).
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from hasel_wheel_driver.samples import ENCODER_COUNT as COUNT
from hasel_wheel_driver.samples import TelemetrySample
from hasel_wheel_sim import layout as L
from hasel_wheel_sim.integrator import rk4
from hasel_wheel_sim.model import SECTOR, Extensions, param_vector
from hasel_wheel_sim.params import WheelParams
from hasel_wheel_sim.wheel import initial_state



@dataclass(frozen=True)
class ObserverConfig:
    """Tuning (SI): unmodelled acceleration, extra encoder noise, gating, defaults."""

    accel_noise: float = 0.05       # std of white unmodelled acceleration [rad/s^2] (swept: 0.02-0.1 best)
    encoder_noise: float = 0.0      # encoder noise std beyond quantisation [rad]
    gate_sigma: float = 6.0         # innovations beyond this many sigma are outliers [1]
    default_phi_a: float = math.radians(3.0)   # phi_a when the latched command is unknown [rad]
    default_phi_d: float = math.radians(22.0)  # phi_d likewise [rad]
    initial_speed_std: float = 2.0  # std of the first speed guess [rad/s]
    window: int = 300               # samples over which the quality is judged [1]


class Estimate(NamedTuple):
    """The six hybrid states with uncertainty (angles rad, speed rad/s, time s)."""

    t: float
    xi1: float
    xi2: float
    q: int
    act_counter: float
    deact_counter: float
    eta_unwrapped: int
    disturbance: float
    xi2_std: float
    quality: float


class Observer:
    """EKF on (xi1, xi2) with the hybrid model as its process model."""

    def __init__(self, params: WheelParams | None = None, extensions: Extensions | None = None,
                 config: ObserverConfig | None = None) -> None:
        self.params = params or WheelParams()
        self.config = config or ObserverConfig()
        self.pv = param_vector(self.params, extensions)
        self._s = initial_state()          # scratch state for the flow: q, eta, phi_a, on-time
        self._commands: dict[int, tuple[float, float]] = {}
        self.x: np.ndarray | None = None    # (xi1, xi2)
        self.P = np.zeros((2, 2))
        self.t = 0.0
        self.on_since = 0.0
        self.rejected = 0
        self.updates = 0
        self._recent: deque[bool] = deque(maxlen=self.config.window)
        self._prev: TelemetrySample | None = None

    def command_sent(self, sequence: int, phi_a: float, phi_d: float) -> None:
        """Tell the observer which (phi_a, phi_d) a command sequence number stands for."""
        self._commands[sequence] = (phi_a, phi_d)

    def _angles(self, seq: int) -> tuple[float, float]:
        return self._commands.get(seq, (self.config.default_phi_a, self.config.default_phi_d))

    def _flow(self, x: np.ndarray, dt: float, s: np.ndarray) -> tuple[float, float]:
        return rk4(float(x[0]), float(x[1]), dt, s, 1.0, self.pv)

    def step(self, z: TelemetrySample) -> Estimate:
        """Fold in one telemetry sample; return the estimate at its time."""
        c = self.config
        r = (COUNT * COUNT) / 12.0 + c.encoder_noise ** 2
        meas = z.angle + 0.5 * COUNT           # middle of the count the encoder floored into
        if self.x is None:
            self.x = np.array([meas, 0.0])
            self.P = np.diag([r, c.initial_speed_std ** 2])
            self.t = z.t
            self._prev = z
            return self._estimate(z)
        dt = z.t - self.t
        if dt > 0.0:
            self._predict(dt, self._prev)
        # update with gating
        h_p = self.P[0]
        s_inn = self.P[0, 0] + r
        nu = meas - self.x[0]
        outlier = nu * nu > (c.gate_sigma ** 2) * s_inn
        self._recent.append(outlier)
        if outlier:
            self.rejected += 1
        else:
            k = h_p / s_inn
            self.x = self.x + k * nu
            self.P = self.P - np.outer(k, h_p)
            self.updates += 1
        self.t = z.t
        if z.q and not (self._prev and self._prev.q):
            self.on_since = z.t
        self._prev = z
        return self._estimate(z)

    def _predict(self, dt: float, prev: TelemetrySample) -> None:
        s = self._s
        phi_a, _ = self._angles(prev.last_command_sequence)
        s[L.S_Q] = prev.q
        s[L.S_ETA] = prev.eta_unwrapped
        s[L.S_PHI_A] = phi_a
        s[L.S_ON_TIME] = max(prev.t - self.on_since, 0.0) if prev.q else 0.0
        x = self.x
        x1, v1 = self._flow(x, dt, s)
        # Jacobian of the flow by central differences (the flow is smooth within a mode)
        e1, e2 = 1e-6, 1e-6
        a = self._flow(x + (e1, 0.0), dt, s)
        b = self._flow(x - (e1, 0.0), dt, s)
        cc = self._flow(x + (0.0, e2), dt, s)
        d = self._flow(x - (0.0, e2), dt, s)
        F = np.array([[(a[0] - b[0]) / (2 * e1), (cc[0] - d[0]) / (2 * e2)],
                      [(a[1] - b[1]) / (2 * e1), (cc[1] - d[1]) / (2 * e2)]])
        qa = self.config.accel_noise ** 2
        Q = qa * np.array([[dt ** 3 / 3.0, dt ** 2 / 2.0], [dt ** 2 / 2.0, dt]])
        self.x = np.array([x1, v1])
        self.P = F @ self.P @ F.T + Q

    def _estimate(self, z: TelemetrySample) -> Estimate:
        phi_a, phi_d = self._angles(z.last_command_sequence)
        base = z.eta_unwrapped * SECTOR
        xi1 = float(self.x[0])
        act = 0.0 if z.q else base + phi_a - xi1
        deact = base + phi_d - xi1
        bad = sum(self._recent) / max(len(self._recent), 1)
        quality = max(0.0, 1.0 - 5.0 * bad)
        return Estimate(z.t, xi1, float(self.x[1]), z.q, act, deact, z.eta_unwrapped, 0.0,
                        float(math.sqrt(max(self.P[1, 1], 0.0))), quality)


def finite_difference_speed(t: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Backward-difference speed [rad/s] of sampled angles (the baseline the observer beats)."""
    v = np.zeros_like(angle)
    v[1:] = np.diff(angle) / np.diff(t)
    return v
