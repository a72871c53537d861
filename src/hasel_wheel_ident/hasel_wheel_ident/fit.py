"""Fitting the hybrid model to trials: friction from coast-downs, then the force law (and any
candidate effects) by multiple-shooting least squares, with uncertainty.

Parameterisation.  F_a depends on sigma6 / (sigma2 |xi2| + sigma3), so only two ratios of
(sigma2, sigma3, sigma6) are determined by data (docs/model.md).  There is a
second degeneracy: with u = ln(contact angle), the bump's exponent
-sigma1 u - (u - sigma4)^2 / sigma5^2 plus ln(sigma6) is a quadratic in u, which has three
coefficients, while (sigma1, sigma4, sigma5, sigma6) are four.  So sigma1 cannot be told from a
shift of sigma4 with a rescaling of sigma6.  The fit therefore uses the coordinates that the
data does determine (:func:`force_coordinates`):

    peak, centre, width (= |sigma5|), b = sigma2 / sigma3, tau_f
    (+ brake_gain when the data holds braking activations, + each candidate's parameters)

and maps back with sigma1 and sigma3 held at their reference values.
:func:`~.identifiability.identifiability` shows, from the data's own Jacobian in the paper's
parameters, which directions are determined and which are not.

Objective.  Each trial is cut into windows of ``window`` seconds; each window starts from its
own (xi1, xi2), fitted along with the parameters (multiple shooting).  The residual is the
simulated angle as the model's sensor reads it (:func:`~hasel_wheel_sim.model.angle_readings`;
the angle itself unless an eccentricity is fitted) minus the recorded angle [rad] at every
sample, with the measured switching (:func:`~.simulate.shoot_windows`).  The window starts
are solved for inside every evaluation (variable projection: safeguarded Gauss-Newton on
each window, in compiled code, :func:`~.simulate.solve_window_starts`), so scipy's
trust-region least squares sees only the shared parameters, with the window starts
projected out of its Jacobian (Kaufman).  It runs to convergence
(:data:`~.least_squares.FTOL`), not to an iteration limit.  The same projected Jacobian
gives the covariance with the starts marginalised (:mod:`.uncertainty`).

:class:`Problem` holds the shooting; the trials' layout (:mod:`.shooting_layout`), the
parameter map (:mod:`.param_map`), the force gains (:mod:`.force_gains`) and the
least-squares run (:mod:`.least_squares`) are their own modules.  Tested in
``test_ident_fit.py`` and ``test_ident_window_starts.py``.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy import stats

from hasel_wheel_sim import layout as L
from hasel_wheel_sim.model import N_ACTUATORS, angle_readings, param_vector
from hasel_wheel_sim.params import WheelParams

from hasel_wheel_ident.candidates import Candidate, ParamSpec
from hasel_wheel_ident.data import REST_BAND, Trial, clean_mask, rest_start
from hasel_wheel_ident.fit_result import FitResult
from hasel_wheel_ident.force_gains import ForceGains
from hasel_wheel_ident.least_squares import solve
from hasel_wheel_ident.param_map import ParameterMap
from hasel_wheel_ident.shooting_layout import initial_starts, lay_out
from hasel_wheel_ident.simulate import (project_out_starts, shoot_errors, shoot_quotients,
                                        shoot_windows, solve_window_starts)
from hasel_wheel_ident.threads import run_split, with_one_blas_thread
from hasel_wheel_ident.uncertainty import noise


def force_coordinates(p: WheelParams) -> dict[str, float]:
    """The force law's identifiable coordinates (see the module docstring).

    peak = sigma6/sigma3 * exp((centre^2 - sigma4^2) / sigma5^2)   force scale at the bump's top
    centre = sigma4 - sigma1 sigma5^2 / 2                           ln(contact angle [rad]) there
    width = |sigma5|, b = sigma2 / sigma3 [s/rad]
    """
    s2 = p.sigma5 ** 2
    c = p.sigma4 - p.sigma1 * s2 / 2.0
    return {"peak": p.sigma6 / p.sigma3 * math.exp((c * c - p.sigma4 ** 2) / s2), "centre": c,
            "width": abs(p.sigma5), "b": p.sigma2 / p.sigma3}


def from_force_coordinates(base: WheelParams, peak: float, centre: float, width: float,
                           b: float, **other: float) -> WheelParams:
    """WheelParams with the force law given by its coordinates; sigma1 and sigma3 stay at
    ``base`` (the data cannot move them independently)."""
    s2 = width * width
    sigma4 = centre + base.sigma1 * s2 / 2.0
    k = peak * math.exp((sigma4 ** 2 - centre ** 2) / s2)
    return base.with_values(sigma2=b * base.sigma3, sigma4=sigma4,
                            sigma5=math.copysign(width, base.sigma5), sigma6=k * base.sigma3,
                            **other)


def nominal_specs(base: WheelParams, brake: bool) -> tuple[ParamSpec, ...]:
    """The nominal model's fitted parameters (see the module docstring)."""
    c = force_coordinates(base)
    out = (
        ParamSpec("peak", "1", c["peak"], 1e-3, 1e4, 0.1 * c["peak"]),
        ParamSpec("centre", "1", c["centre"], -3.0, 0.0, 0.01),
        ParamSpec("width", "1", c["width"], 0.01, 2.0, 0.01),
        ParamSpec("b", "s/rad", c["b"], 0.0, 10.0, 0.1),
        ParamSpec("tau_f", "N*m", base.tau_f, 1e-5, 1.0, 1e-3),
    )
    if brake:
        out += (ParamSpec("brake_gain", "1", base.brake_gain, 0.01, 100.0, 0.1),)
    return out


# -- friction from coast-downs ----------------------------------------------------------------
@dataclass
class FrictionEstimate:
    """tau_f [N*m] with its 95 % interval, from ``segments`` coast-downs."""

    tau_f: float
    ci95: tuple[float, float]
    segments: int
    per_segment: list[float]


def coast_estimates(tr: Trial, base: WheelParams) -> list[tuple[int, int, float, float]]:
    """(a, b, tau_f [N*m], its variance [(N*m)^2]) of each coast-down [a, b) of ``tr``:
    angle = a + b t - alpha t^2 / 2 fitted by least squares; Coulomb friction alone
    decelerates at alpha = (r + L)/L tau_f / (J/L) (eq. (38)), so
    tau_f = alpha (J/L) L / (r + L)."""
    out = []
    factor = base.inertia * base.L / (base.r + base.L)
    for a, b in tr.coasts:
        t = tr.t[a:b] - tr.t[a]
        y = tr.angle[a:b]
        ok = clean_mask(t, y)
        X = np.column_stack([np.ones(ok.sum()), t[ok], -0.5 * t[ok] ** 2])
        coef, res, *_ = np.linalg.lstsq(X, y[ok], rcond=None)
        dof = max(ok.sum() - 3, 1)
        s2 = float(res[0]) / dof if res.size else 0.0
        cov = s2 * np.linalg.inv(X.T @ X)
        out.append((int(a), int(b), float(coef[2] * factor), float(cov[2, 2] * factor ** 2)))
    return out


def coastdown_friction(trials: list[Trial], base: WheelParams) -> FrictionEstimate | None:
    """tau_f from every coast-down (:func:`coast_estimates`), pooled.

    Segments are weighted by their information (t^4 n); the interval combines the
    regression's own error with the scatter between segments.  None when the trials hold no
    coast-down.
    """
    est, var = [], []
    for tr in trials:
        for _a, _b, e, v in coast_estimates(tr, base):
            est.append(e)
            var.append(v)
    if not est:
        return None
    e, v = np.asarray(est), np.maximum(np.asarray(var), 1e-30)
    w = 1.0 / v
    mean = float(np.sum(w * e) / np.sum(w))
    se = math.sqrt(1.0 / np.sum(w))
    if e.size > 1:   # scatter between segments beyond what the regressions expect
        chi2 = float(np.sum(w * (e - mean) ** 2)) / (e.size - 1)
        se *= math.sqrt(max(chi2, 1.0))
        q = stats.t.ppf(0.975, e.size - 1)
    else:
        q = 1.96
    return FrictionEstimate(mean, (mean - q * se, mean + q * se), int(e.size), [float(x) for x in e])


# -- the multiple-shooting problem ---------------------------------------------------------------
class Problem:
    """Multiple-shooting least squares over a set of trials (see the module docstring).

    ``candidates`` extend the nominal model; ``fixed`` pins shared parameters by name
    (e.g. tau_f from the coast-downs).  ``keep`` (t0, t1) [s], in each trial's own clock,
    counts only the samples with t0 <= t < t1 in the residual: the rest are still simulated,
    so that states such as the retained charge run on from the trial's start, but carry no
    weight (a window without a counted sample has undetermined starts, which stay put).
    Arrays of all trials are concatenated (:mod:`.shooting_layout`); windows never cross a
    trial boundary.  ``threads`` > 1 splits every simulation's windows over that many
    threads (the same numbers bit for bit).  An instance is not thread-safe: its simulations
    share output arrays, so give each thread its own.
    """

    def __init__(self, trials: list[Trial], base: WheelParams | None = None,
                 candidates: tuple[Candidate, ...] = (), window: float = 1.0,
                 fixed: dict[str, float] | None = None, quantised: bool = True,
                 threads: int = 1, keep: tuple[float, float] | None = None) -> None:
        if not trials:
            raise ValueError("identification needs at least one trial")
        self.trials = [at_rest_trimmed(t) for t in trials]
        self.base = base or WheelParams()
        self.candidates = tuple(candidates)
        brake = any(a.phi_a < 0 for tr in trials for a in tr.activations)
        specs = nominal_specs(self.base, brake) + tuple(p for c in candidates for p in c.params)
        self.params = ParameterMap(specs, len(nominal_specs(self.base, brake)), fixed)
        self.specs, self.n_nominal = self.params.specs, self.params.n_nominal
        self.fixed, self.free = self.params.fixed, self.params.free
        self.window = window
        self.quantised = quantised
        self.threads = max(int(threads), 1)
        self.keep = keep
        lay = self.layout = lay_out(self.trials, window, keep)
        self.t, self.y, self.q, self.eta, self.phi_a = lay.t, lay.y, lay.q, lay.eta, lay.phi_a
        self.on_time, self.ok, self.pad, self.n = lay.on_time, lay.ok, lay.pad, lay.n
        self.starts, self.window_trial = lay.starts, lay.window_trial
        self.trial_slices, self.trial_windows = lay.trial_slices, lay.trial_windows
        self.quantum = encoder_quantum(self.y) if self.quantised else None
        self._out1 = np.zeros(self.n)
        self._out2 = np.zeros(self.n)
        self._every = np.arange(self.n_windows)
        self._gains = ForceGains(self.layout, self.trials)
        scale = np.array([tr.friction_scale for tr in self.trials])
        self.friction_scale = None if np.all(scale == 1.0) else scale

    @property
    def n_windows(self) -> int:
        return self.starts.shape[0] - 1

    @property
    def names(self) -> list[str]:
        return self.params.names

    # -- parameters -> model ------------------------------------------------------------------
    def at_bounds(self, fit: FitResult, rel: float = 1e-6) -> list[str]:
        """The nominal parameters of ``fit`` (a fit of this problem) that ended on a bound of
        their range (within ``rel`` of the range's width)."""
        return self.params.at_bounds(fit.values, rel)

    def full_theta(self, theta_free: np.ndarray) -> np.ndarray:
        """All shared parameters, the free ones ``theta_free``
        (:meth:`~.param_map.ParameterMap.full_theta`)."""
        return self.params.full_theta(theta_free)

    def wheel_params(self, full: np.ndarray) -> WheelParams:
        other = {"tau_f": full[4]}
        if self.n_nominal > 5:
            other["brake_gain"] = full[5]
        return from_force_coordinates(self.base, full[0], full[1], full[2], full[3], **other)

    def model(self, full: np.ndarray) -> tuple[np.ndarray, dict]:
        """(parameter vector, extra) of the model with all shared parameters ``full``."""
        pv = param_vector(self.wheel_params(full))
        extra: dict = {}
        i = self.n_nominal
        for c in self.candidates:
            c.apply(full[i:i + c.size], pv, extra)
            i += c.size
        return pv, extra

    def gains(self, pv: np.ndarray) -> np.ndarray:
        """Force multiplier of the active actuator at every sample (spread x retention), (n,),
        read-only (:class:`~.force_gains.ForceGains`)."""
        return self._gains(pv)

    # -- simulation and residual ----------------------------------------------------------------
    def simulate(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Simulated (xi1, xi2) at every sample for the packed vector z."""
        g = len(self.free)
        pv, extra = self.model(self.full_theta(z[:g]))
        x0 = z[g:].reshape(-1, 2)
        eta = self.eta + extra.get("eta_offset", 0.0)
        self._shoot_windows(eta, self.gains(pv), self._every, x0, pv, self._out1, self._out2)
        return self._out1, self._out2

    def residual(self, z: np.ndarray) -> np.ndarray:
        """(n,) the output error [rad] (:meth:`_shoot`) for the packed vector z."""
        g = len(self.free)
        pv, extra = self.model(self.full_theta(z[:g]))
        return self._shoot(pv, self.eta + extra.get("eta_offset", 0.0), self.gains(pv),
                           z[g:].reshape(-1, 2))

    def readings(self, z: np.ndarray, x1: np.ndarray) -> np.ndarray:
        """(n,) the angle sensor's readings [rad] of the wheel angles x1 (n,) [rad] under the
        model of the packed vector z (x1 itself unless an eccentricity is fitted)."""
        return angle_readings(x1, self.model(self.full_theta(z[:len(self.free)]))[0])

    def noise(self, r: np.ndarray, g: int) -> tuple[float, float]:
        """(s^2 [rad^2], inflation) of the residual r (n,) of a fit with g shared parameters
        (:func:`~.uncertainty.noise`)."""
        return noise(r, g, self.ok, self.starts, self.quantum is not None)

    def initial_starts(self) -> np.ndarray:
        """(w, 2) window starts from a line through the first 0.1 s of each window
        (:func:`~.shooting_layout.initial_starts`)."""
        return initial_starts(self.layout)

    def _shoot(self, pv: np.ndarray, eta: np.ndarray, gains: np.ndarray,
               x0: np.ndarray) -> np.ndarray:
        """(n,) the output error [rad] of every window shot from the starts x0 (w, 2): simulated
        minus measured angle, 0 at rejected samples (:func:`~.simulate.sample_error`); the
        wheel's (xi1, xi2) are left in ``self._out1``, ``self._out2``.

        The simulated wheel angles are first turned into what the sensor of the model ``pv``
        reads (:func:`~hasel_wheel_sim.model.angle_reading`).  When the angles are encoder
        counts (``self.quantum`` [rad], found in the data), a reading y says only that the
        angle lies in [y, y + quantum): the error is the distance from that interval (0
        inside).  Taking y itself as the angle would add the encoder's sawtooth, which at
        300 Hz aliases into slow errors that correlate with speed and bias the force law (by
        ~5 % in its peak)."""
        err = np.empty(self.n)
        self._split_by_trial(lambda part, p: shoot_errors(
            *self._inputs(eta, gains), part, x0, p, self.y, self._quantum_or_nan, self.ok,
            self._out1, self._out2, err), self._every, pv)
        return err

    @property
    def _quantum_or_nan(self) -> float:
        return math.nan if self.quantum is None else float(self.quantum)

    def _inputs(self, eta: np.ndarray, gains: np.ndarray) -> tuple[np.ndarray, ...]:
        """The compiled simulators' leading arguments: the data, sectors ``eta`` and
        ``gains`` (each (n,)), and the window starts."""
        return self.t, self.q, eta, self.phi_a, self.on_time, gains, self.starts

    def _split(self, fn: Callable[[np.ndarray], None], windows: np.ndarray) -> None:
        """``fn(part)`` for the listed windows, split over ``self.threads`` threads (windows
        are independent and write disjoint samples, and the compiled simulators release the
        GIL, so the result is the same bit for bit)."""
        if self.threads == 1 or windows.size < 2 * self.threads:
            fn(windows)
        else:
            run_split(fn, [windows[i::self.threads] for i in range(self.threads)])

    def _split_by_trial(self, fn: Callable[[np.ndarray, np.ndarray], None], windows: np.ndarray,
                        pv: np.ndarray) -> None:
        """``fn(part, pv)`` as :meth:`_split`; where the trials' friction differs
        (``Trial.friction_scale``), each trial's windows apart with its own tau_f in pv."""
        if self.friction_scale is None:
            self._split(lambda part: fn(part, pv), windows)
            return
        of = self.window_trial[windows]
        for j, scale in enumerate(self.friction_scale):
            mine = windows[of == j]
            if mine.size:
                pj = pv.copy()
                pj[L.P_FRICTION] *= scale
                self._split(lambda part, pj=pj: fn(part, pj), mine)

    def _shoot_windows(self, eta: np.ndarray, gains: np.ndarray, windows: np.ndarray,
                       x0: np.ndarray, pv: np.ndarray, out1: np.ndarray,
                       out2: np.ndarray) -> None:
        """:func:`~.simulate.shoot_windows` of ``windows`` on this problem's data, split over
        ``self.threads`` threads (:meth:`_split_by_trial`)."""
        self._split_by_trial(lambda part, p: shoot_windows(*self._inputs(eta, gains), part, x0,
                                                           p, out1, out2), windows, pv)

    def solve_starts(self, full: np.ndarray, x0: np.ndarray, iterations: int = 12
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Best window starts for the shared parameters ``full`` (Gauss-Newton, each window on
        its own: a window's residuals depend on its own start only).

        Returns (x0 (w, 2), residual (n,), d residual / d xi1_0 (n,), d residual / d xi2_0 (n,)).
        """
        pv, extra = self.model(full)
        return self.starts_for(pv, self.eta + extra.get("eta_offset", 0.0), self.gains(pv), x0,
                               iterations)

    def starts_for(self, pv: np.ndarray, eta: np.ndarray, gains: np.ndarray, x0: np.ndarray,
                   iterations: int = 20):
        """:meth:`solve_starts` for a given parameter vector, sectors and gains.

        Gauss-Newton per window, safeguarded: a window takes its step only if its own squared
        error does not grow, else it tries a quarter of the step next time (and doubles it
        again after a success).  A window leaves the iteration once its step is far below the
        encoder's resolution (1e-7 rad, 1e-6 rad/s) or has shrunk to 1/256.  Windows that have
        left are not simulated again, so a warm start costs a few simulations of the windows
        that still move, not ``iterations`` of the whole data set.

        Each window iterates alone in compiled code (:func:`~.simulate.solve_window_starts`),
        the windows split over the threads.  Its sums follow numpy's order, so the starts and
        residuals are the bits the same rule gave written with numpy arrays over all windows
        at once (tested); the Python work between the simulations, which had left the second
        core idle for about half of a fit, is gone.
        """
        x0 = np.array(x0, dtype=float, order="C")   # a copy, solved in place
        r, d1, d2 = np.empty(self.n), np.empty(self.n), np.empty(self.n)
        scratch = np.empty(self.n), np.empty(self.n), np.empty(self.n)
        self._split_by_trial(lambda part, p: solve_window_starts(
            *self._inputs(eta, gains), part, x0, p, self.y, self._quantum_or_nan, self.ok,
            iterations, r, d1, d2, *scratch), self._every, pv)
        return x0, r, d1, d2

    def _project(self, J: np.ndarray, d1: np.ndarray, d2: np.ndarray) -> np.ndarray:
        """Remove from each column of J (n, g) the part that the window starts can explain
        (:func:`~.simulate.project_out_starts`, over the threads)."""
        out = np.empty_like(J)
        self._split(lambda part: project_out_starts(J, d1, d2, self.starts, part, out),
                    self._every)
        return out

    def stepped(self, theta: np.ndarray, j: int) -> tuple[np.ndarray, float]:
        """(theta with its j-th free parameter stepped by h, h): the Jacobian's forward
        difference, 1e-6 of the value or of its typical scale, backwards at the upper bound."""
        p = self.specs[self.free[j]]
        h = 1e-6 * max(abs(theta[j]), p.scale)
        if theta[j] + h > p.upper:
            h = -h
        tp = theta.copy()
        tp[j] += h
        return tp, h

    def jacobian(self, theta: np.ndarray, x0: np.ndarray, r: np.ndarray, d1: np.ndarray,
                 d2: np.ndarray) -> np.ndarray:
        """(n, g) derivative of the residual [rad] with respect to the free parameters at
        ``theta`` (g,), with the window starts x0 (w, 2) projected out (finite differences
        with the starts held; ``r``, ``d1``, ``d2`` as returned by :meth:`solve_starts`)."""
        J = np.empty((self.n, theta.size))
        for j in range(theta.size):
            tp, h = self.stepped(theta, j)
            pv, extra = self.model(self.full_theta(tp))
            inputs = self._inputs(self.eta + extra.get("eta_offset", 0.0), self.gains(pv))
            col = J[:, j]
            self._split_by_trial(lambda part, p: shoot_quotients(
                *inputs, part, x0, p, self.y, self._quantum_or_nan, self.ok, r, h,
                self._out1, self._out2, col), self._every, pv)
        return self._project(J, d1, d2)

    # -- fitting ------------------------------------------------------------------------------
    @with_one_blas_thread
    def fit(self, start: dict[str, float] | None = None, x0: np.ndarray | None = None,
            max_nfev: int = 100) -> FitResult:
        """Least squares to convergence (:func:`~.least_squares.solve`).  ``start``
        overrides start values by name, ``x0`` gives window starts (w, 2)."""
        return solve(self, start, x0, max_nfev)

    def window_starts(self, z: np.ndarray) -> np.ndarray:
        return z[len(self.free):].reshape(-1, 2)


def encoder_quantum(y: np.ndarray) -> float | None:
    """The encoder's count [rad] if every step of the angles y (n,) is a whole number of one
    count of 2 pi / N (N = 2^8 .. 2^16), else None (motion capture, filtered angles)."""
    d = np.abs(np.diff(y))
    d = d[d > 1e-9]
    if d.size < 10:
        return None
    for bits in range(8, 17):
        c = 2 * math.pi / 2 ** bits
        k = d / c
        if k.min() > 0.5 and np.max(np.abs(k - np.round(k))) < 1e-6:
            return c
    return None


def at_rest_trimmed(tr: Trial, band: float = REST_BAND) -> Trial:
    """The trial without its tail at rest: from where the angle stays within ``band`` [rad]
    to the end (:func:`~.data.rest_start`, the rule the coast-downs end by).  A stopped
    wheel tells nothing about the parameters, and the speed it starts a window with is not
    determined.

    A glitched reading in the tail (a random count) is only left out of the band's judgement:
    ending the rest there would keep a tail of rest whose constant residual correlates the
    whole fit's, which :func:`~.residual.analyse` then reports as structure.  Tested in
    ``test_ident_data.py`` (``test_a_glitch_in_the_tail_at_rest_does_not_keep_the_tail``)."""
    rest = rest_start(tr.t, tr.angle, band)
    if rest is None or rest == 0:
        return tr
    last = rest + 1                               # up to the first sample at rest
    if last >= tr.t.shape[0] or last < 30:
        return tr
    return tr.slice(0, last, tr.name)


@dataclass
class RestTail:
    """The rest at the end of a trial: from its first sample at rest, the last one the fits
    keep, to the end of the record; the samples after that first one are left out
    (:func:`at_rest_trimmed`)."""

    from_s: float            # [s] its first sample at rest, after the trial's first sample
    seconds: float           # [s] from there to the end of the record
    scheduled_share: float   # [1] the share of the samples left out with a pad scheduled
    hv_share: float          # [1] the share of the samples left out with a pad on (q = 1)
    pad: int | None          # the pad in contact (eta, 0..15) for the most of those samples
    target: int | None       # the command's target pad (n_a, 0..15) for the most of the
                             # scheduled ones; None when none is scheduled

    @property
    def stalled(self) -> bool:
        """The wheel stopped for good while still driven: a pad scheduled for most of a rest
        of 1 s or more (a wheel at rest after a coast-down has none).  With the pad on it is
        too weak to push the wheel on; with it off, the wheel stopped short of its switching
        angle and waits for it."""
        return self.seconds >= 1.0 and self.scheduled_share > 0.5

    def text(self, trial: str) -> str:
        """The stall in words (see :attr:`stalled`)."""
        how = (f"pad {self.pad} on for {100 * self.hv_share:.0f} % of it" if self.hv_share > 0.5
               else f"pad {self.target} scheduled but off, short of its switching angle (pad "
                    f"{self.pad} in contact)")
        return (f"{trial}: the wheel stopped {self.from_s:.2f} s into the trial, while driven, "
                f"and stayed at rest for {self.seconds:.1f} s to the end, {how}; the fit "
                f"leaves that rest "
                f"out.  A wheel that stalls while driven points to a pad broken or far weaker "
                f"than the others: this one, or the one before it, which left the wheel where "
                f"this one cannot move it.")


def _most(values: np.ndarray) -> int | None:
    """The most frequent of ``values`` (pad indices, taken modulo 16); None when empty."""
    v = (values.astype(np.int64) % N_ACTUATORS)
    return int(np.bincount(v).argmax()) if v.size else None


def rest_tail(tr: Trial) -> RestTail | None:
    """The rest at the end of ``tr`` (see :class:`RestTail`), or None when the fits keep every
    sample (no rest at the end, the whole record at rest, or too little left before it)."""
    n = at_rest_trimmed(tr).t.shape[0]
    if n == tr.t.shape[0]:
        return None
    scheduled = tr.n_a[n:] >= 0
    return RestTail(float(tr.t[n - 1] - tr.t[0]), float(tr.t[-1] - tr.t[n - 1]),
                    float(scheduled.mean()),
                    float(tr.q[n:].astype(bool).mean()), _most(tr.eta_unwrapped[n:]),
                    _most(tr.n_a[n:][scheduled]))


def wald_p(fit: FitResult, effect: Candidate) -> float:
    """p-value of "this effect is absent" from the fit's covariance."""
    names = [p.name for p in effect.params]
    idx = [fit.names.index(nm) for nm in names]
    x = fit.theta[idx]
    null = np.array([_null_value(effect, nm) for nm in names])
    C = fit.cov[np.ix_(idx, idx)]
    try:
        chi2 = float((x - null) @ np.linalg.solve(C, x - null))
    except np.linalg.LinAlgError:
        return 1.0
    return float(stats.chi2.sf(chi2, len(idx)))


def effect_wald_p(fit: FitResult, effect: Candidate) -> float:
    """p-value of "``effect`` is absent" in ``fit`` (:func:`wald_p`; for charge retention
    the one-sided test of its rate, :func:`_retention_p`)."""
    return wald_p(fit, effect) if effect.id != "charge_retention" else _retention_p(fit)


def _retention_p(fit: FitResult) -> float:
    """Retention is absent when its rate is 0 (its recovery is then undetermined)."""
    i = fit.names.index("rate")
    sd = math.sqrt(max(fit.cov[i, i], 1e-300))
    return float(stats.norm.sf(fit.theta[i] / sd))


def _null_value(effect: Candidate, name: str) -> float:
    """The parameter value at which the effect vanishes."""
    if effect.id == "charge_retention":
        return 0.0 if name == "rate" else math.nan
    return 0.0
