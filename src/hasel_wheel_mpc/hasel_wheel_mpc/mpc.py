"""Model predictive speed control (paper Sec. V) on the hybrid model, without ROS.

At each switch-on of the current actuator (the paper's decision point), the controller
chooses u = (n_a, phi_a, phi_d) for the next pad.  It predicts every candidate over the next
activation-deactivation cycle with the hybrid model, all candidates at once in one compiled
batch.  The prediction switches on 300 Hz ticks, as the firmware does, and the candidate is
latched when the current actuator switches off.

Cost (59), as we read it: the next cycle has two flow segments, q = 0 (waiting for the
candidate's switch-on) and q = 1 (the candidate on, until it switches off).  Each segment's
squared speed error is averaged over its samples, and J = 1/2 (mean_0 + mean_1).  The speed
before the current actuator switches off is the same for every candidate, so it is not part
of J.  The disturbance estimate enters as a speed offset: xi2_prdt = xi2_model + d.

Our addition: a terminal term w_T (xi2_end + d - xi2_r)^2 (``terminal_weight``; 0 = (59) alone),
see :func:`costs_59`.

Braking (Sec. V-A): when the estimated speed is at least ``brake_threshold`` [rad/s] above the
reference, u = braking_input (n_a = eta + 2, -22 deg, -6 deg); no search.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from hasel_wheel_driver.samples import Command
from hasel_wheel_sim import layout as L
from hasel_wheel_sim.integrator import simulate_batch
from hasel_wheel_sim.jit import jit
from hasel_wheel_sim.model import SECTOR, Extensions, braking_input, param_vector
from hasel_wheel_sim.params import WheelParams
from hasel_wheel_sim.wheel import TICK, initial_state

D = math.radians


@dataclass(frozen=True)
class MpcConfig:
    """Search space and modes (angles rad, speeds rad/s)."""

    phi_a: tuple[float, ...] = tuple(D(x) for x in np.arange(1.0, 15.01, 0.5))
    phi_d: tuple[float, ...] = tuple(D(x) for x in (16.0, 18.0, 20.0, 22.0))
    brake_threshold: float = 0.3
    brake_phi_a: float = D(-22.0)
    brake_phi_d: float = D(-6.0)
    max_horizon: float = 4.0           # longest prediction [s] (slow wheels)
    terminal_weight: float = 1.0       # w_T of our terminal term; 0 gives (59) exactly [1]

    def candidates(self) -> np.ndarray:
        """(n, 2) array of (phi_a, phi_d) with phi_a < phi_d."""
        return np.array([(a, d) for d in self.phi_d for a in self.phi_a if a < d])


class Decision(NamedTuple):
    command: Command
    predicted_speed: float   # mean predicted speed over the candidate's cycle [rad/s] (with d)
    cost: float              # J of (59) [(rad/s)^2]
    candidates: int
    compute_time: float      # [s]
    braking: bool


def cost_59(speed: np.ndarray, q: np.ndarray, reference: float, d: float = 0.0) -> float:
    """J of (59) for one predicted trajectory that starts with the current actuator on.

    ``speed``, ``q`` (n,) per tick.  Segments: after the current switch-off (first 1 -> 0),
    q = 0 until the candidate's switch-on, then q = 1 until its switch-off.  Returns +inf if
    the horizon does not contain the whole cycle.
    """
    qi = q.astype(np.int8)
    edges = np.flatnonzero(np.diff(qi)) + 1         # indices where q changes
    offs = [i for i in edges if qi[i] == 0]
    ons = [i for i in edges if qi[i] == 1]
    if not offs:
        return math.inf
    a = offs[0]
    on_after = [i for i in ons if i > a]
    if not on_after:
        return math.inf
    b = on_after[0]
    off_after = [i for i in offs if i > b]
    if not off_after:
        return math.inf
    c = off_after[0]
    e = speed + d - reference
    return 0.5 * (float(np.mean(e[a:b] ** 2)) + float(np.mean(e[b:c] ** 2)))


def cycle_mean(speed: np.ndarray, q: np.ndarray) -> float:
    """Mean speed over the next cycle: from the current switch-off to the candidate's
    switch-off (the window (59) judges); the whole horizon if it holds no full cycle."""
    qi = q.astype(np.int8)
    offs = np.flatnonzero((qi[:-1] == 1) & (qi[1:] == 0)) + 1
    if offs.size >= 2:
        return float(np.mean(speed[offs[0]:offs[1]]))
    return float(np.mean(speed))


@jit
def costs_59(out: np.ndarray, reference: float, d: float, costs: np.ndarray,
             terminal_weight: float = 0.0) -> None:
    """:func:`cost_59` for every row of ``out`` (n, ticks, 3) at once (compiled).

    With ``terminal_weight`` w_T > 0 it adds w_T (xi2 + d - ref)^2 at the candidate's
    switch-off: (59) alone looks at one cycle only, and a joint (phi_a, phi_d) search then
    happily picks a weak push that stays near the reference this cycle and leaves the wheel
    too slow for the next (observed).  The paper, searching phi_a only with phi_d = 22 deg,
    did not meet this.
    """
    for i in range(out.shape[0]):
        a = -1
        b = -1
        c = -1
        for k in range(1, out.shape[1]):
            q0 = out[i, k - 1, 2]
            q1 = out[i, k, 2]
            if q0 == 1.0 and q1 == 0.0:
                if a < 0:
                    a = k
                elif b >= 0:
                    c = k
                    break
            elif q0 == 0.0 and q1 == 1.0 and a >= 0 and b < 0:
                b = k
        if c < 0:
            costs[i] = math.inf
            continue
        s0 = 0.0
        for k in range(a, b):
            e = out[i, k, 1] + d - reference
            s0 += e * e
        s1 = 0.0
        for k in range(b, c):
            e = out[i, k, 1] + d - reference
            s1 += e * e
        end = out[i, c - 1, 1] + d - reference
        costs[i] = 0.5 * (s0 / (b - a) + s1 / (c - b)) + terminal_weight * end * end


class Mpc:
    """``decide(xi1, xi2, eta_unwrapped, phi_a_now, phi_d_now, reference, d) -> Decision``."""

    def __init__(self, params: WheelParams | None = None, extensions: Extensions | None = None,
                 config: MpcConfig | None = None) -> None:
        self.config = config or MpcConfig()
        self.cands = self.config.candidates()
        self.pv = param_vector(params or WheelParams(), extensions)
        n = len(self.cands)
        self._pvs = np.tile(self.pv, (n, 1))
        self._base = initial_state(mode="tick")
        self.seq = 0

    def decide(self, xi1: float, xi2: float, eta_unwrapped: int, phi_a_now: float,
               phi_d_now: float, reference: float, d: float = 0.0) -> Decision:
        """Choose u for the pad after ``eta_unwrapped`` (the actuator that just switched on)."""
        t0 = time.perf_counter()
        self.seq += 1
        if xi2 + d >= reference + self.config.brake_threshold:
            n_a, pa, pd = braking_input(xi1, self.config.brake_phi_a, self.config.brake_phi_d)
            cmd = Command(n_a, pa, pd, self.seq)
            return Decision(cmd, xi2 + d, math.nan, 0, time.perf_counter() - t0, True)
        n = len(self.cands)
        s = self._base.copy()
        s[L.S_XI1] = xi1
        s[L.S_XI2] = xi2
        s[L.S_Q] = 1.0
        s[L.S_ETA] = eta_unwrapped
        s[L.S_ARMED] = 1.0
        s[L.S_PHI_A] = phi_a_now
        s[L.S_PHI_D] = phi_d_now
        s[L.S_THETA_ON] = eta_unwrapped * SECTOR + phi_a_now
        s[L.S_THETA_OFF] = eta_unwrapped * SECTOR + phi_d_now
        s[L.S_PEND] = 1.0
        s[L.S_PEND_NA] = float((eta_unwrapped + 1) % 16)
        states = np.tile(s, (n, 1))
        states[:, L.S_PEND_PHI_A] = self.cands[:, 0]
        states[:, L.S_PEND_PHI_D] = self.cands[:, 1]
        # long enough for ~2.3 sectors at the current speed (the rest of this pad + the next)
        horizon = min(self.config.max_horizon, 2.3 * SECTOR / max(xi2, 0.3))
        n_ticks = max(int(horizon / TICK), 10)
        out = np.empty((n, n_ticks, 3))
        simulate_batch(states, self._pvs, TICK, n_ticks, out)
        costs = np.empty(n)
        costs_59(out, reference, d, costs, self.config.terminal_weight)
        if np.isfinite(costs).any():
            best = int(np.argmin(costs))
        else:   # no candidate completes its cycle within the horizon: push as hard as we can
            best = int(np.lexsort((self.cands[:, 0], -self.cands[:, 1]))[0])
        pa, pd = self.cands[best]
        cmd = Command((eta_unwrapped + 1) % 16, float(pa), float(pd), self.seq)
        return Decision(cmd, cycle_mean(out[best, :, 1], out[best, :, 2]) + d,
                        float(costs[best]), n, time.perf_counter() - t0, False)
