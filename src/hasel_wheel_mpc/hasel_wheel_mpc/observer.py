"""State observer: the six hybrid states from telemetry, with speed seen through a 10-bit encoder.

A 10-bit encoder sampled at 300 Hz resolves speed only in steps of 2 pi/1024 x 300 = 1.84 rad/s
by finite difference (``docs/model.md``).  This observer is an extended Kalman filter on
(xi1, xi2) and the coefficients of a_d, whose prediction integrates the hybrid model itself
(the same compiled RK4 flow as the plant), driven by the known actuation: q and eta from
telemetry, phi_a of the latched command.  The measurement is the floor-quantised encoder
angle, corrected to the middle of its count, with variance count^2/12 (+ noise^2) [rad^2].
Its speed error stays within 0.02 rad/s RMSE, a twentieth of the finite difference's
(``test_observer.py::test_observer_beats_the_finite_difference_on_a_10_bit_encoder``).

* Encoder glitches: an innovation beyond ``gate_sigma`` standard deviations is rejected and
  counted; the prediction carries on (``test_glitches_are_rejected_and_counted``).
* Missing samples: the prediction spans the device-time gap
  (``test_lost_samples_are_bridged_by_the_model``).
* Lost wheel: after ``reacquire_after`` outliers in a row it restarts from their line fit
  (``test_an_observer_started_on_a_fast_wheel_locks_on``).
* Quality [1]: 1 - 5 x the share of rejected samples in the last ``window``, at least 0;
  0 means unusable.

``Observer.step(sample) -> Estimate`` is the whole contract.  The MPC's speed offset d is
not estimated here but in the control core (disturbance.py).  Details: ``docs/controller.md``.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from hasel_wheel_common.samples import ENCODER_COUNT as COUNT
from hasel_wheel_common.samples import PadEdges, TelemetrySample, accel_coefficients_of
from hasel_wheel_sim import layout as L
from hasel_wheel_sim.integrator import rk4
from hasel_wheel_sim.model import SECTOR, Extensions, reading_param_vector
from hasel_wheel_sim.params import WheelParams
from hasel_wheel_sim.wheel import initial_state



@dataclass(frozen=True)
class ObserverConfig:
    """Tuning (SI): unmodelled acceleration, extra encoder noise, gating, defaults.

    The disturbance coefficients walk slowly, so they hold the average of many pads rather
    than follow the last few, and the MPC's prediction, which takes them as given, does not
    scatter from cycle to cycle with the encoder's noise.  Their first values still come
    quickly (``initial_disturbance_std``).  They are not learnt while the wheel is surely
    slower than ``learn_speed`` (its speed estimate plus three standard deviations): a slower wheel (starting, stalling) is moved by the start push
    and held by static friction, which would teach them what a rolling wheel never feels
    (``test_observer.py::test_a_standing_wheel_teaches_the_disturbance_nothing``).
    """

    accel_noise: float = 0.05       # std of white unmodelled acceleration [rad/s^2]
    encoder_noise: float = 0.0      # encoder noise std beyond quantisation [rad]
    gate_sigma: float = 6.0         # innovations beyond this many sigma are outliers [1]
    default_phi_a: float = math.radians(3.0)   # phi_a when the latched command is unknown [rad]
    default_phi_d: float = math.radians(22.0)  # phi_d likewise [rad]
    initial_speed_std: float = 2.0  # std of the first speed guess [rad/s]
    initial_disturbance_std: float = 0.2  # std of the first guess of c, a, b [rad/s^2]
    window: int = 300               # samples over which the quality is judged [1]
    disturbance_rate: float = 0.005  # random-walk intensity of each disturbance coefficient
                                     # (c, a, b) [rad/s^2 per sqrt(s)]; 0 = no disturbance state
    pivot_rate: float = 0.005        # the same for the pivot harmonic (e, f) [rad/s^2 per
                                     # sqrt(s)]; 0 = none
    learn_speed: float = 0.5        # the disturbance is learnt only at this speed or faster
                                    # [rad/s]
    reacquire_after: int = 30       # this many outliers in a row mean the estimate lost the
                                    # wheel (started on a fast wheel, a long dropout): restart
                                    # from those samples' line fit [samples]; 0 = never


class Estimate(NamedTuple):
    """The six hybrid states with uncertainty (angles rad, speed rad/s, time s)."""

    t: float
    xi1: float
    xi2: float
    q: int
    act_counter: float
    deact_counter: float
    eta_unwrapped: int
    xi2_std: float
    quality: float
    accel_disturbance: float = 0.0      # a_d at xi1: unmodelled acceleration [rad/s^2]
    accel_disturbance_std: float = 0.0  # one-sigma uncertainty of its constant part [rad/s^2]
    accel_coefficients: tuple = (0.0,) * 5   # (c, a, b, e, f) of a_d [rad/s^2]


def estimate_from_msg(m: Any) -> Estimate:
    """An :class:`Estimate` from a HybridStateEstimate message (attribute access; float64
    fields, so exactly what the observer computed).  A message from before the five a_d
    coefficients carries ``accel_disturbance`` as the constant part (``test_estimate_msg.py::
    test_an_estimate_from_before_the_coefficients_reads_as_none_and_replays_alike``).
    """
    coeffs = accel_coefficients_of(m) or (float(m.accel_disturbance), 0.0, 0.0, 0.0, 0.0)
    stamp = m.header.stamp
    return Estimate(stamp.sec + stamp.nanosec * 1e-9, float(m.xi1), float(m.xi2), int(m.q),
                    float(m.activation_counter), float(m.deactivation_counter),
                    int(m.eta_unwrapped), float(m.xi2_stddev), float(m.quality),
                    float(m.accel_disturbance), 0.0, coeffs)


class Observer:
    """EKF on (xi1, xi2, c, a, b, e, f) with the hybrid model as its process model.

    a_d = c + a cos(xi1) + b sin(xi1) + e cos(psi) + f sin(psi) [rad/s^2], psi = (r/L) xi1
    the pivot arm's angle (eq. (8)), is the acceleration the model does not explain: a
    constant part (charge retention, drag), a once-per-turn part (an off-centre mass; the
    paper trims its wheel's COM with weights for this reason) and a once-per-lap part (whatever
    is fixed to the room the wheel circles in: a sloping floor, a tether, the cable to the
    arm).  The lap is 1/(r/L) = 4.1 turns, 26 s at 1 rad/s: slower than a cycle, too fast for
    the constant part to follow without lag.  The coefficients are slow random walks.  a_d is
    added to the model's acceleration in the prediction, and the MPC predicts with it too
    (``test_observer.py::test_observer_recovers_a_known_off_centre_mass``,
    ``test_observer_recovers_a_known_platform_disturbance``).
    """

    def __init__(self, params: WheelParams | None = None, extensions: Extensions | None = None,
                 config: ObserverConfig | None = None) -> None:
        self.params = params or WheelParams()
        self.config = config or ObserverConfig()
        self.pv = reading_param_vector(self.params, extensions)
        self._s = initial_state()          # scratch state for the flow: q, eta, phi_a, on-time
        self._commands: dict[int, tuple[float, float]] = {}
        self._now: set[int] = set()        # sequence numbers of START commands
        self.on_speed = math.inf           # speed estimate at the last switch-on [rad/s]
        self.on_contact = 0.0              # contact angle read at the last switch-on [rad]
        self.x: np.ndarray | None = None    # (xi1 [rad], xi2 [rad/s], c, a, b, e, f [rad/s^2])
        self.P = np.zeros((N_STATES, N_STATES))
        self._pv = self.pv.copy()           # the model with the current a_d as a torque
        self.t = 0.0
        self.on_since = 0.0
        self.rejected = 0
        self.updates = 0
        self.reacquisitions = 0
        self._run: list[tuple[float, float]] = []    # (t, angle) of the outliers in a row
        self._recent: deque[bool] = deque(maxlen=self.config.window)
        self._recent_bad = 0          # how many of self._recent are True (kept, not summed)
        self._prev: TelemetrySample | None = None
        self._edges = PadEdges()
        #: (nu [rad], its predicted variance [rad^2]) of the last update, None before the first
        self.innovation: tuple[float, float] | None = None

    def command_sent(self, sequence: int, phi_a: float, phi_d: float, now: bool = False) -> None:
        """Tell the observer which (phi_a, phi_d) [rad] a command sequence number stands for;
        for a START (``now``) the pad's force law starts at its contact angle at switch-on,
        which the observer takes from the reading there."""
        self._commands[sequence] = (phi_a, phi_d)
        if now:
            self._now.add(sequence)
        else:
            self._now.discard(sequence)

    def _angles(self, seq: int) -> tuple[float, float]:
        return self._commands.get(seq, (self.config.default_phi_a, self.config.default_phi_d))

    def _flow(self, x: np.ndarray, dt: float, s: np.ndarray) -> tuple[float, float]:
        set_disturbance(self._pv, self.pv, x[2:])
        return rk4(float(x[0]), float(x[1]), dt, s, 1.0, self._pv)

    def step(self, z: TelemetrySample) -> Estimate:
        """Fold in one telemetry sample; return the estimate at its time."""
        c = self.config
        switched_on, _ = self._edges.step(z.q, z.eta_unwrapped)
        r = (COUNT * COUNT) / 12.0 + c.encoder_noise ** 2
        meas = z.angle + 0.5 * COUNT           # middle of the count the encoder floored into
        if self.x is None:
            self.x = np.zeros(N_STATES)
            self.x[0] = meas
            self.P = np.diag([r, c.initial_speed_std ** 2, *self._disturbance_var()])
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
        self.innovation = (float(nu), float(s_inn))     # one-step prediction error [rad, rad^2]
        outlier = nu * nu > (c.gate_sigma ** 2) * s_inn
        if self._recent.maxlen:
            if len(self._recent) == self._recent.maxlen:
                self._recent_bad -= self._recent[0]
            self._recent.append(bool(outlier))
            self._recent_bad += bool(outlier)
        if outlier:
            self.rejected += 1
            self._run.append((z.t, meas))
            if c.reacquire_after and len(self._run) >= c.reacquire_after:
                self._reacquire()
        else:
            self._run = []
            k = h_p / s_inn
            if abs(self.x[1]) + 3.0 * math.sqrt(self.P[1, 1]) < c.learn_speed:
                k[2:] = 0.0              # surely slow: a_d is held (Joseph form stays valid)
            self.x = self.x + k * nu
            # Joseph form: keeps P symmetric positive definite with the tiny encoder variance
            a = np.eye(len(k))
            a[:, 0] -= k
            self.P = a @ self.P @ a.T + r * np.outer(k, k)
            self.updates += 1
        self.t = z.t
        if switched_on:              # also when the one q = 0 sample before it was lost
            self.on_since = z.t
            self.on_speed = float(self.x[1])
            self.on_contact = meas - z.eta_unwrapped * SECTOR
        self._prev = z
        return self._estimate(z)

    def _reacquire(self) -> None:
        """Restart from the outliers in a row: angle and speed from their least-squares line
        (glitches come one at a time, so a run this long is the wheel itself), the
        disturbance kept, the uncertainty of a first sample."""
        t, a = (np.array(v) for v in zip(*self._run))
        speed, intercept = np.polyfit(t - t[-1], a, 1)
        c = self.config
        r = (COUNT * COUNT) / 12.0 + c.encoder_noise ** 2
        self.x[0], self.x[1] = intercept, speed
        self.P = np.diag([r, (COUNT / (t[-1] - t[0])) ** 2 + r, *self._disturbance_var()])
        self.reacquisitions += 1
        self._run = []

    def _disturbance_var(self) -> list[float]:
        """First variances of (c, a, b, e, f) [(rad/s^2)^2]: 0 for coefficients switched off."""
        c = self.config
        v = c.initial_disturbance_std ** 2
        return [v if c.disturbance_rate > 0.0 else 0.0] * 3 + [v if c.pivot_rate > 0.0 else 0.0] * 2

    def _predict(self, dt: float, prev: TelemetrySample) -> None:
        s = self._s
        phi_a, _ = self._angles(prev.last_command_sequence)
        if prev.last_command_sequence in self._now:
            phi_a = self.on_contact
        s[L.S_Q] = prev.q
        s[L.S_ETA] = prev.eta_unwrapped
        s[L.S_PHI_A] = phi_a
        s[L.S_ON_TIME] = max(prev.t - self.on_since, 0.0) if prev.q else 0.0
        s[L.S_ON_SPEED] = self.on_speed if prev.q else math.inf
        x = self.x
        x1, v1 = self._flow(x, dt, s)
        # Jacobian of the flow by central differences (the flow is smooth within a mode)
        e1, e2 = 1e-6, 1e-6
        z = (0.0,) * (N_STATES - 2)
        a = self._flow(x + (e1, 0.0, *z), dt, s)
        b = self._flow(x - (e1, 0.0, *z), dt, s)
        cc = self._flow(x + (0.0, e2, *z), dt, s)
        d = self._flow(x - (0.0, e2, *z), dt, s)
        F = np.eye(N_STATES)
        F[0, 0] = (a[0] - b[0]) / (2 * e1)
        F[0, 1] = (cc[0] - d[0]) / (2 * e2)
        F[1, 0] = (a[1] - b[1]) / (2 * e1)
        F[1, 1] = (cc[1] - d[1]) / (2 * e2)
        # a_d enters as an added acceleration: d/d(c, a, b, e, f) = (dt^2/2, dt) x basis
        basis = disturbance_basis(float(x[0]), self.pv[L.P_PIVOT_RATIO])
        F[0, 2:] = dt * dt / 2.0 * basis
        F[1, 2:] = dt * basis
        cfg = self.config
        Q = np.zeros((N_STATES, N_STATES))
        Q[:2, :2] = cfg.accel_noise ** 2 * np.array([[dt ** 3 / 3.0, dt ** 2 / 2.0],
                                                     [dt ** 2 / 2.0, dt]])
        Q[2:, 2:] = np.diag([cfg.disturbance_rate ** 2] * 3 + [cfg.pivot_rate ** 2] * 2) * dt
        self.x = np.array([x1, v1, *x[2:]])
        self.P = F @ self.P @ F.T + Q

    def _estimate(self, z: TelemetrySample) -> Estimate:
        phi_a, phi_d = self._angles(z.last_command_sequence)
        base = z.eta_unwrapped * SECTOR
        xi1 = float(self.x[0])
        act = 0.0 if z.q else base + phi_a - xi1
        deact = base + phi_d - xi1
        bad = self._recent_bad / max(len(self._recent), 1)
        quality = max(0.0, 1.0 - 5.0 * bad)
        return Estimate(z.t, xi1, float(self.x[1]), z.q, act, deact, z.eta_unwrapped,
                        float(math.sqrt(max(self.P[1, 1], 0.0))), quality,
                        disturbance_at(self.x[2:], xi1, self.pv[L.P_PIVOT_RATIO]),
                        float(math.sqrt(max(self.P[2, 2], 0.0))),
                        tuple(float(v) for v in self.x[2:]))


#: The observer's states: xi1, xi2 and the five coefficients of a_d.
N_STATES = 7


def disturbance_basis(xi1: float, pivot_ratio: float) -> np.ndarray:
    """(1, cos xi1, sin xi1, cos psi, sin psi), psi = pivot_ratio * xi1: shape (5,)."""
    psi = pivot_ratio * xi1
    return np.array([1.0, math.cos(xi1), math.sin(xi1), math.cos(psi), math.sin(psi)])


def disturbance_at(coefficients, xi1: float, pivot_ratio: float = 0.0) -> float:
    """a_d [rad/s^2] at wheel angle xi1 [rad] for coefficients (c, a, b) or (c, a, b, e, f)
    [rad/s^2]; ``pivot_ratio`` r/L [1] turns xi1 into the pivot angle of e and f."""
    basis = disturbance_basis(xi1, pivot_ratio)[:len(coefficients)]
    return float(np.dot(basis, coefficients))


def fold_pivot(coefficients, xi1: float, pivot_ratio: float) -> tuple[float, float, float]:
    """(c, a, b, e, f) [rad/s^2] -> (c + e cos psi + f sin psi, a, b) with psi = pivot_ratio *
    xi1: the pivot harmonic as a constant, its value at wheel angle ``xi1`` [rad]."""
    c, a, b, e, f = coefficients
    psi = pivot_ratio * xi1
    return (float(c + e * math.cos(psi) + f * math.sin(psi)), float(a), float(b))


def set_disturbance(pv: np.ndarray, base: np.ndarray, coefficients) -> np.ndarray:
    """Write the acceleration disturbance (c, a, b) or (c, a, b, e, f) [rad/s^2] into ``pv``
    as torques [N*m] (missing coefficients are 0).

    c, a, b go into the bias slots.  The pivot pair e cos psi + f sin psi joins the model's
    own platform term T sin(psi + phase) of ``base`` as one sinusoid, so the compiled flow
    evaluates no extra term for it (the plant, which has no estimate, pays nothing).
    ``base`` is the model's own parameter vector (its inertia converts); returns ``pv``.
    """
    if len(coefficients) not in (3, 5):
        raise ValueError(f"disturbance coefficients {tuple(coefficients)!r}: expected (c, a, b) "
                         f"or (c, a, b, e, f) [rad/s^2]")
    inertia = 1.0 / base[L.P_INV_INERTIA]
    pv[L.P_BIAS_TORQUE] = coefficients[0] * inertia
    pv[L.P_BIAS_COS] = coefficients[1] * inertia
    pv[L.P_BIAS_SIN] = coefficients[2] * inertia
    e, f = coefficients[3:5] if len(coefficients) == 5 else (0.0, 0.0)
    torque, phase = base[L.P_PLATFORM_TORQUE], base[L.P_PLATFORM_PHASE]
    along_cos = torque * math.sin(phase) + e * inertia       # T sin(psi + phase) =
    along_sin = torque * math.cos(phase) + f * inertia       #   T sin(phase) cos psi + T cos(phase) sin psi
    pv[L.P_PLATFORM_TORQUE] = math.hypot(along_cos, along_sin)
    pv[L.P_PLATFORM_PHASE] = math.atan2(along_cos, along_sin)
    return pv


def finite_difference_speed(t: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Backward-difference speed [rad/s] of sampled angles (the baseline the observer beats)."""
    v = np.zeros_like(angle)
    v[1:] = np.diff(angle) / np.diff(t)
    return v
