"""Is an effect the same in every trial?  Its parameters refitted trial by trial, on the
halves of each drive, and beside the measuring devices.

* **Trial by trial** (:func:`trial_consistency`): each chosen effect is refitted on each trial
  alone with the nominal model (:data:`NOMINAL`), the other effects held.  Its size m_j (the
  parameters projected on their mean direction, in units of their typical magnitude) is
  regressed on ln v_j, v_j the trial's mean speed while driven [rad/s]: size ~ v^k.  It is
  *inconsistent* (refused, code ``SPEED_STAND_IN``) when the slope's two-sided p <
  :data:`TREND_P` and |k| > :data:`EXPONENT`; short of that with p < :data:`LEAN_P` it
  *leans* (a caution).  Trials whose speeds span less than :data:`MIN_SPEED_RATIO` are cut
  into spans (:func:`speed_units`).  Tested in ``test_ident_consistency.py``.
* **Within the trials**: refitted on the halves of each drive, size ~ hv^h with hv the
  accumulated HV time; it *drifts* (:func:`drifts`) when p < :data:`TREND_P` and
  |h| > :data:`DRIFT`.
* **Beside a measuring device** (:data:`HV_LOSS`, :data:`ON_LAG`, never named): a drifting
  effect or a rise lag is refitted beside a force loss that grows with HV time
  (:func:`drift_stand_in`: codes ``DRIFT_STAND_IN``, ``HV_LOSS_LOOKALIKE``); an effect whose
  size grows with speed beside a force that builds up after each switch-on
  (:func:`lag_stand_in`: code ``SWITCH_ON_LAG_STAND_IN``).  It stands in when it no longer
  holds there (:meth:`Beside.holds`).

The evidence behind each threshold is in docs/identification.md.
"""
from __future__ import annotations

import dataclasses
import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from scipy import stats

from hasel_wheel_sim.params import WheelParams

from hasel_wheel_sim import layout as L

from hasel_wheel_ident.candidates import BY_ID, Candidate, ParamSpec
from hasel_wheel_ident.data import Trial, hv_time
from hasel_wheel_ident.fit import FitResult, Problem, effect_wald_p
from hasel_wheel_ident.metrics import fitted_metrics, pooled_rmse
from hasel_wheel_ident.reasons import Finding, Reason

#: The nominal model's parameters (:func:`~.fit.nominal_specs`), refitted in each trial too.
NOMINAL = frozenset({"peak", "centre", "width", "b", "brake_gain", "tau_f"})

#: Evaluation limit of each trial's refit, which starts at the fit on all trials (the folds'
#: limit too).
MAX_NFEV = 30

#: A trend of an effect's size with the trials' speed this unlikely by chance (two-sided) ...
TREND_P = 1e-3
#: ... and steeper than size ~ speed^EXPONENT makes it inconsistent (:func:`inconsistent`).
EXPONENT = 0.5
#: Trials whose mean speeds while driven span less than this ratio cannot show a trend with
#: speed: runs of one closed loop through one reference profile all have the same mean.  Then
#: each trial's drive is cut into :data:`SPANS` spans (:func:`speed_spans`), and the spans are
#: refitted one by one in place of the trials, provided their speeds span this ratio.
MIN_SPEED_RATIO = 1.2
SPANS = 6
#: ... but no more spans than leave this many turns of the wheel to each on average, so that
#: a once-per-turn effect is seen over a few turns in every span.
MIN_SPAN_TURNS = 3.0
#: The fewest samples of a span (a :class:`~.data.Trial` needs 30).
MIN_SPAN_SAMPLES = 30
#: A change within the trials this unlikely by chance (p < TREND_P, two-sided), and steeper
#: than size ~ hv^DRIFT, is reported as a caution (:func:`drifts`).
DRIFT = 0.05
#: A trend with the trials' speed this unlikely by chance (two-sided), steeper than
#: speed^(+-EXPONENT) but short of TREND_P, is reported as a caution (:func:`leans`), not
#: refused.
LEAN_P = 1e-2


@dataclass
class Beside:
    """An effect refitted beside a measuring device (:func:`measure_beside`): ``value`` the
    device's one parameter in its unit, ``values`` the effect's own values there (each in its
    unit), ``p`` the effect's Wald p there (:func:`~.fit.effect_wald_p`), ``sim`` the
    pooled free-run error on all trials [rad/s] with the effect and without it (the device
    alone), and ``min_gain`` (a fraction) the search's, by which :meth:`holds` judges."""

    device: Candidate
    value: float
    values: dict[str, float]
    p: float
    sim: tuple[float, float]
    min_gain: float = 0.10
    #: the device's own Wald p beside the effect (:func:`~.fit.effect_wald_p`)
    device_p: float = math.nan

    def holds(self) -> bool:
        """Whether the effect still holds beside the device: its Wald p under
        :data:`BESIDE_P`, and it cuts the free run on all trials by half of ``min_gain`` or
        more against the device alone."""
        e1, e0 = self.sim
        return self.p < BESIDE_P and 1.0 - e1 / e0 >= 0.5 * self.min_gain

    def text(self, effect: str, need: bool = False) -> str:
        """The refit in words; with ``need``, what :meth:`holds` needs."""
        e1, e0 = self.sim
        needs = ((f" (need < {BESIDE_P:.0e})", f", need {50 * self.min_gain:.0f} %")
                 if need else ("", ""))
        cut = 1.0 - e1 / e0
        noun, value = DEVICE_WORDS[self.device.id]
        own = (f", itself at Wald p {self.device_p:.1e}" if math.isfinite(self.device_p)
               else "")
        return (f"refitted beside {noun} ({value(self.value)}, a measuring "
                f"device{own}; Wald p of {effect} {self.p:.1e}{needs[0]}, the free run on all "
                f"trials {e1:.4f} rad/s against {e0:.4f} without it, "
                f"{'a cut' if cut >= 0 else 'a rise'} of {100 * abs(cut):.1f} %{needs[1]})")


@dataclass
class Consistency:
    """An effect refitted trial by trial.

    ``effect`` its id; ``names`` (k,) the parameters refitted; ``trials`` (m,) the trials'
    names; ``estimates`` (m, k) the parameters per trial and ``sd`` (m, k) their standard
    deviations, each in its own unit; ``pooled`` (k,) their inverse-covariance mean; ``chi2``
    on ``dof`` degrees of freedom about one value, and its ``p``; ``speeds`` (m,) [rad/s]
    each trial's mean measured speed while driven; ``exponent`` k (size ~ speed^k) with its
    standard deviation ``exponent_sd`` and the two-sided ``trend_p`` of the slope.

    Within each trial (:func:`_drift`): ``halves`` (m, 2) the size (the projection on the
    pooled direction, in units of the parameters' typical magnitudes) refitted on the first
    and the second half of the trial's drive, ``halves_sd`` (m, 2) their standard deviations,
    ``hv`` (m, 2) [s] the mean accumulated HV on-time of the driven actuator in each half;
    ``drift`` h (size ~ hv^h within a trial) with ``drift_sd`` and the two-sided ``drift_p``
    of "no change"; None, 0, inf and 1 when it cannot be formed."""

    effect: str
    names: list[str]
    trials: list[str]
    estimates: np.ndarray
    sd: np.ndarray
    pooled: np.ndarray
    chi2: float
    dof: int
    p: float
    speeds: list[float]
    exponent: float
    exponent_sd: float
    trend_p: float
    #: "trial" when the units refitted one by one are the trials, "span" when they are spans
    #: of the trials' drives (:func:`speed_spans`; ``trials`` then names the spans)
    unit: str = "trial"
    #: the trials' names, for the halves (``trials`` names the spans when ``unit`` is "span")
    halves_trials: list[str] = field(default_factory=list)
    halves: np.ndarray | None = None
    halves_sd: np.ndarray | None = None
    hv: np.ndarray | None = None
    drift: float = 0.0
    drift_sd: float = math.inf
    drift_p: float = 1.0
    #: refitted beside :data:`HV_LOSS` (:func:`drift_stand_in`); None when not refitted
    beside: Beside | None = None
    #: refitted beside :data:`ON_LAG` (:func:`lag_stand_in`); None when not refitted
    beside_lag: Beside | None = None

    def text(self, candidate: Candidate) -> str:
        """The per-trial values in words, slowest trial first."""
        rows = []
        for name, v, x in sorted(zip(self.trials, self.speeds, self.estimates),
                                 key=lambda r: r[1]):
            if len(self.names) == candidate.size:     # its physical size, e.g. a torque
                label, val = next((k, float(w)) for k, w in candidate.describe(x).items()
                                  if isinstance(w, float))
            else:
                label, val = self.names[0], float(x[0])
            rows.append(f"{label} {val:.4g} at {v:.2f} rad/s ({name})")
        return (", ".join(rows) + f": size ~ speed^k, k = {self.exponent:+.2f} +- "
                f"{self.exponent_sd:.2f} (p = {self.trend_p:.1e} for no trend); chi2 "
                f"{self.chi2:.1f} on {self.dof} dof about one value (p = {self.p:.1e})")

    def drift_text(self) -> str:
        """The change within the trials in words."""
        if self.halves is None:
            return "no change within the trials could be measured"
        rows = [f"{a:.3g} -> {b:.3g} ({name}, {h0:.2f} -> {h1:.2f} s of HV per actuator)"
                for name, (a, b), (h0, h1) in zip(self.halves_trials or self.trials,
                                                  self.halves, self.hv)
                if np.isfinite(a) and np.isfinite(b)]
        return ("its size from the first to the second half of each drive, relative to the "
                "typical magnitude: " + ", ".join(rows) + f": size ~ hv^h, h = "
                f"{self.drift:+.2f} +- {self.drift_sd:.2f} (p = {self.drift_p:.1e} for no "
                f"change)")


def trial_consistency(trials: list[Trial], base: WheelParams, effects: tuple[Candidate, ...],
                      fit: FitResult, effect: Candidate, window: float = 1.0,
                      threads: int = 2) -> Consistency | None:
    """Refit ``effect``'s own parameters (its ``per_trial`` ones) and the nominal model on each
    trial alone, any other effect held at ``fit`` (the fit of the model with ``effects`` on
    all ``trials``).  Returns the per-trial estimates in each parameter's own unit (see
    :class:`Consistency`); None with fewer than two trials."""
    if len(trials) < 2:
        return None
    params = [p for p in effect.params
              if effect.per_trial is None or p.name in effect.per_trial]
    own = {p.name for p in params}
    held = {n: v for n, v in fit.values.items() if n not in own and n not in NOMINAL}
    start = dict(fit.values)
    # each trial's windows start where the fit on all trials put them (the same windows:
    # a trial is cut the same way alone), and the trials are fitted side by side, one thread
    # each (the compiled simulator releases the GIL), as the folds are
    every = Problem(trials, base, effects, window=window)
    x_all = fit.x0
    # the trials as the fits see them, a tail at rest trimmed (fit.at_rest_trimmed): the
    # speeds, spans and halves are taken from these, so that a wheel that stalls for good
    # while driven has no half in the trimmed tail (a fit of no samples)
    seen = every.trials

    def one(j: int) -> FitResult:
        prob = Problem([trials[j]], base, effects, window=window, fixed=held)
        return prob.fit(start=start, x0=x_all[every.trial_windows[j]], max_nfev=MAX_NFEV)

    with ThreadPoolExecutor(max_workers=max(threads, 1)) as pool:
        fits = list(pool.map(one, range(len(trials))))
    units, unit_fits, unit = seen, fits, "trial"
    spans = speed_units(seen)
    if spans:
        # each span weighed alone (``keep``), the samples before it still run the model (a
        # retained charge builds up from the trial's start), from its trial's fit, the
        # other effects held
        def one_span(job: tuple[int, Trial]) -> FitResult:
            j, piece = job
            prob = Problem([trials[j]], base, effects, window=window, fixed=held,
                           keep=(float(piece.t[0]), float(np.nextafter(piece.t[-1], math.inf))))
            return prob.fit(start=fits[j].values, x0=fits[j].x0, max_nfev=MAX_NFEV)

        with ThreadPoolExecutor(max_workers=max(threads, 1)) as pool:
            unit_fits = list(pool.map(one_span, spans))
        units, unit = [piece for _, piece in spans], "span"
    est, sd, cov, speeds = _estimates(units, unit_fits, params)
    # in units of each parameter's typical magnitude, so that no unit dominates the norm; a
    # direction a trial does not determine (an infinite variance) carries no information
    scale = np.array([p.scale for p in params])
    x = np.array(est)
    u = x / scale
    k = x.shape[1]
    covs = [c / np.outer(scale, scale) for c in cov]
    infos = [np.linalg.pinv(np.where(np.isfinite(c), c, 0.0)) for c in covs]
    pooled = np.linalg.pinv(np.sum(infos, axis=0)) @ np.sum([i @ v for i, v in zip(infos, u)],
                                                            axis=0)
    chi2 = float(sum((v - pooled) @ i @ (v - pooled) for i, v in zip(infos, u)))
    dof = (len(units) - 1) * k
    exponent, exponent_sd, trend_p = _trend(u, covs, pooled, speeds)
    con = Consistency(effect.id, [p.name for p in params], [tr.name for tr in units], x,
                      np.array(sd), pooled * scale, chi2, dof, float(stats.chi2.sf(chi2, dof)),
                      speeds, exponent, exponent_sd, trend_p, unit)
    if spans:       # the halves below are halves of the trials, sized by the trials' fits
        u = np.array(_estimates(seen, fits, params)[0]) / scale
        con.halves_trials = [tr.name for tr in seen]
    norm = float(np.linalg.norm(pooled))
    if norm > 0.0:
        d = pooled / norm
        own_names = [p.name for p in params]

        def half(job: tuple[int, tuple[float, float]]) -> FitResult:
            j, span = job
            res = fits[j]
            fixed = {**held, **{n: v for n, v in res.values.items() if n not in own}}
            prob = Problem([trials[j]], base, effects, window=window, fixed=fixed, keep=span)
            return prob.fit(start=res.values, x0=res.x0,
                            max_nfev=MAX_NFEV)

        cuts = [_halves(tr) for tr in seen]
        jobs = [(j, span) for j, c in enumerate(cuts) if c is not None for span in c[0]]
        with ThreadPoolExecutor(max_workers=max(threads, 1)) as pool:
            done = dict(zip(jobs, pool.map(half, jobs)))
        halves = np.full((len(trials), 2), np.nan)
        halves_var = np.full((len(trials), 2), np.inf)
        hv = np.full((len(trials), 2), np.nan)
        for j, c in enumerate(cuts):
            if c is None:
                continue
            hv[j] = c[1]
            for i, span in enumerate(c[0]):
                res = done[(j, span)]
                order = [res.names.index(n) for n in own_names]
                cj = res.cov[np.ix_(order, order)] / np.outer(scale, scale)
                halves[j, i] = d @ (res.theta[order] / scale)
                halves_var[j, i] = d @ cj @ d if np.all(np.isfinite(cj)) else np.inf
        con.halves, con.hv = halves, hv
        con.halves_sd = np.sqrt(halves_var)
        con.drift, con.drift_sd, con.drift_p = _drift(halves, halves_var, hv, u @ d)
    return con


def _estimates(units: list[Trial], fits: list[FitResult], params: list
               ) -> tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray], list[float]]:
    """(estimates, their sd, their covariance, the unit's speed [rad/s]) of ``params`` in
    each fit of ``fits``, one per trial or span of ``units``."""
    est, sd, cov, speeds = [], [], [], []
    for tr, res in zip(units, fits):
        order = [res.names.index(p.name) for p in params]
        est.append(res.theta[order])
        c = res.cov[np.ix_(order, order)]
        cov.append(c)
        sd.append(np.sqrt(np.maximum(np.diag(c), 0.0)))
        speeds.append(driven_speed(tr))
    return est, sd, cov, speeds


def driven_speed(tr: Trial) -> float:
    """The trial's mean speed [rad/s] while driven: the angle it turns from its first to its
    last sample with an actuator scheduled or on, over that time (the whole trial if none)."""
    driven = tr.q.astype(bool) | (tr.n_a >= 0)
    span = tr.t[driven] if driven.any() else tr.t
    ang = tr.angle[driven] if driven.any() else tr.angle
    return float((ang[-1] - ang[0]) / max(span[-1] - span[0], 1e-9))


def speed_spans(tr: Trial, n: int = SPANS) -> list[Trial]:
    """The trial's drive (first to last sample with an actuator scheduled or on) cut into
    ``n`` spans of about equal duration, or fewer so that they average
    :data:`MIN_SPAN_TURNS` turns each, each a trial of its own named after its times [s];
    each cut is moved on to the next sample with no actuator on, so no push is cut, and a
    tail under :data:`MIN_SPAN_SAMPLES` joins the span before.  [] when the trial has no
    drive, or one shorter than that."""
    driven = np.flatnonzero(tr.q.astype(bool) | (tr.n_a >= 0))
    if driven.size == 0:
        return []
    first, end = int(driven[0]), int(driven[-1]) + 1
    if end - first < MIN_SPAN_SAMPLES:
        return []
    turns = abs(float(tr.angle[end - 1] - tr.angle[first])) / (2 * math.pi)
    n = max(min(n, int(turns / MIN_SPAN_TURNS)), 1)
    cuts = [first]
    for t_cut in np.linspace(tr.t[first], tr.t[end - 1], n + 1)[1:-1]:
        i = max(int(np.searchsorted(tr.t, t_cut)), cuts[-1] + MIN_SPAN_SAMPLES)
        while i < end and tr.q[i]:
            i += 1
        if i < end:
            cuts.append(i)
    while len(cuts) > 1 and end - cuts[-1] < MIN_SPAN_SAMPLES:
        cuts.pop()                                      # a short tail joins the span before
    cuts.append(end)
    return [tr.slice(a, b, f"{tr.name} {tr.t[a] - tr.t[0]:.0f}-{tr.t[b - 1] - tr.t[0]:.0f} s")
            for a, b in zip(cuts, cuts[1:])]


def speed_units(trials: list[Trial]) -> list[tuple[int, Trial]]:
    """(trial index, span) of every trial's :func:`speed_spans` when the trials' speeds while
    driven span less than :data:`MIN_SPEED_RATIO` and the spans' speeds span at least that;
    [] otherwise (the trials themselves are the units)."""
    speeds = [driven_speed(tr) for tr in trials]
    if min(speeds) <= 0.0 or max(speeds) >= MIN_SPEED_RATIO * min(speeds):
        return []           # a trial at rest or rolling back: the trials themselves
    spans = [(j, piece) for j, tr in enumerate(trials) for piece in speed_spans(tr)]
    v = [driven_speed(piece) for _, piece in spans]
    if len(spans) < 3 or min(v) <= 0.0 or max(v) < MIN_SPEED_RATIO * min(v):
        return []
    return spans


#: The first and second half of a trial's drive are told apart only if the mean accumulated
#: HV time of the driven actuator differs between them by this factor or more.
MIN_HV_RATIO = 1.5


def _halves(tr: Trial) -> tuple[tuple[tuple[float, float], tuple[float, float]],
                                 tuple[float, float]] | None:
    """((early span, late span) [s], (mean HV time in each) [s]) of the trial: its drive
    (from the first to the last sample with an actuator scheduled or on) cut at the middle.
    The coast is in neither: it would carry much of the information on a torque (a drag, an
    off-centre mass) in one half only.  The HV time is the driven actuator's accumulated
    on-time (:func:`~.data.hv_time`) averaged over the samples where it is on.  None without
    a drive, or when the halves' HV times differ by less than :data:`MIN_HV_RATIO`."""
    driven = tr.q.astype(bool) | (tr.n_a >= 0)
    on = tr.q.astype(bool)
    if not on.any():
        return None
    t_on = tr.t[driven]
    mid = 0.5 * (t_on[0] + t_on[-1])
    h = hv_time(tr)
    early, late = on & (tr.t < mid), on & (tr.t >= mid)
    if not early.any() or not late.any():
        return None
    h0, h1 = float(h[early].mean()), float(h[late].mean())
    if h0 <= 0.0 or h1 < MIN_HV_RATIO * h0:
        return None
    end = float(np.nextafter(t_on[-1], math.inf))         # keep's end is exclusive
    return ((-math.inf, mid), (mid, end)), (h0, h1)


def _drift(halves: np.ndarray, var: np.ndarray, hv: np.ndarray,
           whole: np.ndarray) -> tuple[float, float, float]:
    """(h, sd of h, two-sided p of h = 0): how the size changes within a trial, size ~ hv^h.

    ``halves`` (m, 2) the sizes refitted on each trial's halves with variances ``var``
    (m, 2), at the mean HV times ``hv`` (m, 2) [s]; ``whole`` (m,) the size fitted on the
    whole trial.  Each trial gives h_j = (late - early) / (whole * ln(hv_late / hv_early)),
    with variance (var_early + var_late) / (whole * ln ratio)^2; they are averaged with
    inverse-variance weights.  (0, inf, 1) when no trial gives one (no cut, or a size that
    is not positive on the whole trial)."""
    num = den = 0.0
    for (a, b), (va, vb), (h0, h1), m in zip(halves, var, hv, whole):
        if not (np.isfinite(a) and np.isfinite(b) and m > 0.0 and h0 > 0.0 and h1 > h0):
            continue
        g = m * math.log(h1 / h0)
        v = (va + vb) / g ** 2
        if not (np.isfinite(v) and v > 0.0):
            continue
        num += (b - a) / g / v
        den += 1.0 / v
    if den <= 0.0:
        return 0.0, math.inf, 1.0
    h = num / den
    sd = 1.0 / math.sqrt(den)
    return float(h), float(sd), float(2 * stats.norm.sf(abs(h) / sd))


def _trend(u: np.ndarray, covs: list[np.ndarray], pooled: np.ndarray,
           speeds: list[float]) -> tuple[float, float, float]:
    """(k, sd of k, two-sided p of the slope) of the sizes m_j = pooled' u_j / |pooled| of
    the m trials' estimates u (m, k) with covariances ``covs`` (m of (k, k)), against ln of
    the trials' ``speeds`` [rad/s] (see the module docstring).  (0, inf, 1) when it cannot be
    formed: no size, one speed, fewer than two trials with a finite variance, or a size that
    is not positive."""
    norm = float(np.linalg.norm(pooled))
    x = np.log(np.maximum(np.asarray(speeds), 1e-9))
    if norm <= 0.0 or np.ptp(x) <= 0.0:
        return 0.0, math.inf, 1.0
    d = pooled / norm
    m = u @ d
    var = np.array([d @ c @ d for c in covs])
    ok = np.isfinite(var) & (var > 0.0)
    if ok.sum() < 2 or np.ptp(x[ok]) <= 0.0:
        return 0.0, math.inf, 1.0
    w = np.where(ok, 1.0 / np.where(ok, var, 1.0), 0.0)
    X = np.column_stack([np.ones_like(x), x - np.average(x, weights=w)])
    cov = np.linalg.inv(X.T @ (w[:, None] * X))
    a, b = cov @ X.T @ (w * np.where(ok, m, 0.0))
    if a <= 0.0:
        return 0.0, math.inf, 1.0
    k = b / a
    # delta method for b / a (a and b are uncorrelated: x is centred on its weighted mean)
    sd = (abs(k) * math.sqrt(max(cov[1, 1] / b ** 2 + cov[0, 0] / a ** 2
                                 - 2 * cov[0, 1] / (a * b), 0.0)) if b != 0
          else math.sqrt(cov[1, 1]) / a)
    return float(k), float(sd), float(2 * stats.norm.sf(abs(b) / math.sqrt(cov[1, 1])))


def drifts(c: Consistency | None) -> bool:
    """True when the effect's size changes within the trials as the actuators accumulate HV
    time: significantly (p < TREND_P) and steeper than hv^(+-DRIFT)."""
    return c is not None and c.drift_p < TREND_P and abs(c.drift) > DRIFT


def inconsistent(c: Consistency | None) -> bool:
    """True when the effect is not one value across the trials (or their spans, ``unit``
    "span"): its size trends with their speed, significantly (p < TREND_P) and steeper than
    speed^(+-EXPONENT).  A drift within the trials (:func:`drifts`) is reported, not
    refused (see the module docstring)."""
    return c is not None and c.trend_p < TREND_P and abs(c.exponent) > EXPONENT


def stand_in_reason(c: Candidate, con: Consistency | None) -> Finding | None:
    """Code ``SPEED_STAND_IN`` when ``c``, refitted trial by trial as ``con``, is
    :func:`inconsistent` (its size trends with the trials' speed); None otherwise.  Values:
    ``unit`` ("trial" or "span"), ``exponent`` k and ``trend_p``."""
    if not inconsistent(con):
        return None
    how = ("in every trial, refitted trial by trial" if con.unit == "trial" else
           "at every speed, refitted span by span (the trials' speeds while driven differ by "
           f"less than {MIN_SPEED_RATIO}x; {len(con.trials)} spans of "
           f"{len(con.halves_trials)} drives)")
    return Finding(Reason.SPEED_STAND_IN,
                   f"{c.id} is not the same {how}: {con.text(c)}; a physical {c.id} would be "
                   f"one value at every speed, so it stands in for an effect whose size goes "
                   f"otherwise with the speed",
                   {"unit": con.unit, "exponent": con.exponent, "trend_p": con.trend_p})


def leans(c: Consistency | None) -> bool:
    """True when the effect's size trends with the trials' speed (p < LEAN_P, steeper than
    speed^(+-EXPONENT)) short of :func:`inconsistent`: evidence, not enough to refuse it."""
    return (c is not None and c.trend_p < LEAN_P and abs(c.exponent) > EXPONENT
            and not inconsistent(c))


def lean_caution(c: Candidate, con: Consistency | None) -> str | None:
    """A caution when ``c``, refitted trial by trial as ``con``, :func:`leans` on the speed;
    None otherwise.  It quotes the refit beside :data:`ON_LAG` when one ran."""
    if not leans(con):
        return None
    by = "trial by trial" if con.unit == "trial" else "span by span"
    b = con.beside_lag
    beside = ("" if b is None else f"; {b.text(c.id)}: there it "
              + ("still holds" if b.holds() else "no longer holds"))
    return (f"{c.id} goes with the speed, refitted {by}: {con.text(c)}; short of a refusal "
            f"(p < {TREND_P:.0e}), but a physical {c.id} would be one value at every speed, "
            f"so it may stand in for an effect whose size goes with the speed (trials at "
            f"more speeds, or with longer drives at a steady speed, would tell){beside}")


def caution(c: Candidate, con: Consistency | None) -> str | None:
    """Every caution on ``c`` refitted as ``con`` (:func:`lean_caution`,
    :func:`drift_caution`, :func:`loss_caution`), one sentence each; None when there is
    none."""
    return " ".join(f"{s}." for s in (lean_caution(c, con), drift_caution(c, con),
                                       loss_caution(c, con)) if s) or None


def loss_caution(c: Candidate, con: Consistency | None) -> str | None:
    """A caution when ``c``, a rise lag that does not drift (:data:`LOSS_LOOKALIKES`), still
    holds beside :data:`HV_LOSS` while the device is significant beside it too (p under
    :data:`LOOKALIKE_P`): the two are close in shape on these trials, and the loss may be
    what is there; None otherwise.  Seen with retention of 0.05/s, 3 x 34 s, plant seed 13,
    while the coast-downs read tau_f low (README, Known gaps)."""
    b = None if con is None else con.beside
    if (c.id not in LOSS_LOOKALIKES or b is None or drifts(con) or not b.holds()
            or not b.device_p < LOOKALIKE_P):
        return None
    return (f"{c.id} {b.text(c.id)}: there it still holds, but so does the loss (under "
            f"{LOOKALIKE_P:g}); on these trials the two weaken the pushes in close shapes, so "
            f"a loss with the accumulated HV time (charge retention) may be what is there")


def drift_caution(c: Candidate, con: Consistency | None) -> str | None:
    """A caution when ``c``, refitted on the halves of each drive, changes within the trials
    (:func:`drifts`); None otherwise."""
    if not drifts(con):
        return None
    if con.beside is not None and con.beside.holds():
        return (f"{c.id} is not the same throughout a trial, refitted on the halves of each "
                f"drive: {con.drift_text()}; {con.beside.text(c.id)}: there it still holds, "
                f"so an effect that changes during a trial is probably still missing and "
                f"this one took up part of it")
    return (f"{c.id} is not the same throughout a trial, refitted on the halves of each "
            f"drive: {con.drift_text()}; either it stands in for an effect that changes "
            f"during a trial, or such an effect is still missing and this one took up part "
            f"of it")


#: Charge retention's recovery [s] in the measuring device: far longer than any trial, so
#: that the loss grows with the accumulated HV time alone.
HV_LOSS_RECOVERY = 1e5


def _hv_loss(x, pv, extra):
    pv[L.P_RET_RATE] = x[0]
    pv[L.P_RET_RECOVERY] = HV_LOSS_RECOVERY


#: The measuring device for a change within the trials (module docstring): every actuator's
#: force x exp(-loss_rate Q_i), Q_i its accumulated HV time.
HV_LOSS = Candidate("hv_loss", "actuator force lost with accumulated HV time (a measuring "
                    "device)", (ParamSpec("loss_rate", "1/s", 1e-3, 0.0, 1.0, 1e-2),),
                    _hv_loss, lambda x: {"rate_per_s": float(x[0])}, "hv_time")

#: Effects refitted beside :data:`HV_LOSS` whether they drift or not (:func:`drift_stand_in`):
#: a rise lag takes a bite out of every push, and so does a loss with the HV time, which
#: need not show as a drift of the lag's size within the trials (a 25 ms lag named for
#: retention of 0.05/s: h = -0.01 +- 0.02; README, Known gaps).
LOSS_LOOKALIKES = frozenset({"rise_lag"})
#: ... which stands in when it does not hold beside the device while the device is
#: significant beside it at this level [1].
LOOKALIKE_P = 1e-2
#: Beside the device, the effect must still differ from "no effect" at this level (the
#: search's Wald test) ...
BESIDE_P = 1e-6
#: Evaluation limit of the measuring refit beside an unexplained drift, after the search
#: (:func:`refit_beside`, once per run and device): it starts from a force law bent to take
#: up the loss.  The stand-in tests during the search (:func:`measure_beside`) keep
#: :data:`MAX_NFEV`, since they start from the effect's own fit.
BESIDE_NFEV = 150


def can_measure_beside(effects: tuple[Candidate, ...]) -> bool:
    """Whether :data:`HV_LOSS` can go beside the model with ``effects``: not when it has a
    retention of its own (the device would be it) or the device already."""
    return not any(c.id in ("charge_retention", HV_LOSS.id) for c in effects)


def refit_beside(trials: list[Trial], base: WheelParams, effects: tuple[Candidate, ...],
                 fit: FitResult, device: Candidate, window: float = 1.0, threads: int = 2,
                 max_nfev: int = BESIDE_NFEV) -> tuple[Problem, FitResult]:
    """(The problem, its fit): the model with ``effects`` (fitted on all ``trials`` as
    ``fit``; ``window`` [s]) refitted with the measuring ``device`` beside it, from ``fit``
    and the device's start value, for up to ``max_nfev`` evaluations."""
    problem = Problem(trials, base, effects + (device,), window, threads=threads)
    return problem, problem.fit(start=fit.values, x0=fit.x0, max_nfev=max_nfev)


def measure_beside(trials: list[Trial], base: WheelParams, effects: tuple[Candidate, ...],
                   fit: FitResult, effect: Candidate, device: Candidate, min_gain: float,
                   window: float = 1.0, threads: int = 2) -> Beside | None:
    """``effect`` (in ``effects``, the model fitted on all ``trials`` as ``fit``) refitted
    beside the measuring ``device``, and the model without ``effect`` but with the device
    (each :data:`MAX_NFEV` evaluations; the second from the first): a :class:`Beside` judged
    by ``min_gain`` (a fraction), or None when one of its figures is not finite."""
    with_it, f1 = refit_beside(trials, base, effects, fit, device, window, threads, MAX_NFEV)
    own = {p.name for p in effect.params}
    without = Problem(trials, base, tuple(c for c in effects if c is not effect) + (device,),
                      window, threads=threads)
    f0 = without.fit(start={k: v for k, v in f1.values.items() if k not in own},
                     x0=f1.x0, max_nfev=MAX_NFEV)
    e1 = pooled_rmse(fitted_metrics(with_it, f1, trials))
    e0 = pooled_rmse(fitted_metrics(without, f0, trials))
    p = effect_wald_p(f1, effect)
    value = f1.values[device.params[0].name]
    if not all(math.isfinite(v) for v in (e1, e0, p, value)) or e0 <= 0.0:
        return None
    return Beside(device, value, {n: f1.values[n] for n in own}, p, (e1, e0), min_gain,
                  effect_wald_p(f1, device))


def drift_stand_in(trials: list[Trial], base: WheelParams, effects: tuple[Candidate, ...],
                   fit: FitResult, effect: Candidate, con: Consistency | None,
                   min_gain: float, window: float = 1.0, threads: int = 2) -> Finding | None:
    """Why ``effect`` (in ``effects``, the model fitted on all ``trials`` as ``fit``, with
    windows of ``window`` [s]) stands in for a change within the trials (code
    ``DRIFT_STAND_IN``, or ``HV_LOSS_LOOKALIKE`` for a rise lag that does not drift), or
    None; values: ``drift`` h, ``p`` (its Wald p beside the device), ``device_p``.

    Tested when :func:`can_measure_beside`, for an effect that drifts (:func:`drifts` of
    ``con``, its check trial by trial) and for every rise lag (:data:`LOSS_LOOKALIKES`).  It
    is refitted beside :data:`HV_LOSS` (:func:`measure_beside`).  An effect that drifts
    stands in when it no longer holds there (:meth:`Beside.holds`: its Wald p not under
    :data:`BESIDE_P`, or it cuts the pooled free-run error on all trials by less than half
    of ``min_gain``, a fraction, against the device alone).  A rise lag that does not drift
    stands in when it no longer holds there *and* the device itself is significant beside it
    (p under :data:`LOOKALIKE_P`): the loss is then there and the lag is not needed.  The
    refit is kept on ``con`` (``beside``); when it is void, None."""
    drifting = drifts(con)
    if con is None or not can_measure_beside(effects) or not (
            drifting or effect.id in LOSS_LOOKALIKES):
        return None
    con.beside = b = measure_beside(trials, base, effects, fit, effect, HV_LOSS, min_gain,
                                    window, threads)
    if b is None or b.holds():
        return None
    values = {"drift": con.drift, "p": b.p, "device_p": b.device_p}
    if drifting:
        return Finding(Reason.DRIFT_STAND_IN,
                       f"{effect.id} changes within the trials ({con.drift_text()}); "
                       f"{b.text(effect.id, need=True)}: there it no longer holds, so it "
                       f"stands in for an effect that changes during the trials", values)
    if not b.device_p < LOOKALIKE_P:
        return None
    return Finding(Reason.HV_LOSS_LOOKALIKE,
                   f"{effect.id} and a loss with the accumulated HV time weaken the pushes in "
                   f"close shapes; {b.text(effect.id, need=True)}: there it no longer holds "
                   f"while the loss does (under {LOOKALIKE_P:g}), so it stands in for a loss "
                   f"that grows with the HV time", values)


#: The measuring device for a size that grows with the speed (module docstring): the rise
#: lag's physics, every actuator's force x (1 - exp(-t_on / lag_tau)), t_on the time since
#: it was switched on, from 20 ms, without the rise lag's screening or saved model fields.
#: A loss at each switch-on takes a larger share of a shorter push, so it grows with speed.
ON_LAG = dataclasses.replace(
    BY_ID["rise_lag"], id="on_lag",
    title="actuator force that builds up after each switch-on (a measuring device)",
    params=(ParamSpec("lag_tau", "s", 0.02, 1e-5, 0.5, 0.01),), extension=None,
    screen_at=(), scan=())

#: Each device in words: (what it is, its fitted value [its unit] -> words).
DEVICE_WORDS: dict[str, tuple[str, Callable[[float], str]]] = {
    HV_LOSS.id: ("a force loss that grows with the accumulated HV time",
                 lambda v: f"rate {v:.3g}/s"),
    ON_LAG.id: ("a force that builds up after each switch-on",
                lambda v: f"time constant {1e3 * v:.3g} ms"),
}

#: The trend axis (:data:`~.residual.TREND_AXES`) along which each device's loss drifts:
#: a loss with HV time along the HV time, a loss at each switch-on along the speed.
DEVICE_TREND_AXIS = {HV_LOSS.id: "hv_time", ON_LAG.id: "speed"}


def lead_device(devices: dict[str, dict], min_gain: float) -> str | None:
    """The id of the device that takes up the most of a drift (:func:`devices_verdict`),
    or None when none does."""
    devices = _finite(devices)
    if not devices:
        return None
    need = 0.5 * min_gain
    together = together_lead(devices)
    best = together or min(devices, key=lambda k: devices[k]["sim_rmse_rad_s"])
    d = devices[best]
    e = d["sim_rmse_rad_s"]
    if 1.0 - e / d["sim_rmse_model_rad_s"] < need:
        return None
    if together is None and not all(e <= (1.0 - need) * o["sim_rmse_rad_s"]
                                    for k, o in devices.items() if k != best):
        return None
    return best


def together_lead(devices: dict[str, dict]) -> str | None:
    """The one device that stays significant with every other beside it, when the devices
    were refitted together (``wald_p_together`` of each): its Wald p there under
    :data:`BESIDE_P` while every other's is :data:`LOOKALIKE_P` or more.  None when the
    refit together is missing, or does not single one out.

    This overrides the free runs: on short trials a look-alike can run them better than the
    loss that is there.  (A p of 1 can also mean a parameter the fit leaves undetermined,
    :func:`~.fit.wald_p`: beside the other device that device is then not needed either.)
    Tested in ``test_ident_consistency.py``."""
    ps = {k: d.get("wald_p_together", math.nan) for k, d in devices.items()}
    if len(ps) < 2 or not all(math.isfinite(p) for p in ps.values()):
        return None
    lead = [k for k, p in ps.items() if p < BESIDE_P]
    if len(lead) != 1 or not all(p >= LOOKALIKE_P for k, p in ps.items() if k != lead[0]):
        return None
    return lead[0]


def _finite(devices: dict[str, dict]) -> dict[str, dict]:
    """The devices whose free runs are finite (and the model's positive)."""
    return {k: d for k, d in devices.items()
            if math.isfinite(d["sim_rmse_rad_s"]) and math.isfinite(d["sim_rmse_model_rad_s"])
            and d["sim_rmse_model_rad_s"] > 0.0}


def devices_verdict(devices: dict[str, dict], min_gain: float) -> str:
    """Which measuring device takes up the most of a drift, in words (a description, not a
    name).  ``devices`` maps each device's id to its refit beside the model:
    ``sim_rmse_rad_s`` the free run on all trials with it, ``sim_rmse_model_rad_s`` without
    it, and optionally ``wald_p_together`` its Wald p with all the devices refitted together.
    A device takes up the drift when it cuts that error by half of ``min_gain`` (a
    fraction) or more; one takes up the most when, besides, it alone stays significant
    together (:func:`together_lead`) or, failing that verdict, its error is that much below
    every other device's.  Devices whose figures are not finite are left out."""
    lead = lead_device(devices, min_gain)
    if lead is not None:
        why = ""
        if lead == together_lead(_finite(devices)):
            others = ", ".join(f"{DEVICE_WORDS[k][0]} {d['wald_p_together']:.1e}"
                               for k, d in devices.items() if k != lead)
            why = (f": refitted together, only it stays significant (Wald p "
                   f"{devices[lead]['wald_p_together']:.1e}; {others})")
        return (f"of these, {DEVICE_WORDS[lead][0]} takes up the most of it{why} (a "
                f"description, not a name)")
    devices = _finite(devices)
    if not devices:
        return "no device could be refitted beside the model"
    need = 0.5 * min_gain
    if all(1.0 - d["sim_rmse_rad_s"] / d["sim_rmse_model_rad_s"] < need
           for d in devices.values()):
        return (f"no device takes up much of it (each cuts the free run on all trials by less "
                f"than {100 * need:.0f} %)")
    return (f"no device takes up clearly more of it than the others (free runs within "
            f"{100 * need:.0f} % of each other): its shape is not told")


#: An effect whose size grows with the trials' speed (k > :data:`EXPONENT`) with a trend
#: this unlikely by chance (two-sided) or less is refitted beside :data:`ON_LAG`
#: (:func:`lag_stand_in`).
SEEK_P = 0.1


def grows_with_speed(c: Consistency | None) -> bool:
    """True when the effect's size grows with the trials' speed, steeper than
    speed^EXPONENT with a trend p under :data:`SEEK_P`: reason enough to test it beside
    :data:`ON_LAG` (:func:`lag_stand_in`), not to refuse it."""
    return c is not None and c.exponent > EXPONENT and c.trend_p < SEEK_P


def can_measure_lag(effects: tuple[Candidate, ...]) -> bool:
    """Whether :data:`ON_LAG` can go beside the model with ``effects``: not when it has a
    rise lag of its own (the device would be it) or the device already."""
    return not any(c.id in ("rise_lag", ON_LAG.id) for c in effects)


def lag_stand_in(trials: list[Trial], base: WheelParams, effects: tuple[Candidate, ...],
                 fit: FitResult, effect: Candidate, con: Consistency | None,
                 min_gain: float, window: float = 1.0, threads: int = 2) -> Finding | None:
    """Why ``effect`` (in ``effects``, the model fitted on all ``trials`` as ``fit``, with
    windows of ``window`` [s]) stands in for a force that builds up after each switch-on
    (code ``SWITCH_ON_LAG_STAND_IN``; values ``exponent`` k, ``p`` its Wald p beside the
    device, ``device_p``), or None.

    Only an effect whose size grows with the speed (:func:`grows_with_speed` of ``con``)
    is tested, and only when :func:`can_measure_lag`.  It is refitted beside
    :data:`ON_LAG` (:func:`measure_beside`) and stands in when it no longer holds there
    (:meth:`Beside.holds`).  The refit is kept on ``con`` (``beside_lag``); when it is
    void, None."""
    if not grows_with_speed(con) or not can_measure_lag(effects):
        return None
    con.beside_lag = measure_beside(trials, base, effects, fit, effect, ON_LAG, min_gain,
                                    window, threads)
    if con.beside_lag is None or con.beside_lag.holds():
        return None
    b = con.beside_lag
    return Finding(Reason.SWITCH_ON_LAG_STAND_IN,
                   f"{effect.id} grows with the speed ({con.text(effect)}); "
                   f"{b.text(effect.id, need=True)}: there it no longer holds, so it stands "
                   f"in for a loss at each switch-on, which takes a larger share of the "
                   f"shorter pushes at speed",
                   {"exponent": con.exponent, "p": b.p, "device_p": b.device_p})
