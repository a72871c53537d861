"""Integration of the hybrid model: RK4 flows with exactly located jumps.

Flows use classical RK4 with the paper's step h = 1/300 s.  In *exact* mode a step that
would carry xi1 past the next switching angle is split: the partial step length that lands
xi1 on the angle is found by safeguarded Newton iteration on the RK4 step map (to 1e-12 rad),
the jump (52) is applied there, and the rest of the step follows.  In *tick* mode the
switching happens as on the firmware: on the first 300 Hz tick at which the angle has been
passed.  In both modes a wheel that friction brings to rest stops exactly (speed 0).

One wheel's state lives in a flat float64 vector (:mod:`.layout`).  :func:`advance` moves it
by one tick; :func:`simulate_batch` moves N wheels (an (N, S_SIZE) array) over many ticks and
records their angle and speed.  Both are compiled by numba when it is installed.
"""
from __future__ import annotations

import math

import numpy as np

from hasel_wheel_sim import layout as L
from hasel_wheel_sim.jit import jit, jit_inline, jit_kernel, jit_parallel, prange
from hasel_wheel_sim.model import (N_ACTUATORS, SECTOR, acceleration, angle_at_reading, angle_reading,
                    contact_at_switch_on, sector_of, unwrap_target)

#: Tolerance of event location on the wheel angle [rad].
EVENT_TOL = 1e-12


@jit_inline
def _gain(s: np.ndarray, pv: np.ndarray) -> float:
    """Force gain of the actuator of interest: fabrication spread x charge retention."""
    act = int(s[L.S_ETA]) % N_ACTUATORS
    g = pv[L.P_GAINS + act]
    if pv[L.P_RET_RATE] > 0.0:
        g *= math.exp(-pv[L.P_RET_RATE] * s[L.S_RET + act])
    return g


@jit_inline
def rk4(xi1: float, xi2: float, h: float, s: np.ndarray, gain: float,
        pv: np.ndarray) -> tuple[float, float]:
    """One classical RK4 step of length h [s] of (xi1, xi2) with q, eta, phi_a held (a flow).

    Friction keeps the direction of the speed at the start of the step: a sign change of
    xi2 inside the step is a stop event, located separately.
    """
    fd = 1.0 if xi2 > 0.0 else (-1.0 if xi2 < 0.0 else 0.0)
    q = s[L.S_Q]
    eta = s[L.S_ETA]
    pa = contact_at_switch_on(eta, s[L.S_PHI_A], pv)
    t_on = s[L.S_ON_TIME]
    w_on = s[L.S_ON_SPEED]
    hh = 0.5 * h
    a1 = acceleration(xi1, xi2, q, eta, pa, gain, t_on, pv, fd, w_on)
    x2 = xi1 + hh * xi2
    v2 = xi2 + hh * a1
    a2 = acceleration(x2, v2, q, eta, pa, gain, t_on + hh, pv, fd, w_on)
    x3 = xi1 + hh * v2
    v3 = xi2 + hh * a2
    a3 = acceleration(x3, v3, q, eta, pa, gain, t_on + hh, pv, fd, w_on)
    x4 = xi1 + h * v3
    v4 = xi2 + h * a3
    a4 = acceleration(x4, v4, q, eta, pa, gain, t_on + h, pv, fd, w_on)
    return (xi1 + h / 6.0 * (xi2 + 2.0 * v2 + 2.0 * v3 + v4),
            xi2 + h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4))


@jit_kernel
def _locate(s: np.ndarray, gain: float, pv: np.ndarray, h_max: float, x1: float, v1: float,
            target: float, which: int) -> tuple[float, float, float]:
    """Partial RK4 step at which the flow reaches ``target``: (length in (0, h_max] [s],
    xi1 [rad], xi2 [rad/s] at its end).

    ``which`` = 0: xi1 reaches ``target`` (increasing); 1: xi2 reaches 0 (sign change).
    (x1, v1) is the full step of length h_max, which the caller has already taken.  The state
    returned is the RK4 step of the length returned, as computed, so the caller need not
    repeat it.  Safeguarded Newton: a bracket [lo, hi] is kept and bisection used whenever
    Newton leaves it.
    """
    x0 = s[L.S_XI1]
    v0 = s[L.S_XI2]
    lo = 0.0
    hi = h_max
    x_hi, v_hi = x1, v1
    if which == 0:
        f_lo = x0 - target
        f_hi = x1 - target
    else:
        f_lo = v0
        f_hi = v1
    sign_lo = 1.0 if f_lo > 0.0 else -1.0
    # linear first guess
    hg = h_max * f_lo / (f_lo - f_hi) if f_lo != f_hi else h_max
    for _ in range(60):
        if not (lo < hg < hi):
            hg = 0.5 * (lo + hi)
        x, v = rk4(x0, v0, hg, s, gain, pv)
        if which == 0:
            f = x - target
            df = v
        else:
            f = v
            df = acceleration(x, v, s[L.S_Q], s[L.S_ETA],
                              contact_at_switch_on(s[L.S_ETA], s[L.S_PHI_A], pv), gain,
                              s[L.S_ON_TIME] + hg, pv, 1.0 if v0 > 0.0 else -1.0,
                              s[L.S_ON_SPEED])
        if which == 0 and abs(f) <= EVENT_TOL:
            return hg, x, v
        if which == 1 and abs(f) <= 1e-13:
            return hg, x, v
        if f * sign_lo > 0.0:
            lo = hg
        else:
            hi = hg
            x_hi, v_hi = x, v
        if hi - lo <= 1e-15:
            return hi, x_hi, v_hi
        hg = hg - f / df if df != 0.0 else 0.5 * (lo + hi)
    return hi, x_hi, v_hi


@jit_inline
def _flow(s: np.ndarray, gain: float, pv: np.ndarray, dt: float, x: float, v: float) -> None:
    """Commit a flow of duration dt that ended at (x, v): time, on-time, retention, counters."""
    s[L.S_T] += dt
    s[L.S_XI1] = x
    s[L.S_XI2] = v
    q = s[L.S_Q]
    if q != 0.0:
        s[L.S_ON_TIME] += dt
        s[L.S_ACT_TIME] += dt
    if pv[L.P_RET_RATE] > 0.0:
        tau = pv[L.P_RET_RECOVERY]
        decay = math.exp(-dt / tau)
        for i in range(N_ACTUATORS):
            s[L.S_RET + i] *= decay
        if q != 0.0:
            act = int(s[L.S_ETA]) % N_ACTUATORS
            s[L.S_RET + act] += tau * (1.0 - decay)


@jit_kernel
def _latch(s: np.ndarray, pv: np.ndarray, n_a: float, phi_a: float, phi_d: float,
           seq: float) -> None:
    """Latch u = (n_a, phi_a, phi_d): the eta, Delta, delta parts of the jump map (52).

    The firmware switches when its angle *reading* reaches N pi/8 + phi; the switching
    angles are kept as the wheel angles where that happens (the same with an exact sensor)."""
    n = unwrap_target(n_a, phi_a, angle_reading(s[L.S_XI1], pv))
    s[L.S_ETA] = n
    # (never behind the wheel: rounding in the inverse must not put a due switch-on in the past)
    s[L.S_THETA_ON] = max(angle_at_reading(n * SECTOR + phi_a, pv), s[L.S_XI1])
    s[L.S_THETA_OFF] = angle_at_reading(n * SECTOR + phi_d, pv)
    s[L.S_PHI_A] = phi_a
    s[L.S_PHI_D] = phi_d
    s[L.S_CMD_SEQ] = seq
    s[L.S_ARMED] = 1.0


@jit_kernel
def _next_command(s: np.ndarray, pv: np.ndarray) -> bool:
    """Latch the next command if there is one: the pending command first, else the
    built-in open-loop schedule.  Returns False when there is none (the wheel idles)."""
    if s[L.S_PEND] != 0.0:
        s[L.S_PEND] = 0.0
        _latch(s, pv, s[L.S_PEND_NA], s[L.S_PEND_PHI_A], s[L.S_PEND_PHI_D], s[L.S_PEND_SEQ])
        return True
    auto = int(s[L.S_AUTO])
    if auto == L.AUTO_OFF:
        return False
    if auto == L.AUTO_AFTER_ACTIVE and s[L.S_N_ON] > 0:
        base = s[L.S_ETA]
    else:  # after the sector measured now (eq. (40)), also used for the very first target
        base = sector_of(angle_reading(s[L.S_XI1], pv))
    n_a = float((int(base) + 1) % N_ACTUATORS)
    phi_a = s[L.S_AUTO_PHI_A]
    if s[L.S_PRIME_LEFT] > 0.0:
        s[L.S_PRIME_LEFT] -= 1.0
        phi_a = s[L.S_PRIME_PHI_A]
    _latch(s, pv, n_a, phi_a, s[L.S_AUTO_PHI_D], -1.0)
    return True


@jit_kernel
def _record(ev: np.ndarray, n: int, s: np.ndarray, kind: int) -> int:
    if n < ev.shape[0]:
        ev[n, 0] = s[L.S_T]
        ev[n, 1] = s[L.S_XI1]
        ev[n, 2] = kind
        ev[n, 3] = s[L.S_ETA]
    return n + 1


@jit_kernel
def _switch(s: np.ndarray, pv: np.ndarray, ev: np.ndarray, n_ev: int) -> int:
    """Apply the jump (52) due now: switch-on if q = 0, switch-off (and latch) if q = 1."""
    if s[L.S_Q] == 0.0:
        s[L.S_Q] = 1.0
        s[L.S_ON_TIME] = 0.0
        s[L.S_ON_SPEED] = s[L.S_XI2]
        s[L.S_N_ON] += 1.0
        return _record(ev, n_ev, s, L.EV_ON)
    s[L.S_Q] = 0.0
    s[L.S_N_OFF] += 1.0
    n_ev = _record(ev, n_ev, s, L.EV_OFF)  # eta of the actuator that switched off
    if not _next_command(s, pv):
        s[L.S_ARMED] = 0.0
    return n_ev


def _advance(s: np.ndarray, pv: np.ndarray, h: float, ev: np.ndarray) -> int:
    """Advance one wheel by exactly h seconds (one firmware tick); return the event count.

    ``s`` (S_SIZE,) is updated in place; events are written to ``ev`` (k, 4) as rows
    (time [s], xi1 [rad], kind, eta) -- see ``layout.EV_*``; eta is the actuator that
    switched (on/off) or the target latched (arm).
    """
    n_ev = 0
    # while no actuator is on, a waiting command takes effect now: it arms an idle wheel or
    # replaces a target that has not switched on (which a stopped wheel might never reach)
    if s[L.S_Q] == 0.0 and (s[L.S_ARMED] == 0.0 or s[L.S_PEND] != 0.0):
        if _next_command(s, pv):
            n_ev = _record(ev, n_ev, s, L.EV_ARM)
    exact = s[L.S_MODE] == L.MODE_EXACT
    remaining = h
    for _ in range(64):
        if remaining <= 0.0:
            break
        gain = _gain(s, pv)
        x0 = s[L.S_XI1]
        v0 = s[L.S_XI2]
        x1, v1 = rk4(x0, v0, remaining, s, gain, pv)
        armed = s[L.S_ARMED] != 0.0
        target = s[L.S_THETA_OFF] if s[L.S_Q] != 0.0 else s[L.S_THETA_ON]
        cross = exact and armed and x1 >= target
        stop = (v0 > 0.0 and v1 < 0.0) or (v0 < 0.0 and v1 > 0.0)
        if not cross and not stop:
            _flow(s, gain, pv, remaining, x1, v1)
            remaining = 0.0
            break
        h_sw, x_sw, v_sw = math.inf, x1, v1
        h_st, x_st = math.inf, x1
        if cross:
            h_sw, x_sw, v_sw = _locate(s, gain, pv, remaining, x1, v1, target, 0)
        if stop:
            h_st, x_st, _ = _locate(s, gain, pv, remaining, x1, v1, 0.0, 1)
        if h_sw <= h_st:
            _flow(s, gain, pv, h_sw, x_sw, v_sw)
            remaining -= h_sw
            n_ev = _switch(s, pv, ev, n_ev)
        else:
            _flow(s, gain, pv, h_st, x_st, 0.0)
            remaining -= h_st
            n_ev = _record(ev, n_ev, s, L.EV_STOP)
    if not exact and s[L.S_ARMED] != 0.0:
        target = s[L.S_THETA_OFF] if s[L.S_Q] != 0.0 else s[L.S_THETA_ON]
        if s[L.S_XI1] >= target:
            n_ev = _switch(s, pv, ev, n_ev)
    return n_ev


#: One tick of one wheel (``_advance``), called from Python, the plant and the MPC.
advance = jit_kernel(_advance)
#: The same function inlined into :func:`run_wheel`'s loop, which saves a call per tick
#: (bench_model.py prints the batch's bookkeeping per tick, inlined and called).
_advance_inline = jit_inline(_advance)


@jit_kernel
def run_wheel(s: np.ndarray, pv: np.ndarray, h: float, n_ticks: int, out: np.ndarray,
              ev: np.ndarray) -> None:
    """Advance one wheel by ``n_ticks`` ticks; ``out`` (n_ticks, 3) gets (xi1, xi2, q) per tick."""
    for k in range(n_ticks):
        _advance_inline(s, pv, h, ev)
        out[k, 0] = s[L.S_XI1]
        out[k, 1] = s[L.S_XI2]
        out[k, 2] = s[L.S_Q]


@jit
def simulate_batch(states: np.ndarray, pvs: np.ndarray, h: float, n_ticks: int,
                   out: np.ndarray) -> None:
    """Advance N wheels by ``n_ticks`` ticks of h seconds and record them.

    states (N, S_SIZE) and pvs (N, P_SIZE) hold one wheel per row; ``out`` (N, n_ticks, 3)
    receives (xi1 [rad], xi2 [rad/s], q) after every tick.  ``states`` is updated in place.
    """
    ev = np.zeros((L.EV_MAX_PER_TICK, 4))
    for i in range(states.shape[0]):
        run_wheel(states[i], pvs[i], h, n_ticks, out[i], ev)


@jit_parallel
def simulate_batch_parallel(states: np.ndarray, pvs: np.ndarray, h: float, n_ticks: int,
                            out: np.ndarray) -> None:
    """:func:`simulate_batch` with the wheels spread over all cores (same results, bitwise)."""
    for i in prange(states.shape[0]):
        run_wheel(states[i], pvs[i], h, n_ticks, out[i], np.zeros((L.EV_MAX_PER_TICK, 4)))
