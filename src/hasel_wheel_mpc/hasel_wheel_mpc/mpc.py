"""Model predictive speed control (paper Sec. V) on the hybrid model, without ROS.

At each switch-on of the current actuator the controller chooses u = (n_a, phi_a, phi_d) for
the next pad: it predicts every candidate with the hybrid model (compiled, 300 Hz firmware
ticks, latched at the current switch-off) and keeps the cheapest.  The reasons for each
choice are in ``docs/controller.md``.  Angles rad, speeds rad/s, times s.

* Horizon: ``horizon_pads`` cycles, 1 (the paper's) or 2 (default: that cycle and the next,
  in which the next pad repeats the candidate's angles).  Two cycles hold each cycle's mean
  speed closer to the reference where an off-centre mass moves it
  (``test_controller.py::test_two_cycle_horizon_holds_each_cycle_mean_where_an_off_centre_mass_moves_it``).
* Search: a coarse pass over ``phi_a`` x ``phi_d`` (default the paper's 15 candidates, 1-15
  deg at 22 deg), then a joint pass around the winner, ``refine_phi_a`` x ``refine_phi_d``
  (default +-0.25 deg x {21, 22} deg less the pair already predicted: 20 in all;
  ``test_mpc.py::test_refinement_searches_phi_a_and_phi_d_jointly_around_the_coarse_winner``).
* Cost (59) [(rad/s)^2]: the mean of the segment means of (xi2 + d - xi2_r)^2 over the
  horizon's q = 0 and q = 1 segments; ``time_weighted`` (default) takes the mean over all
  its samples instead; ``terminal_weight`` adds w_T (xi2_end - xi2_r)^2 (default 0)
  (``test_mpc.py::test_cost_59_by_hand``, ``test_cost_over_two_cycles_by_hand``).
* Disturbances: the estimator's speed offset d [rad/s] is added to the predicted speed, the
  observer's a_d(xi1) [rad/s^2] to the model's acceleration (observer.py, disturbance.py).
* Braking (Sec. V-A): when xi2 + d >= xi2_r + ``brake_threshold`` [rad/s], u = (n_a,
  ``brake_phi_a``, ``brake_phi_d``), no search; defaults 0.2 rad/s, -22.4 deg, -6 deg (the
  paper: 0.3, -22, -6).  n_a and phi_a come from :func:`braking_command`: the earliest
  switch-on the pad still reaches, the strongest in our braking-force model
  (``test_mpc.py::test_braking_when_the_speed_is_above_the_reference_by_the_threshold``,
  ``test_braking_pad_switches_on_no_earlier_than_it_still_can``).  A new reference between
  two pads is braked on at once (:meth:`Mpc.brake_now`).
* Deadline: the decision must be ready ``deadline_margin`` [s] before the current actuator
  switches off, as the prediction times it.  A later one is discarded and the fallback sent:
  the last driving (phi_a, phi_d) for the next pad, phi_a raised to :func:`earliest_phi_a`
  and kept within ``phi_a_max``; each miss is counted in ``Mpc.deadline_misses``
  (``test_mpc.py::test_a_late_decision_is_replaced_by_the_fallback_and_counted``).
"""
from __future__ import annotations

import functools
import gc
import math
import time
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from hasel_wheel_common.samples import Command
from hasel_wheel_sim import layout as L
from hasel_wheel_sim.integrator import advance
from hasel_wheel_sim.jit import jit
from hasel_wheel_sim.model import SECTOR, Extensions, reading_param_vector
from hasel_wheel_sim.params import WheelParams
from hasel_wheel_sim.wheel import TICK, initial_state

from hasel_wheel_mpc.observer import fold_pivot, set_disturbance

D = math.radians


#: Allowed prediction horizons [cycles].
HORIZON_PADS = (1, 2)


@dataclass(frozen=True)
class MpcConfig:
    """Search space, cost and modes (angles rad, speeds rad/s, times s)."""

    phi_a: tuple[float, ...] = tuple(D(x) for x in range(1, 16))      # coarse pass
    phi_d: tuple[float, ...] = (D(22.0),)
    refine_phi_a: tuple[float, ...] = tuple(D(x) for x in (-0.25, 0.0, 0.25))
    refine_phi_d: tuple[float, ...] = tuple(D(x) for x in (21.0, 22.0))
    brake_threshold: float = 0.2       # [rad/s] above the reference
    brake_phi_a: float = D(-22.4)      # [rad], or the earliest the pad can still switch on
    brake_phi_d: float = D(-6.0)
    max_horizon: float = 6.0           # longest prediction [s] (slow wheels)
    terminal_weight: float = 0.0       # w_T of our terminal term [1]; 0 = none
    horizon_pads: int = 2              # cycles predicted: 1 = the paper's, 2 = and the next
    time_weighted: bool = True         # mean over all the cycle's samples; False = (59) exactly
    deadline_margin: float = 0.004     # the command's way to the wheel [s]
    phi_a_min: float = 0.0             # actuation limits: driving phi_a only in [min, max] [rad]
    phi_a_max: float = SECTOR

    def __post_init__(self) -> None:
        for name in ("phi_a", "phi_d", "refine_phi_d"):
            bad = [x for x in getattr(self, name) if not 0.0 < x < SECTOR]
            if bad:
                raise ValueError(f"{name} = {bad} rad: driving angles must lie in (0, pi/8)")
        if not (math.isfinite(self.brake_threshold) and self.brake_threshold > 0.0):
            raise ValueError(f"brake_threshold = {self.brake_threshold!r} rad/s: expected > 0")
        if not (-SECTOR < self.brake_phi_a < self.brake_phi_d < 0.0):
            raise ValueError(f"braking angles brake_phi_a = {self.brake_phi_a!r}, brake_phi_d = "
                             f"{self.brake_phi_d!r} rad: expected -pi/8 < brake_phi_a < "
                             f"brake_phi_d < 0 rad")
        if self.terminal_weight < 0.0 or self.deadline_margin < 0.0 or self.max_horizon <= 0.0:
            raise ValueError("terminal_weight and deadline_margin must be >= 0, max_horizon > 0")
        if self.horizon_pads not in HORIZON_PADS or isinstance(self.horizon_pads, bool):
            raise ValueError(f"horizon_pads = {self.horizon_pads!r}: expected 1 (the paper's "
                             f"one cycle) or 2 (that cycle and the next)")
        if not 0.0 <= self.phi_a_min < self.phi_a_max <= SECTOR:
            raise ValueError(f"phi_a_min = {self.phi_a_min!r}, phi_a_max = {self.phi_a_max!r} rad: "
                             f"expected 0 <= phi_a_min < phi_a_max <= pi/8")
        if not self.candidates().size:
            raise ValueError(f"no coarse phi_a candidate lies in [phi_a_min, phi_a_max] = "
                             f"[{self.phi_a_min!r}, {self.phi_a_max!r}] rad (candidates: "
                             f"{', '.join(f'{a:.4f}' for a in self.phi_a)} rad)")

    def _allowed(self, phi_a: float) -> bool:
        return self.phi_a_min <= phi_a <= self.phi_a_max and 0.0 < phi_a < SECTOR

    def candidates(self) -> np.ndarray:
        """(n, 2) array of the coarse pass's (phi_a, phi_d) [rad] with phi_a < phi_d and
        phi_a within [phi_a_min, phi_a_max]."""
        return _pairs([a for a in self.phi_a if self._allowed(a)], self.phi_d)

    def refinement(self, phi_a: float) -> np.ndarray:
        """(m, 2) array of the fine pass around a coarse winner ``phi_a`` [rad], without the
        pairs the coarse pass has already predicted (the winner at a coarse phi_d)."""
        pairs = _pairs([phi_a + o for o in self.refine_phi_a if self._allowed(phi_a + o)],
                       self.refine_phi_d)
        seen = (np.abs(pairs[:, 0] - phi_a) < 1e-12) & np.isin(pairs[:, 1], self.phi_d)
        return pairs[~seen]


def _at_least(cands: np.ndarray, floor: float) -> np.ndarray:
    """Rows of ``cands`` (n, 2) whose phi_a [rad] is >= ``floor``; if none is, the row(s) with
    the largest phi_a, the latest switch-on there is (a wheel too fast for any of them)."""
    keep = cands[cands[:, 0] >= floor]
    if len(keep) or not len(cands):
        return keep
    return cands[cands[:, 0] == cands[:, 0].max()]


def _pairs(phi_a, phi_d) -> np.ndarray:
    rows = [(a, d) for d in phi_d for a in phi_a if a < d]
    return np.array(rows, dtype=float).reshape(-1, 2)


class Decision(NamedTuple):
    command: Command
    predicted_speed: float   # mean predicted speed over the candidate's cycle [rad/s] (with d)
    cost: float              # J [(rad/s)^2]
    candidates: int          # candidates predicted [count]
    compute_time: float      # wall time spent deciding [s]
    braking: bool
    deadline_slack: float = math.nan   # time to the current switch-off - margin - compute [s]
    deadline_missed: bool = False      # True: the fallback was sent instead


def cost_59(speed: np.ndarray, q: np.ndarray, reference: float, d: float = 0.0,
            terminal_weight: float = 0.0, time_weighted: bool = False, pads: int = 1) -> float:
    """J for one predicted trajectory that starts with the current actuator on [(rad/s)^2].

    The plain reference of what :func:`predict_cycle_costs` computes inside its loop.
    ``speed`` [rad/s], ``q`` (n,) per tick.  Segments: after the current switch-off (first
    1 -> 0), q = 0 until the candidate's switch-on, then q = 1 until its switch-off; with
    ``pads`` = 2, then the next pad's q = 0 and q = 1 segments too.  (59): the mean of the
    segment means of (speed + d - reference)^2 (1/2 (mean_0 + mean_1) for one cycle); with
    ``time_weighted`` the mean over all the segments' samples instead; plus
    ``terminal_weight`` [1] times the squared error of the last sample before the last
    switch-off (0: none).  Returns +inf if the horizon does not contain every cycle
    (``test_mpc.py::test_cost_59_by_hand``, ``test_cost_over_two_cycles_by_hand``).
    """
    qi = q.astype(np.int8)
    edges = np.flatnonzero(np.diff(qi)) + 1         # indices where q changes
    offs = [i for i in edges if qi[i] == 0]
    if not offs:
        return math.inf
    bounds = [offs[0]]                  # a, b, c, ...: the starts of the segments, then the end
    for _ in range(2 * pads):
        nxt = [i for i in edges if i > bounds[-1]]
        if not nxt:
            return math.inf
        bounds.append(nxt[0])
    e = speed + d - reference
    first, end = bounds[0], bounds[-1]
    if time_weighted:
        j = float(np.mean(e[first:end] ** 2))
    else:
        j = float(np.mean([np.mean(e[x:y] ** 2) for x, y in zip(bounds[:-1], bounds[1:])]))
    return j + terminal_weight * float(e[end - 1]) ** 2


@jit
def predict_cycle_costs(s0: np.ndarray, pv: np.ndarray, cands: np.ndarray, h: float,
                        max_ticks: int, reference: float, d: float, terminal_weight: float,
                        time_weighted: bool, costs: np.ndarray, means: np.ndarray,
                        pads: int) -> int:
    """Predict every candidate over the next ``pads`` cycles and cost it, sharing the prefix.

    ``s0`` (S_SIZE,) is the wheel with the current actuator on; ``cands`` (n, 2) hold
    (phi_a, phi_d) [rad] for the next pad (and, with ``pads`` = 2, for the pad after it,
    queued when the candidate switches on).  Every candidate's trajectory is identical until
    the current actuator switches off, so that prefix is simulated once; each candidate then
    runs from the start of that tick until its last switch-off and stops.  The samples and
    the cost are those of :func:`cost_59` on the full-horizon simulation (same ticks;
    ``test_mpc.py::test_shared_prefix_predictor_equals_the_full_horizon_simulation`` and
    ``test_two_cycle_predictor_equals_a_step_by_step_simulation``), with ``time_weighted``
    replacing the mean of the segment means by the mean over all samples.  Writes ``costs``
    (n,) [(rad/s)^2] (inf when the cycles do not finish within ``max_ticks``) and ``means``
    (n,), the model's mean speed over the first cycle [rad/s] (d not added).  Returns the
    prefix length in ticks (the time left before the current switch-off, in units of h), or
    -1 if it does not switch off in time.
    """
    ev = np.zeros((L.EV_MAX_PER_TICK, 4))
    s = s0.copy()
    pre = s0.copy()
    k = 0
    while k < max_ticks:
        pre[:] = s
        advance(s, pv, h, ev)
        k += 1
        if s[L.S_Q] == 0.0:
            break
    if s[L.S_Q] != 0.0:
        costs[:] = math.inf
        means[:] = math.nan
        return -1
    left = max_ticks - k + 1
    w = np.empty_like(pre)
    sums = np.empty(2 * pads)           # per segment: sum of squared errors, sample count
    counts = np.empty(2 * pads)
    for i in range(cands.shape[0]):
        w[:] = pre
        w[L.S_PEND_PHI_A] = cands[i, 0]
        w[L.S_PEND_PHI_D] = cands[i, 1]
        sums[:] = 0.0
        counts[:] = 0.0
        cycle = 0
        seg = 0
        vsum = 0.0
        n_first = 0
        last = 0.0
        done = False
        for _ in range(left):
            advance(w, pv, h, ev)
            q = w[L.S_Q]
            if seg == 0 and q != 0.0:
                seg = 1
                if cycle + 1 < pads:    # the pad after repeats the candidate's angles
                    w[L.S_PEND] = 1.0
                    w[L.S_PEND_NA] = (w[L.S_ETA] + 1.0) % 16.0
                    w[L.S_PEND_PHI_A] = cands[i, 0]
                    w[L.S_PEND_PHI_D] = cands[i, 1]
            elif seg == 1 and q == 0.0:
                cycle += 1
                if cycle == pads:
                    done = True
                    break
                seg = 0
            e = w[L.S_XI2] + d - reference
            sums[2 * cycle + seg] += e * e
            counts[2 * cycle + seg] += 1.0
            if cycle == 0:
                vsum += w[L.S_XI2]
                n_first += 1
            last = e
        if not done:
            costs[i] = math.inf
            means[i] = math.nan
            continue
        if time_weighted:
            j = sums.sum() / counts.sum()
        else:           # the mean of the segment means (a segment may be empty: skipped)
            j = 0.0
            m = 0
            for g in range(2 * pads):
                if counts[g] > 0.0:
                    j += sums[g] / counts[g]
                    m += 1
            j /= m
        costs[i] = j + terminal_weight * last * last
        means[i] = vsum / n_first
    return k


#: Rotation [ticks of 1/300 s at the current speed] between the current pad's switch-off angle
#: and the next target's switch-on angle: the firmware switches off on the first tick past
#: phi_d and latches the next target then, so a target less than a tick ahead may already
#: be behind the wheel, and would only come round again a turn later (the wheel coasts for
#: 16 pads).  Driving and braking targets alike
#: (``test_mpc.py::test_a_driving_target_is_never_chosen_behind_the_latch``).
LATCH_TICKS = 2.0


def earliest_phi_a(pad: int, xi2: float, latch: float) -> float:
    """Most negative (braking) or smallest (driving) phi_a [rad] at which the unwrapped
    ``pad`` can still switch on: its contact angle where the command latches, at the
    unwrapped wheel angle ``latch`` [rad], plus LATCH_TICKS ticks of rotation at xi2
    [rad/s].  A command latches where the current pad switches off, or on arrival if no pad
    is on."""
    return latch - pad * SECTOR + LATCH_TICKS * TICK * max(xi2, 0.0)


def braking_command(latch: float, xi2: float, phi_a: float, phi_d: float) -> tuple[int, float]:
    """(unwrapped pad, phi_a [rad]) of the braking input for a command that latches at the
    wheel angle ``latch`` [rad], with the configured ``phi_a`` < ``phi_d`` < 0 [rad].

    The pad is the first one that can still brake for at least half its window: from the
    one after the sector of ``latch`` on, the first that can switch on no later than the
    middle of [phi_a, phi_d] (so the phi_a returned is always below phi_d).  After a driving
    pad that switches off at 22 deg that is eta + 2, as in Sec. III-D, at -22 deg (2.6
    rad/s: 2 ticks after -23 deg); after a braking pad (off at -6 deg) the next pad, at phi_a
    (``test_mpc.py::test_braking_command_is_valid_and_still_ahead_at_any_latch_angle``).
    """
    limit = 0.5 * (phi_a + phi_d)
    pad = math.floor(latch / SECTOR) + 1
    while earliest_phi_a(pad, xi2, latch) > limit:    # each pad is a sector further
        pad += 1
    return pad, max(phi_a, earliest_phi_a(pad, xi2, latch))


def next_pad(xi1: float, xi2: float, phi_a: float, lead: float) -> int:
    """The first actuator (0..15) whose switch-on angle ``phi_a`` [rad] is still ahead of the
    wheel when a command sent now arrives: xi1 [rad] advanced by xi2 [rad/s] x ``lead`` [s].

    For a driving decision on an idle wheel (no pad on, so the command latches on arrival):
    the pad after the sector floor(xi1 / (pi/8)) would skip a pad that is less than phi_a
    past the sector boundary, and a slow wheel could then coast to a stop
    (``test_mpc.py::test_next_pad_is_the_first_whose_switch_on_is_still_ahead``).
    """
    ahead = xi1 + max(xi2, 0.0) * lead
    return (int(math.floor((ahead - phi_a) / SECTOR)) + 1) % 16


def gc_paused(fn):
    """Run ``fn`` with Python's cyclic garbage collector paused (it resumes on return).

    A full collection in a process that holds a long recording can outlast a decision's
    deadline; the pause moves it to just after the call, so no collection starts inside a
    decision (``test_mpc.py::test_no_garbage_collection_runs_inside_a_decision``).
    """
    @functools.wraps(fn)
    def paused(*args, **kwargs):
        if not gc.isenabled():
            return fn(*args, **kwargs)
        gc.disable()
        try:
            return fn(*args, **kwargs)
        finally:
            gc.enable()
    return paused


class Mpc:
    """``decide(xi1, xi2, eta_unwrapped, phi_a_now, phi_d_now, reference, d, disturbance)``.

    ``clock`` returns seconds (wall time by default; tests pass a fake one).
    """

    def __init__(self, params: WheelParams | None = None, extensions: Extensions | None = None,
                 config: MpcConfig | None = None, clock=time.perf_counter) -> None:
        self.config = config or MpcConfig()
        self.pv = reading_param_vector(params or WheelParams(), extensions)
        self._base = initial_state(mode="tick")
        self.clock = clock
        self.seq = 0
        self.decisions = 0
        self.deadline_misses = 0
        #: Pads (0..15) the MPC does not drive: it targets the next pad after them instead.
        self.skip: set[int] = set()
        allowed = self.cands[:, 0]          # within the actuation limits
        self.last_drive = (float(allowed[len(allowed) // 2]), max(self.config.phi_d))
        # load the compiled predictor now, so the first real decision is not the slow one
        self._costs(initial_state(mode="tick"), self.pv, self.cands[:1], 2, 1.0, 0.0)

    @property
    def config(self) -> MpcConfig:
        """The configuration in use; setting it (e.g. a run-time parameter change) also
        recomputes the coarse candidates."""
        return self._config

    @config.setter
    def config(self, config: MpcConfig) -> None:
        self._config = config
        self.cands = config.candidates()

    @gc_paused
    def decide(self, xi1: float, xi2: float, eta_unwrapped: int, phi_a_now: float,
               phi_d_now: float, reference: float, d: float = 0.0,
               disturbance: tuple = (0.0, 0.0, 0.0), pad_on: bool = True) -> Decision:
        """Choose u for the pad after ``eta_unwrapped`` (the actuator that just switched on).

        xi1 [rad] unwrapped, xi2 [rad/s], (phi_a_now, phi_d_now) [rad] of the current pad,
        reference [rad/s]; ``d`` [rad/s] is added to the predicted speed; ``disturbance``
        (c, a, b) or (c, a, b, e, f) [rad/s^2], the observer's a_d (observer.py), is added to
        the model's acceleration over the whole prediction.  Its pivot harmonic e, f enters as
        a constant, its value in the middle of the cycles the cost judges (the pivot angle moves
        by r/L pi/8 = 0.1 rad in a cycle, so the error is second order), which spares the
        prediction two trigonometric calls per step.  ``pad_on`` False: no pad is on (an idle
        wheel), so a braking command latches on arrival, not at a switch-off.
        """
        t0 = self.clock()
        self.seq += 1
        self.decisions += 1
        if xi2 + d >= reference + self.config.brake_threshold:
            # latches at the current pad's switch-off, or on arrival if none is on
            off = eta_unwrapped * SECTOR + phi_d_now if pad_on else self._arrival(xi1, xi2)
            return self._brake(t0, xi1, xi2, off, d, off)
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
        target = self.target_pad(eta_unwrapped)
        s[L.S_PEND] = 1.0
        s[L.S_PEND_NA] = float(target % 16)
        if len(disturbance) == 5:
            middle = (eta_unwrapped + 0.5 * self.config.horizon_pads) * SECTOR + phi_d_now
            disturbance = fold_pivot(disturbance, middle, self.pv[L.P_PIVOT_RATIO])
        pv = set_disturbance(self.pv.copy(), self.pv, disturbance)
        # long enough for the rest of this pad and the whole next one(s) at the current speed:
        # 2.5 sectors for one, more after a braking pad's switch-on (at -22 deg, a sector
        # earlier)
        pads = self.config.horizon_pads
        ahead = target - eta_unwrapped              # 1, or more past skipped pads
        to_go = max((pads + ahead + 0.5) * SECTOR, 1.25 * ((target + pads) * SECTOR - xi1))
        horizon = min(self.config.max_horizon, to_go / max(xi2, 0.3))
        n_ticks = max(int(horizon / TICK), 10)
        cfg = self.config
        # a target that latches behind the wheel would wait a whole turn: keep the candidates
        # that can still switch on after the current pad switches off at phi_d_now (on an idle
        # wheel the command latches on arrival, and its pad is chosen to suit: next_pad)
        floor = (earliest_phi_a(target, xi2, eta_unwrapped * SECTOR + phi_d_now)
                 if pad_on else -math.inf)
        cands = _at_least(self.cands, floor)
        costs, means, prefix = self._costs(s, pv, cands, n_ticks, reference, d)
        n = len(cands)
        if np.isfinite(costs).any():
            fine = _at_least(cfg.refinement(cands[int(np.argmin(costs)), 0]), floor)
            if len(fine):
                c2, m2, _ = self._costs(s, pv, fine, n_ticks, reference, d)
                cands = np.vstack([cands, fine])
                costs = np.concatenate([costs, c2])
                means = np.concatenate([means, m2])
                n += len(fine)
            best = int(np.argmin(costs))
        else:   # no candidate completes its cycle within the horizon: push as hard as we can
            best = int(np.lexsort((cands[:, 0], -cands[:, 1]))[0])
        pa, pd = (float(x) for x in cands[best])
        dt = self.clock() - t0
        left = prefix * TICK if prefix > 0 else horizon    # no switch-off in sight
        slack = left - cfg.deadline_margin - dt
        missed = slack < 0.0
        if missed:      # too late to matter: keep the wheel rolling as it was
            self.deadline_misses += 1
            pa, pd = self.last_drive
            # a faster wheel than then: not behind the latch, and still within the limits
            pa = min(max(pa, floor), cfg.phi_a_max)
        else:
            self.last_drive = (pa, pd)
        cmd = Command(target % 16, pa, pd, self.seq)
        return Decision(cmd, float(means[best]) + d, float(costs[best]), n, dt, False, slack,
                        missed)

    def target_pad(self, eta_unwrapped: int) -> int:
        """The unwrapped pad the next driving command targets: the next one after
        ``eta_unwrapped`` that is not in :attr:`skip` (``test_mpc.py::
        test_a_skipped_pad_is_not_driven``)."""
        target = eta_unwrapped + 1
        while target % 16 in self.skip and target < eta_unwrapped + 16:
            target += 1
        return target

    @gc_paused
    def brake_now(self, xi1: float, xi2: float, d: float, act_counter: float) -> Decision:
        """A braking decision while no actuator is on (a new reference between two pads): it
        replaces the pending target, which switches on ``act_counter`` [rad] from now.
        xi1 [rad] unwrapped, xi2 and the speed offset d [rad/s]."""
        t0 = self.clock()
        self.seq += 1
        self.decisions += 1
        return self._brake(t0, xi1, xi2, self._arrival(xi1, xi2), d, xi1 + act_counter)

    def _arrival(self, xi1: float, xi2: float) -> float:
        """Wheel angle [rad] when a command sent now arrives: the sample's age (a tick at
        most) and the command's way (deadline_margin) at xi2 [rad/s]."""
        return xi1 + max(xi2, 0.0) * (TICK + self.config.deadline_margin)

    def _brake(self, t0: float, xi1: float, xi2: float, latch: float, d: float,
               due: float) -> Decision:
        """The braking input (Sec. III-D) for a command that latches at ``latch`` [rad]
        (:func:`braking_command`); it must be there before the wheel reaches ``due`` [rad]."""
        pd = self.config.brake_phi_d
        pad, pa = braking_command(latch, xi2, self.config.brake_phi_a, pd)
        left = (due - xi1) / max(xi2, 1e-3)
        dt = self.clock() - t0
        return Decision(Command(pad % 16, pa, pd, self.seq), xi2 + d, math.nan, 0, dt, True,
                        left - self.config.deadline_margin - dt, False)

    def _costs(self, s, pv, cands, n_ticks, reference, d):
        costs = np.empty(len(cands))
        means = np.empty(len(cands))
        prefix = predict_cycle_costs(s, pv, cands, TICK, n_ticks, reference, d,
                                     self.config.terminal_weight, self.config.time_weighted,
                                     costs, means, self.config.horizon_pads)
        return costs, means, prefix
