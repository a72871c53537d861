"""Compiled simulators of the hybrid model for identification (no rclpy, no ROS).

Two ways to switch the actuators:

* **measured switching** (:func:`shoot_windows`): the actuator state (q, eta) recorded at
  sample k acts over [t_k, t_k+1), with the angle phi_a of the activation it belongs to.
  The firmware switches on its 300 Hz ticks and reports the state it switched to, so this
  reproduces it; the least-squares objective is smooth in the parameters, which is what the
  fit needs.  The trial is cut into windows, each started from its own
  (xi1, xi2) (multiple shooting), so an error in one place cannot poison the rest.
* **model switching** (:func:`free_run`): the recorded sequence of activations (pad, phi_a,
  phi_d) is replayed, but each switches on and off when the *simulated* contact angle crosses
  its angles (checked at the sample times, as the firmware does).  A free run from the
  trial's start is the paper's simulation error (Table III).

Both use the model's own flow map (:func:`hasel_wheel_sim.model.acceleration`), so every
extension the model has (COM offset, drag, rise lag, platform torque, gains, retention) is
available to the fit through the parameter vector.
"""
from __future__ import annotations

import math

import numpy as np

from hasel_wheel_sim import layout as L
from hasel_wheel_sim.jit import jit, jit_inline, jit_kernel
from hasel_wheel_sim.model import (N_ACTUATORS, SECTOR, acceleration, angle_reading,
                                   contact_at_switch_on)


@jit_inline
def _rk4(x1: float, x2: float, h: float, q: float, eta: float, phi_a: float, gain: float,
         on_time: float, pv: np.ndarray) -> tuple[float, float]:
    """One RK4 step of (xi1, xi2) over h [s] with the actuator input held; phi_a [rad] is the
    commanded (read) activation angle, turned into the true one the force law needs."""
    if q != 0.0:
        phi_a = contact_at_switch_on(eta, phi_a, pv)
    k1a = x2
    k1b = acceleration(x1, x2, q, eta, phi_a, gain, on_time, pv, 0.0)
    k2a = x2 + 0.5 * h * k1b
    k2b = acceleration(x1 + 0.5 * h * k1a, k2a, q, eta, phi_a, gain, on_time + 0.5 * h, pv, 0.0)
    k3a = x2 + 0.5 * h * k2b
    k3b = acceleration(x1 + 0.5 * h * k2a, k3a, q, eta, phi_a, gain, on_time + 0.5 * h, pv, 0.0)
    k4a = x2 + h * k3b
    k4b = acceleration(x1 + h * k3a, k4a, q, eta, phi_a, gain, on_time + h, pv, 0.0)
    n1 = x1 + h / 6.0 * (k1a + 2.0 * k2a + 2.0 * k3a + k4a)
    n2 = x2 + h / 6.0 * (k1b + 2.0 * k2b + 2.0 * k3b + k4b)
    if x2 > 0.0 and n2 <= 0.0 and q == 0.0:   # friction stopped the wheel inside the step
        return x1 + 0.5 * x2 * h, 0.0          # (it rests; Coulomb friction holds it)
    return n1, n2


@jit_kernel
def shoot_windows(t: np.ndarray, q: np.ndarray, eta: np.ndarray, phi_a: np.ndarray,
                  on_time: np.ndarray, gain: np.ndarray, starts: np.ndarray,
                  windows: np.ndarray, x0: np.ndarray, pv: np.ndarray, out1: np.ndarray,
                  out2: np.ndarray) -> None:
    """Multiple-shooting simulation with measured switching, of the listed windows only.

    t (n,) [s]; q (n,) 0/1; eta (n,) unwrapped sector of the actuator of interest (float, may
    carry a fractional angle offset); phi_a (n,) [rad] activation angle in effect; on_time (n,)
    [s] time since the active actuator switched on; gain (n,) force multiplier of the active
    actuator; starts (w+1,) sample index where each window starts (last = n); windows (m,)
    indices of the windows to simulate; x0 (w, 2) initial (xi1 [rad], xi2 [rad/s]) of each
    window; pv the model's parameter vector.  Writes xi1 into out1 (n,) and xi2 into out2 (n,)
    over the listed windows and leaves the other samples alone.
    """
    for i in range(windows.shape[0]):
        w = windows[i]
        a = starts[w]
        b = starts[w + 1]
        x1 = x0[w, 0]
        x2 = x0[w, 1]
        out1[a] = x1
        out2[a] = x2
        for k in range(a, b - 1):
            x1, x2 = _rk4(x1, x2, t[k + 1] - t[k], q[k], eta[k], phi_a[k], gain[k],
                          on_time[k], pv)
            out1[k + 1] = x1
            out2[k + 1] = x2


@jit_inline
def charge_step(charge: float, on: float, h: float, recovery: float) -> float:
    """Retained charge Q [s] after h [s]: dQ/dt = on - Q / recovery, exact for constant ``on``."""
    decay = math.exp(-h / recovery)
    return charge * decay + on * recovery * (1.0 - decay)


@jit
def retention_charge(t: np.ndarray, q: np.ndarray, pad: np.ndarray, recovery: float) -> np.ndarray:
    """Retained charge Q [s of HV time] of the *active* actuator at each sample, shape (n,).

    Every actuator i accumulates dQ_i/dt = q_i - Q_i / recovery from the recorded switching
    (q, pad = eta mod 16); the force of the active one is scaled by exp(-rate * Q).
    """
    charge = np.zeros(N_ACTUATORS)
    out = np.zeros(t.shape[0])
    for k in range(t.shape[0]):
        out[k] = charge[pad[k]]
        if k + 1 < t.shape[0]:
            h = t[k + 1] - t[k]
            for i in range(N_ACTUATORS):
                on = 1.0 if (q[k] != 0 and pad[k] == i) else 0.0
                charge[i] = charge_step(charge[i], on, h, recovery)
    return out


@jit
def free_run(t: np.ndarray, act_eta: np.ndarray, act_phi_a: np.ndarray, act_phi_d: np.ndarray,
             j0: int, on0: int, x0: np.ndarray, eta_offset: float, t_last_on: float,
             pv: np.ndarray, out1: np.ndarray, out2: np.ndarray, out_q: np.ndarray) -> None:
    """Free run with model switching over the whole trial.

    act_* (m,): the recorded activations in order (unwrapped pad, phi_a, phi_d [rad]); j0 the
    activation pending at t[0]; on0 1 if it is on at t[0].  The pending activation switches on
    at the first sample where the simulated contact angle reaches phi_a, and off where it
    reaches phi_d, both as the firmware sees it: the sensor's reading of xi1 (pv's
    eccentricity, :func:`~hasel_wheel_sim.model.angle_reading`) less eta pi/8; then the next one is pending.  Gains and retained charge follow the
    simulated switching (pv's gains, retention rate and recovery).  Nothing switches on after
    ``t_last_on`` [s] (when the recording's last activation switched on), so a simulation
    that runs slower does not drive on past the recorded drive.  x0 = (xi1, xi2) at t[0].
    Writes xi1, xi2, q into out1, out2, out_q (n,).
    """
    charge = np.zeros(N_ACTUATORS)
    x1 = x0[0]
    x2 = x0[1]
    j = j0
    on = on0
    t_on = t[0]
    m = act_eta.shape[0]
    rate = pv[L.P_RET_RATE]
    recovery = pv[L.P_RET_RECOVERY]
    for k in range(t.shape[0]):
        if j < m:
            xc = angle_reading(x1, pv) - (act_eta[j] + eta_offset) * SECTOR
            if on == 0 and xc >= act_phi_a[j] and t[k] <= t_last_on:
                on = 1
                t_on = t[k]
            if on == 1 and xc >= act_phi_d[j]:
                on = 0
                j += 1
        out1[k] = x1
        out2[k] = x2
        out_q[k] = on
        if k + 1 == t.shape[0]:
            break
        h = t[k + 1] - t[k]
        if on == 1:
            pad = int(act_eta[j]) % N_ACTUATORS
            g = pv[L.P_GAINS + pad]
            if rate > 0.0:
                g *= math.exp(-rate * charge[pad])
            x1, x2 = _rk4(x1, x2, h, 1.0, act_eta[j] + eta_offset, act_phi_a[j], g,
                          t[k] - t_on, pv)
        else:
            x1, x2 = _rk4(x1, x2, h, 0.0, 0.0, 0.0, 1.0, 0.0, pv)
        if rate > 0.0:
            for i in range(N_ACTUATORS):
                a_on = 1.0 if (on == 1 and int(act_eta[j]) % N_ACTUATORS == i) else 0.0
                charge[i] = charge_step(charge[i], a_on, h, recovery)
