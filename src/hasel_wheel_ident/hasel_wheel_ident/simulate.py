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
def shoot_window(t: np.ndarray, q: np.ndarray, eta: np.ndarray, phi_a: np.ndarray,
                 on_time: np.ndarray, gain: np.ndarray, a: int, b: int, x1: float, x2: float,
                 pv: np.ndarray, out1: np.ndarray, out2: np.ndarray) -> None:
    """One window of :func:`shoot_windows`: samples a..b-1, started from (x1 [rad],
    x2 [rad/s]) at sample a.  Called, not inlined: the kernels below shoot at several places,
    and an inlined copy of the RK4 step at each took numba about a minute to compile."""
    out1[a] = x1
    out2[a] = x2
    for k in range(a, b - 1):
        x1, x2 = _rk4(x1, x2, t[k + 1] - t[k], q[k], eta[k], phi_a[k], gain[k], on_time[k], pv)
        out1[k + 1] = x1
        out2[k + 1] = x2


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
        shoot_window(t, q, eta, phi_a, on_time, gain, starts[w], starts[w + 1], x0[w, 0],
                     x0[w, 1], pv, out1, out2)


@jit_inline
def sample_error(x1: float, k: int, y: np.ndarray, quantum: float, ok: np.ndarray,
                 pv: np.ndarray) -> float:
    """Simulated minus measured angle [rad] at sample k, for the simulated wheel angle x1
    [rad]: what the model's sensor reads (:func:`~hasel_wheel_sim.model.angle_reading`)
    minus y[k], or with encoder counts (``quantum`` [rad], NaN when the angles are not
    counts) its distance from the count's interval [y[k], y[k] + quantum); 0 where ok[k] is
    False.  The same bits as the numpy version it replaced (numpy's clip, NaN kept; kept as
    the reference in test_ident_window_starts.py)."""
    if not ok[k]:
        return 0.0
    m = angle_reading(x1, pv)
    if quantum != quantum:
        return m - y[k]
    lo = y[k]
    hi = y[k] + quantum
    c = m if (m != m or m > lo) else lo
    c = c if (c != c or c < hi) else hi
    return m - c


@jit_kernel
def _pairwise_dot(u: np.ndarray, v: np.ndarray, a: int, n: int) -> float:
    """Sum of u[k] v[k] over k = a..a+n-1, in the order of numpy's pairwise summation (blocks
    of up to 128 in eight running sums, halves above that), so the same bits as numpy's sum
    of the products.

    Recursive, and cached by numba: numba/numba#6061 reports a recursive function that
    crashed when loaded from the cache.  This one loads (numba 0.68; a test compiles it in
    one process and calls it from the cache in another)."""
    if n < 8:
        res = 0.0
        for i in range(a, a + n):
            res += u[i] * v[i]
        return res
    if n <= 128:
        r0 = u[a] * v[a]
        r1 = u[a + 1] * v[a + 1]
        r2 = u[a + 2] * v[a + 2]
        r3 = u[a + 3] * v[a + 3]
        r4 = u[a + 4] * v[a + 4]
        r5 = u[a + 5] * v[a + 5]
        r6 = u[a + 6] * v[a + 6]
        r7 = u[a + 7] * v[a + 7]
        i = a + 8
        end = a + n - n % 8
        while i < end:
            r0 += u[i] * v[i]
            r1 += u[i + 1] * v[i + 1]
            r2 += u[i + 2] * v[i + 2]
            r3 += u[i + 3] * v[i + 3]
            r4 += u[i + 4] * v[i + 4]
            r5 += u[i + 5] * v[i + 5]
            r6 += u[i + 6] * v[i + 6]
            r7 += u[i + 7] * v[i + 7]
            i += 8
        res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
        while i < a + n:
            res += u[i] * v[i]
            i += 1
        return res
    n2 = n // 2
    n2 -= n2 % 8
    return _pairwise_dot(u, v, a, n2) + _pairwise_dot(u, v, a + n2, n - n2)


@jit_inline
def window_dot(u: np.ndarray, v: np.ndarray, a: int, b: int) -> float:
    """Sum of u[k] v[k] over one window, samples a..b-1 (b > a): bit for bit what
    ``np.add.reduceat(u * v, starts)`` gives for it (the first product, plus numpy's pairwise
    sum of the rest; a window of one sample is its product, unchanged, -0.0 included)."""
    if b - a == 1:
        return u[a] * v[a]
    return u[a] * v[a] + _pairwise_dot(u, v, a + 1, b - a - 1)


@jit_inline
def _normal(d1: np.ndarray, d2: np.ndarray, a: int, b: int) -> tuple[float, float, float, float]:
    """The normal matrix (a11, a12, a22) of one window's start derivatives d1, d2 (samples
    a..b-1) and its determinant (inf when |det| <= 1e-30, so that the step is 0)."""
    a11 = window_dot(d1, d1, a, b)
    a12 = window_dot(d1, d2, a, b)
    a22 = window_dot(d2, d2, a, b)
    det = a11 * a22 - a12 * a12
    if not abs(det) > 1e-30:
        det = math.inf
    return a11, a12, a22, det


@jit_inline
def _window_errors(x: np.ndarray, a: int, b: int, y: np.ndarray, quantum: float,
                   ok: np.ndarray, pv: np.ndarray, out: np.ndarray) -> None:
    for k in range(a, b):
        out[k] = sample_error(x[k], k, y, quantum, ok, pv)


@jit_kernel
def shoot_errors(t: np.ndarray, q: np.ndarray, eta: np.ndarray, phi_a: np.ndarray,
                 on_time: np.ndarray, gain: np.ndarray, starts: np.ndarray, windows: np.ndarray,
                 x0: np.ndarray, pv: np.ndarray, y: np.ndarray, quantum: float, ok: np.ndarray,
                 out1: np.ndarray, out2: np.ndarray, err: np.ndarray) -> None:
    """:func:`shoot_windows` (into out1, out2), then the output error of each listed window
    into err (n,) [rad] (:func:`sample_error`; y, quantum, ok as there)."""
    for i in range(windows.shape[0]):
        w = windows[i]
        a = starts[w]
        b = starts[w + 1]
        shoot_window(t, q, eta, phi_a, on_time, gain, a, b, x0[w, 0], x0[w, 1], pv, out1, out2)
        _window_errors(out1, a, b, y, quantum, ok, pv, err)


@jit_kernel
def shoot_quotients(t: np.ndarray, q: np.ndarray, eta: np.ndarray, phi_a: np.ndarray,
                    on_time: np.ndarray, gain: np.ndarray, starts: np.ndarray,
                    windows: np.ndarray, x0: np.ndarray, pv: np.ndarray, y: np.ndarray,
                    quantum: float, ok: np.ndarray, r: np.ndarray, h: float, out1: np.ndarray,
                    out2: np.ndarray, col: np.ndarray) -> None:
    """:func:`shoot_errors` of a parameter vector pv stepped by h from the one whose output
    error is r (n,): the forward-difference quotient (error - r) / h into col (n,; a column
    of the Jacobian, any stride) over the listed windows."""
    for i in range(windows.shape[0]):
        w = windows[i]
        a = starts[w]
        b = starts[w + 1]
        shoot_window(t, q, eta, phi_a, on_time, gain, a, b, x0[w, 0], x0[w, 1], pv, out1, out2)
        for k in range(a, b):
            col[k] = (sample_error(out1[k], k, y, quantum, ok, pv) - r[k]) / h


@jit_kernel
def project_out_starts(J: np.ndarray, d1: np.ndarray, d2: np.ndarray, starts: np.ndarray,
                       windows: np.ndarray, out: np.ndarray) -> None:
    """Each column of J (n, g) less its least-squares fit by each listed window's two start
    derivatives d1, d2 (n,), into out (n, g): the part of a parameter's effect that the
    window starts cannot take up (variable projection).  Sums in numpy's order
    (:func:`window_dot`), so the bits of the same projection written with numpy arrays."""
    for i in range(windows.shape[0]):
        w = windows[i]
        a = starts[w]
        b = starts[w + 1]
        a11, a12, a22, det = _normal(d1, d2, a, b)
        for j in range(J.shape[1]):
            col = J[:, j]
            g1 = window_dot(d1, col, a, b)
            g2 = window_dot(d2, col, a, b)
            c1 = (a22 * g1 - a12 * g2) / det
            c2 = (a11 * g2 - a12 * g1) / det
            for k in range(a, b):
                out[k, j] = col[k] - (c1 * d1[k] + c2 * d2[k])


#: Forward-difference step of the window starts' derivatives [rad, rad/s].
START_STEP = 1e-6


@jit_kernel
def _start_derivatives(t: np.ndarray, q: np.ndarray, eta: np.ndarray, phi_a: np.ndarray,
                       on_time: np.ndarray, gain: np.ndarray, a: int, b: int, s1: float,
                       s2: float, pv: np.ndarray, y: np.ndarray, quantum: float, ok: np.ndarray,
                       r: np.ndarray, d1: np.ndarray, d2: np.ndarray, out1: np.ndarray,
                       out2: np.ndarray) -> None:
    """d residual / d xi1_0 and / d xi2_0 over samples a..b-1 (forward differences of 1e-6
    rad and 1e-6 rad/s from the start (s1, s2), whose residual is r) into d1, d2."""
    shoot_window(t, q, eta, phi_a, on_time, gain, a, b, s1 + START_STEP, s2 + 0.0, pv, out1,
                 out2)
    for k in range(a, b):
        d1[k] = (sample_error(out1[k], k, y, quantum, ok, pv) - r[k]) / START_STEP
    shoot_window(t, q, eta, phi_a, on_time, gain, a, b, s1 + 0.0, s2 + START_STEP, pv, out1,
                 out2)
    for k in range(a, b):
        d2[k] = (sample_error(out1[k], k, y, quantum, ok, pv) - r[k]) / START_STEP


@jit_kernel
def solve_window_starts(t: np.ndarray, q: np.ndarray, eta: np.ndarray, phi_a: np.ndarray,
                        on_time: np.ndarray, gain: np.ndarray, starts: np.ndarray,
                        windows: np.ndarray, x0: np.ndarray, pv: np.ndarray, y: np.ndarray,
                        quantum: float, ok: np.ndarray, iterations: int, r: np.ndarray,
                        d1: np.ndarray, d2: np.ndarray, out1: np.ndarray, out2: np.ndarray,
                        trial: np.ndarray) -> None:
    """Best start (xi1 [rad], xi2 [rad/s]) of each listed window for the parameter vector pv:
    safeguarded Gauss-Newton on the window's own squared output error (see
    :meth:`~.fit.Problem.starts_for`, which documents the rule).  Windows are independent, so
    each runs its iterations alone (a window whose step was refused keeps its derivatives
    rather than recomputing the same ones).

    The arrays are as in :func:`shoot_errors`; x0 (w, 2) holds the starts to begin from and
    gets the solved ones.  Writes the residual r, its derivatives d1, d2 by each window's
    xi1_0 and xi2_0 (each (n,)) over the listed windows; out1, out2 and trial (n,) are
    scratch."""
    for i in range(windows.shape[0]):
        w = windows[i]
        a = starts[w]
        b = starts[w + 1]
        s1 = x0[w, 0]
        s2 = x0[w, 1]
        shoot_window(t, q, eta, phi_a, on_time, gain, a, b, s1, s2, pv, out1, out2)
        _window_errors(out1, a, b, y, quantum, ok, pv, r)
        cost = window_dot(r, r, a, b)
        lam = 1.0                   # step length factor
        stale = True                # derivatives not at (s1, s2)
        for _ in range(iterations):
            if stale:
                _start_derivatives(t, q, eta, phi_a, on_time, gain, a, b, s1, s2, pv, y,
                                   quantum, ok, r, d1, d2, out1, out2)
                stale = False
            a11, a12, a22, det = _normal(d1, d2, a, b)
            g1 = window_dot(d1, r, a, b)
            g2 = window_dot(d2, r, a, b)
            step1 = -(a22 * g1 - a12 * g2) / det
            step2 = -(a11 * g2 - a12 * g1) / det
            t1 = s1 + lam * step1
            t2 = s2 + lam * step2
            if not (t2 > 0.0 or t2 != t2):         # the wheel rolls forwards (or rests);
                t2 = 0.0                            # -0.0 too becomes 0.0, as in np.maximum
            shoot_window(t, q, eta, phi_a, on_time, gain, a, b, t1, t2, pv, out1, out2)
            _window_errors(out1, a, b, y, quantum, ok, pv, trial)
            cost_try = window_dot(trial, trial, a, b)
            take = cost_try <= cost
            if take:
                s1 = t1
                s2 = t2
                cost = cost_try
                for k in range(a, b):
                    r[k] = trial[k]
                stale = True
            small = abs(step1) < 1e-7 and abs(step2) < 1e-6
            lam = min(2.0 * lam, 1.0) if take else 0.25 * lam
            if (take and small) or not lam >= 1.0 / 256:
                break
        if stale:
            _start_derivatives(t, q, eta, phi_a, on_time, gain, a, b, s1, s2, pv, y, quantum,
                               ok, r, d1, d2, out1, out2)
        x0[w, 0] = s1
        x0[w, 1] = s2


@jit_inline
def charge_step(charge: float, on: float, h: float, recovery: float) -> float:
    """Retained charge Q [s] after h [s]: dQ/dt = on - Q / recovery, exact for constant ``on``."""
    decay = math.exp(-h / recovery)
    return charge * decay + on * recovery * (1.0 - decay)


@jit
def retention_charge(t: np.ndarray, q: np.ndarray, pad: np.ndarray, recovery: float,
                     charge0: np.ndarray) -> np.ndarray:
    """Retained charge Q [s of HV time] of the *active* actuator at each sample, shape (n,).

    Every actuator i accumulates dQ_i/dt = q_i - Q_i / recovery from the recorded switching
    (q, pad = eta mod 16), from ``charge0`` (16,) at t[0] (:func:`~.session.prior_charge`);
    the force of the active one is scaled by exp(-rate * Q).
    """
    charge = charge0.copy()
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
             pv: np.ndarray, charge0: np.ndarray, out1: np.ndarray, out2: np.ndarray,
             out_q: np.ndarray) -> None:
    """Free run with model switching over the whole trial.

    act_* (m,): the recorded activations in order (unwrapped pad, phi_a, phi_d [rad]); j0 the
    activation pending at t[0]; on0 1 if it is on at t[0].  The pending activation switches on
    at the first sample where the simulated contact angle reaches phi_a, and off where it
    reaches phi_d, both as the firmware sees it: the sensor's reading of xi1 (pv's
    eccentricity, :func:`~hasel_wheel_sim.model.angle_reading`) less eta pi/8; then the next one is pending.  Gains and retained charge follow the
    simulated switching (pv's gains, retention rate and recovery; the charge starts at
    ``charge0`` (16,), :func:`~.session.prior_charge`).  Nothing switches on after
    ``t_last_on`` [s] (when the recording's last activation switched on), so a simulation
    that runs slower does not drive on past the recorded drive.  x0 = (xi1, xi2) at t[0].
    Writes xi1, xi2, q into out1, out2, out_q (n,).
    """
    charge = charge0.copy()
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
