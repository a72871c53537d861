"""Residual diagnostics in the spirit of Ljung's model validation (MATLAB ``resid``).

Two residuals come out of a fit (:class:`~.fit.Problem`):

* the **output residual** r [rad]: simulated minus measured angle, every sample, windows
  re-started from fitted states.  For an output-error model it should be independent of
  the input: its cross-correlation with q must stay inside the 99 % band.  Its
  autocorrelation is reported too (whiteness), with the same band;
* the **acceleration residual** a [rad/s^2]: the second derivative of r inside each window
  (Savitzky-Golay, ``SG_WINDOW`` samples).  An unmodelled torque tau shows up in it as
  -tau / (J/L), so its structure against physical axes points at the missing effect.

Structure is judged against each axis (wheel angle, pivot angle, contact angle, actuator
index, time, accumulated HV time of the active actuator, speed, time since switch-on) by a
one-way analysis of variance over bins, and against the unwrapped wheel angle and time by a
least-squares sinusoid scan (a periodogram) of the windows' continuity defects, and by a
regression of those defects on time, HV time and speed during the drive
(:func:`drive_trend`): an effect that grows or fades through each drive is a drift, not a
period of about one cycle per trial.  Samples of a are correlated over the filter
length, so every test counts one independent sample per ``SG_WINDOW``.  When none of these
finds structure but the output residual is not white, that is reported too
(:func:`autocorrelation_signature`): a freely fitted force law can take up a missing effect
within each window, and only the residual's correlation is left to show it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import signal, stats

from hasel_wheel_sim.model import N_ACTUATORS, SECTOR

from hasel_wheel_ident.data import hv_time
from hasel_wheel_ident.session_trend import SESSION_AXES, SessionDrift, session_drift
from hasel_wheel_ident.fit import FitResult, Problem

SG_WINDOW = 61          # samples (0.2 s at 300 Hz) of the Savitzky-Golay derivative
SIGNIFICANCE = 1e-6     # p-value below which structure counts (many axes and frequencies)
MIN_AMPLITUDE = 0.005   # [rad/s^2] structure smaller than this is not reported
MIN_WINDOW_GAIN = 0.2   # a sinusoid that the window means shrink below this is not scanned
#: Axes along which a steady change of the window defects during the drive is looked for
#: (:func:`drive_trend`), and the p-value below which one counts (three tests, not a scan).
TREND_AXES = ("time", "hv_time", "speed")
TREND_SIGNIFICANCE = 1e-4
#: The periodograms' longest period: the longest trial's span (in time, in wheel angle) over
#: this many cycles, without a drift.  A shape of fewer cycles is no period one can name:
#: an effect left out that drifts through each trial reads as a period of one to two cycles
#: of the longest trial.  A pivot lap (25.66 rad of wheel angle) is scanned on trials
#: spanning 51 rad or more.  Tested in ``test_ident_residual.py``
#: (``test_without_a_drift_the_scans_keep_one_level_per_trial_and_slow_periods``).
FEWEST_CYCLES = 2.0
#: With a drift found (:func:`drive_trend`), the periodograms start at this many cycles: a
#: quadratic per drive then takes up the drift's shape, and part of a slower sinusoid
#: (:func:`scan_nuisance`).
MIN_CYCLES = 3.0
#: A window counts as driven when an actuator is on for at least this share of its samples.
DRIVEN_SHARE = 0.2
#: mean autocorrelation of the angle residual over lags 1..max_lag above which the residual
#: counts as not white when no axis shows structure (see :func:`signatures`)
CORRELATED_SHARE = 0.01

#: axis -> (unit, periodic period or None, only while an actuator is on)
AXES = {
    "wheel_angle": ("rad", 2 * math.pi, False),
    "pivot_angle": ("rad", 2 * math.pi, False),
    "contact_angle": ("rad", None, True),
    "actuator": ("index", None, True),
    "time": ("s", None, False),
    "hv_time": ("s", None, True),
    "speed": ("rad/s", None, False),
    "on_time": ("s", None, True),
}


@dataclass
class AxisStructure:
    """Bin means of the acceleration residual against one axis."""

    axis: str
    unit: str
    centers: np.ndarray
    means: np.ndarray
    stderr: np.ndarray
    p_value: float
    amplitude: float          # half the peak-to-peak of the bin means [rad/s^2]


@dataclass
class Peak:
    """A sinusoid in the acceleration residual along an axis."""

    axis: str                 # "wheel_angle_unwrapped" [rad] or "time" [s]
    period: float             # in the axis' unit
    amplitude: float          # [rad/s^2]
    p_value: float
    per_wheel_turn: float     # 2 pi / period (angle axis only, else nan)
    per_pivot_lap: float      # (2 pi L / r) / period (angle axis only, else nan)


@dataclass
class Signature:
    """Structure the model does not explain: where, how periodic, how large."""

    axis: str
    unit: str
    period: float | None      # None when not periodic
    amplitude: float          # [rad/s^2]
    torque: float             # amplitude x (J/L) [N*m]
    p_value: float
    text: str
    #: for a periodic signature sized by a refit (:mod:`.periodic`): the torque is
    #: torque * sin(2 pi x / period + phase) along the signature's axis x [rad]; its 95 %
    #: interval [N*m].  None when sized from the residual alone
    phase: float | None = None
    torque_ci95: tuple[float, float] | None = None
    #: for a signature along the actuator index sized by a refit (:mod:`.actuator`): the 16
    #: actuators' force factors [1] (their geometric mean 1).  None otherwise
    factors: tuple[float, ...] | None = None
    #: True for a drift during the drives along a trend axis (:func:`trend_signature`)
    drift: bool = False
    #: for a drift: each measuring device refitted beside the final model
    #: (:func:`hasel_wheel_ident.unexplained.describe_unexplained`), by id: {value, unit, wald_p,
    #: sim_rmse_rad_s (the free run on all trials with it), sim_rmse_model_rad_s (without)}
    devices: dict[str, dict] = field(default_factory=dict)


@dataclass
class Trend:
    """A steady change of the unmodelled acceleration during the drive (:func:`drive_trend`).

    ``axis`` the axis it follows best (``unit`` its unit); ``slope`` [rad/s^2 per unit] of
    its straight part; ``amplitude`` [rad/s^2] half the largest range of the fitted curve
    (line and bend) within a trial's driven windows;
    ``p_value`` of "no slope"; ``p_values`` that of every axis of :data:`TREND_AXES`;
    ``correlations`` the correlation within trials of the other axes with ``axis`` [1]."""

    axis: str
    unit: str
    slope: float
    amplitude: float
    p_value: float
    p_values: dict[str, float]
    correlations: dict[str, float]


@dataclass
class Diagnostics:
    rms_angle: float                      # [rad]
    rms_accel: float                      # [rad/s^2]
    acf_lags: np.ndarray
    acf: np.ndarray
    ccf_lags: np.ndarray
    ccf_q: np.ndarray
    band99: float
    whiteness_outside: float              # fraction of lags 1..L outside the band
    input_correlation_max: float          # max |ccf| with q
    #: mean autocorrelation over lags 1..L [1] and its standard deviation for a white
    #: residual, 1 / sqrt(n L) (the lags of white noise are nearly independent, each 1/sqrt(n))
    correlated_share: float = 0.0
    correlated_share_sd: float = math.nan
    max_lag_s: float = math.nan           # [s] the lag L in time
    window_s: float = math.nan            # [s] the fit's window length
    structures: dict[str, AxisStructure] = field(default_factory=dict)
    spectra: dict[str, tuple[np.ndarray, np.ndarray]] = field(default_factory=dict)
    peaks: list[Peak] = field(default_factory=list)
    signatures: list[Signature] = field(default_factory=list)
    # per-sample series for plots
    accel: np.ndarray | None = None
    axes: dict[str, np.ndarray] = field(default_factory=dict)
    mask: np.ndarray | None = None
    defects: np.ndarray | None = None     # window continuity defects [rad/s^2]
    trend: Trend | None = None            # a significant steady change during the drive
    #: a significant change from trial to trial along the session (:mod:`.session_trend`)
    session: SessionDrift | None = None


def acceleration_residual(problem: Problem, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(a (n,) [rad/s^2], valid (n,) bool): Savitzky-Golay second derivative of r per window."""
    a = np.zeros(problem.n)
    valid = np.zeros(problem.n, dtype=bool)
    for w in range(problem.n_windows):
        i, j = problem.starts[w], problem.starts[w + 1]
        if j - i < 2 * SG_WINDOW:
            continue
        dt = float(np.median(np.diff(problem.t[i:j])))
        a[i:j] = signal.savgol_filter(r[i:j], SG_WINDOW, 2, deriv=2, delta=dt, mode="interp")
        h = SG_WINDOW // 2
        valid[i + h:j - h] = problem.ok[i + h:j - h]
    return a, valid


def axis_values(problem: Problem, x1: np.ndarray, x2: np.ndarray) -> dict[str, np.ndarray]:
    """Each axis at every sample (nan where it does not apply)."""
    on = problem.q > 0
    t_rel = np.concatenate([tr.t - tr.t[0] for tr in problem.trials])
    hv = np.concatenate([hv_time(tr) for tr in problem.trials])
    ratio = problem.base.r / problem.base.L
    return {
        "wheel_angle": np.mod(x1, 2 * math.pi),
        "pivot_angle": np.mod(ratio * x1, 2 * math.pi),
        "contact_angle": np.where(on, x1 - problem.eta * SECTOR, np.nan),
        "actuator": np.where(on, problem.pad.astype(float), np.nan),
        "time": t_rel,
        "hv_time": np.where(on, hv, np.nan),
        "speed": x2.copy(),
        "on_time": np.where(on, problem.on_time, np.nan),
    }


def correlation(x: np.ndarray, y: np.ndarray, max_lag: int) -> np.ndarray:
    """Normalised cross-correlation of x and y (n,) at lags -max_lag..max_lag (FFT)."""
    x = x - x.mean()
    y = y - y.mean()
    n = x.shape[0]
    f = np.fft.rfft(x, 2 * n)
    g = np.fft.rfft(y, 2 * n)
    c = np.fft.irfft(f * np.conj(g), 2 * n)
    full = np.concatenate([c[-max_lag:], c[:max_lag + 1]])
    return full / (np.sqrt((x @ x) * (y @ y)) or 1.0)


def _bins(axis: str, v: np.ndarray, a: np.ndarray, n_bins: int = 24) -> AxisStructure | None:
    unit, period, _ = AXES[axis]
    if v.size < 50 * SG_WINDOW:
        return None
    if axis == "actuator":
        edges = np.arange(N_ACTUATORS + 1) - 0.5
    elif period is not None:
        edges = np.linspace(0.0, period, n_bins + 1)
    else:
        edges = np.unique(np.quantile(v, np.linspace(0, 1, n_bins + 1)))
        if edges.size < 3:
            return None
    idx = np.clip(np.searchsorted(edges, v, side="right") - 1, 0, edges.size - 2)
    k = edges.size - 1
    cnt = np.bincount(idx, minlength=k).astype(float)
    s1 = np.bincount(idx, a, minlength=k)
    s2 = np.bincount(idx, a * a, minlength=k)
    use = cnt > 2 * SG_WINDOW
    if use.sum() < 3:
        return None
    mean = np.where(use, s1 / np.maximum(cnt, 1), np.nan)
    var = np.where(use, s2 / np.maximum(cnt, 1) - mean ** 2, np.nan)
    n_eff = cnt / SG_WINDOW                       # correlated samples: one per filter length
    se = np.sqrt(np.maximum(var, 0) / np.maximum(n_eff, 1))
    grand = np.nansum(s1[use]) / cnt[use].sum()
    between = np.nansum(n_eff[use] * (mean[use] - grand) ** 2) / (use.sum() - 1)
    within = np.nansum(n_eff[use] * var[use]) / max(n_eff[use].sum() - use.sum(), 1)
    F = between / within if within > 0 else 0.0
    p = float(stats.f.sf(F, use.sum() - 1, max(n_eff[use].sum() - use.sum(), 1)))
    centers = 0.5 * (edges[:-1] + edges[1:])
    amp = 0.5 * float(np.nanmax(mean[use]) - np.nanmin(mean[use]))
    return AxisStructure(axis, unit, centers, mean, se, p, amp)


def _scan(x: np.ndarray, a: np.ndarray, freqs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares sinusoid amplitude [rad/s^2] and F statistic at each frequency [1/unit]."""
    a = a - a.mean()
    amp = np.empty(freqs.size)
    fstat = np.empty(freqs.size)
    tot = float(a @ a)
    n_eff = a.size / SG_WINDOW
    for i, f in enumerate(freqs):
        ph = 2 * math.pi * f * x
        c, s = np.cos(ph), np.sin(ph)
        A = np.array([[c @ c, c @ s], [c @ s, s @ s]])
        b = np.array([c @ a, s @ a])
        try:
            coef = np.linalg.solve(A, b)
        except np.linalg.LinAlgError:
            amp[i], fstat[i] = 0.0, 0.0
            continue
        explained = float(coef @ b)
        amp[i] = math.hypot(coef[0], coef[1])
        fstat[i] = (explained / 2) / max((tot - explained) / (n_eff - 2), 1e-300)
    return amp, fstat


def window_defects(problem: Problem, z: np.ndarray, x2: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Continuity defects of the multiple shooting, as mean accelerations.

    Window w+1 starts at the speed the data asks for; window w ends at the speed the model
    carried it to.  Their difference over the window's duration is the mean unmodelled
    acceleration [rad/s^2] over window w: an unmodelled torque tau shows up as its window
    mean / J.  One value per pair of consecutive windows of the same trial is nearly
    independent of the next, and far less noisy than a second derivative of the encoder
    angle.  Defects further than 6 median absolute deviations from the median are dropped
    (a window start caught in a wrong local minimum).

    Returns (a (m,) [rad/s^2], window index w (m,), trial index (m,)).
    """
    x0 = problem.window_starts(z)
    st = problem.starts
    out, wins = [], []
    for w in range(problem.n_windows - 1):
        if problem.window_trial[w] != problem.window_trial[w + 1]:
            continue
        e = int(st[w + 1]) - 1
        if e - 1 < st[w]:
            continue
        predicted = x2[e] + (x2[e] - x2[e - 1])      # one more step, at the last step's rate
        out.append((x0[w + 1, 1] - predicted) / (problem.t[st[w + 1]] - problem.t[st[w]]))
        wins.append(w)
    a = np.asarray(out)
    wins = np.asarray(wins, dtype=np.int64)
    if a.size:
        dev = np.abs(a - np.median(a))
        keep = dev <= 6.0 * 1.4826 * max(float(np.median(dev)), 1e-12)
        a, wins = a[keep], wins[keep]
    return a, wins, problem.window_trial[wins] if wins.size else wins


def scan_setup(problem: Problem, t_rel: np.ndarray, wins: np.ndarray, trial_of: np.ndarray,
               trend: Trend | None) -> tuple[np.ndarray, float]:
    """(nuisance (m, k), fewest cycles per the longest trial's span) for the periodograms of
    the window defects of windows ``wins`` (m,) in trials ``trial_of``.  Without a drift,
    one level per trial from :data:`FEWEST_CYCLES`, so that a slow period (a pivot lap on a
    short or slow trial) is still scanned; with one, :func:`scan_nuisance` from
    :data:`MIN_CYCLES`."""
    if trend is None:
        return (trial_of[:, None] == np.unique(trial_of)[None, :]).astype(float), FEWEST_CYCLES
    return scan_nuisance(problem, t_rel, wins, trial_of), MIN_CYCLES


def scan_nuisance(problem: Problem, t_rel: np.ndarray, wins: np.ndarray,
                  trial_of: np.ndarray) -> np.ndarray:
    """(m, k) what the periodograms fit besides a sinusoid, for the window defects of windows
    ``wins`` (m,) in trials ``trial_of``: each trial's coast its own level, each trial's
    drive a quadratic in time (``t_rel`` (n,) [s] since the trial's start, window means).

    Used when a drift is found (:func:`drive_trend`).  An effect that grows or fades during
    the drive leaves a defect that drifts through it, with a bend where the wheel spins up,
    and the force law's mean misfit shows only while driven, as a step at the coast.  With
    one level per trial, a periodogram takes such a drift for a sinusoid of about one cycle
    per trial.  A slow drift is a trend, not a period.  A quadratic takes up its shape, and
    with it part of a slow sinusoid: at worst 92 % of its variance at one cycle per drive,
    43 % at 1.5, 15 % at 2 and 7 % at 3, hence the scan from :data:`MIN_CYCLES` then.  Tested in
    ``test_ident_residual.py``
    (``test_a_slow_drift_is_not_taken_for_a_period_but_a_real_one_is_found``)."""
    t = window_means(problem, t_rel, wins)
    driven = driven_windows(problem, wins)
    cols = []
    for j in np.unique(trial_of):
        for regime, powers in ((False, (0,)), (True, (0, 1, 2))):
            m = (trial_of == j) & (driven == regime)
            if not m.any():
                continue
            u = (t - t[m].mean()) / max(float(np.ptp(t[m])), 1e-9)
            for k in powers:
                if m.sum() > k:
                    cols.append(np.where(m, u ** k, 0.0))
    return np.column_stack(cols)


def _defect_scan(problem: Problem, x: np.ndarray, a: np.ndarray, wins: np.ndarray,
                 D: np.ndarray, freqs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Amplitude [rad/s^2] and p-value of a sinusoid along ``x`` (n,) in the defects ``a``.

    Each defect is a window mean, so the regressors are the window means of cos and sin of
    2 pi f x (the averaging over a window is then modelled exactly, not ignored), fitted
    together with the nuisance columns D (m, k) (:func:`scan_nuisance`).  F test of the
    sinusoid against the nuisance alone."""
    base_coef, *_ = np.linalg.lstsq(D, a, rcond=None)
    rss0 = float(np.sum((a - D @ base_coef) ** 2))
    n, k = a.size, D.shape[1] + 2
    amp = np.zeros(freqs.size)
    p = np.ones(freqs.size)
    for i, f in enumerate(freqs):
        ph = 2 * math.pi * f * x
        c = window_means(problem, np.cos(ph), wins)
        s = window_means(problem, np.sin(ph), wins)
        if np.sqrt(np.mean(c * c + s * s)) < MIN_WINDOW_GAIN:
            continue        # averaged away within the windows: nothing reliable to say
        X = np.column_stack([D, c, s])
        coef, *_ = np.linalg.lstsq(X, a, rcond=None)
        rss = float(np.sum((a - X @ coef) ** 2))
        amp[i] = math.hypot(coef[-2], coef[-1])
        if n > k and rss > 0:
            F = ((rss0 - rss) / 2) / (rss / (n - k))
            p[i] = float(stats.f.sf(F, 2, n - k))
    return amp, p


def window_means(problem: Problem, v: np.ndarray, wins: np.ndarray) -> np.ndarray:
    """(m,) the mean of ``v`` (n,) over each of the windows ``wins`` (m,) of ``problem``; its
    non-finite samples are left out (NaN for a window that has none)."""
    st = problem.starts
    ok = np.isfinite(v)
    if ok.all():
        return np.add.reduceat(v, st[:-1])[wins] / np.diff(st)[wins]
    num = np.add.reduceat(np.where(ok, v, 0.0), st[:-1])[wins]
    cnt = np.add.reduceat(ok.astype(float), st[:-1])[wins]
    return np.where(cnt > 0, num / np.maximum(cnt, 1.0), np.nan)


def driven_windows(problem: Problem, wins: np.ndarray) -> np.ndarray:
    """(m,) bool: which of the windows ``wins`` (m,) are driven, an actuator on for at least
    :data:`DRIVEN_SHARE` of their samples."""
    return window_means(problem, problem.q, wins) >= DRIVEN_SHARE


def drive_trend(problem: Problem, axes: dict[str, np.ndarray], a: np.ndarray,
                wins: np.ndarray, trial_of: np.ndarray) -> Trend | None:
    """A steady change of the window defects ``a`` (m,) [rad/s^2] (of windows ``wins``, in
    trials ``trial_of``) during the drive, or None.

    An effect that grows or fades as the wheel is driven (force lost to retained charge, to a
    slower rise at higher speed, to a sagging supply) leaves the nominal fit a defect that
    drifts through each drive: the fitted force law takes up its mean, not its change.  A
    periodogram sees such a drift as a sinusoid of about one cycle per trial, a period that
    names nothing.  So, over the driven windows (an actuator on for at least
    :data:`DRIVEN_SHARE` of the samples; the coast has no force to lose), the defects are
    regressed on each axis of :data:`TREND_AXES` (window means), with one intercept per
    trial, one common slope and one common bend (the axis squared, apart from the line: a
    drift need not be straight, e.g. where the wheel spins up), and F-tested (2 dof)
    against the intercepts alone.  The axis with the smallest p-value is taken when
    p < :data:`TREND_SIGNIFICANCE` and half the fitted curve's largest range within a trial
    reaches :data:`MIN_AMPLITUDE`; its p-value is the smallest of the three, times three
    (Bonferroni).  ``slope`` is the line's.  The other axes' correlations with it within the
    trials say whether the data could tell them apart.  The axis that fits best need not
    be the cause: the fitted force law's speed term takes up the part of a missing torque
    that follows the speed.  None when there is no such trend."""
    if wins.size == 0:
        return None
    driven = driven_windows(problem, wins)
    trials = np.unique(trial_of[driven])
    D = (trial_of[driven][:, None] == trials[None, :]).astype(float)
    y = a[driven]
    n = y.size
    if n < D.shape[1] + 10:
        return None
    r0 = y - D @ np.linalg.lstsq(D, y, rcond=None)[0]
    rss0 = float(r0 @ r0)
    fits: dict[str, tuple[float, float, float, np.ndarray]] = {}
    for name in TREND_AXES:
        x = window_means(problem, axes[name], wins)[driven]
        if not np.all(np.isfinite(x)):
            continue
        xc = x - D @ np.linalg.lstsq(D, x, rcond=None)[0]      # within each trial
        sxx = float(xc @ xc)
        if sxx <= 0.0:
            continue
        # the bend: the square of the axis, within each trial and apart from the line
        q = (xc / math.sqrt(sxx / n)) ** 2
        qc = q - D @ np.linalg.lstsq(D, q, rcond=None)[0]
        qc -= xc * float(xc @ qc) / sxx
        sqq = float(qc @ qc)
        slope = float(xc @ r0) / sxx
        bend = float(qc @ r0) / sqq if sqq > 1e-12 * n else 0.0
        curve = slope * xc + bend * qc
        dof = n - D.shape[1] - 2
        rss = rss0 - float(curve @ curve)
        if not rss > 0.0 or dof < 1:
            continue
        F = ((rss0 - rss) / 2) / (rss / dof)
        tj = trial_of[driven]
        amp = 0.5 * max(float(np.ptp(curve[tj == j])) for j in trials)
        fits[name] = (slope, float(stats.f.sf(F, 2, dof)), amp, xc)
    if not fits:
        return None
    best = min(fits, key=lambda k: fits[k][1])
    slope, p, amp, xc = fits[best]
    p = min(len(TREND_AXES) * p, 1.0)
    if not (p < TREND_SIGNIFICANCE and amp >= MIN_AMPLITUDE):
        return None
    corr = {k: float(xc @ v[3] / math.sqrt((xc @ xc) * (v[3] @ v[3])))
            for k, v in fits.items() if k != best}
    return Trend(best, AXES[best][0], slope, amp, p, {k: v[1] for k, v in fits.items()},
                 corr)


def correlated_share(acf: np.ndarray, n: int) -> tuple[float, float]:
    """(mean, sd): the mean of a normalised autocorrelation ``acf`` (L + 1,) over lags 1..L
    [1], and its standard deviation for a white residual of n samples, 1 / sqrt(n L) (the
    lags of white noise are nearly independent, each with sd 1 / sqrt(n)).  For an AR(1)
    residual with coefficient phi the mean is phi (1 - phi^L) / ((1 - phi) L)."""
    lags = acf.shape[0] - 1
    if lags < 1:
        raise ValueError(f"acf needs lags 0..L with L >= 1, got {acf.shape[0]} value(s)")
    return float(np.mean(acf[1:])), 1.0 / math.sqrt(max(n, 1) * lags)


def analyse(problem: Problem, result: FitResult, max_lag: int = 60) -> Diagnostics:
    """Diagnostics of ``result`` (a fit of ``problem``)."""
    x1, x2 = problem.simulate(result.z)
    x1, x2 = x1.copy(), x2.copy()
    ok = problem.ok
    # the plain difference from the readings (not the distance from the encoder's count
    # intervals that the fit minimises): its structure is what a user can plot and check
    r = np.where(ok, problem.readings(result.z, x1) - problem.y, 0.0)
    a, valid = acceleration_residual(problem, r)
    band = 2.576 / math.sqrt(max(ok.sum(), 1))
    acf = correlation(r[ok], r[ok], max_lag)[max_lag:]
    share, share_sd = correlated_share(acf, int(ok.sum()))
    ccf = correlation(r[ok], problem.q[ok], max_lag)
    lags = np.arange(-max_lag, max_lag + 1)
    diag = Diagnostics(
        rms_angle=float(np.sqrt(np.mean(r[ok] ** 2))),
        rms_accel=float(np.sqrt(np.mean(a[valid] ** 2))) if valid.any() else math.nan,
        acf_lags=np.arange(max_lag + 1), acf=acf, ccf_lags=lags, ccf_q=ccf, band99=band,
        whiteness_outside=float(np.mean(np.abs(acf[1:]) > band)),
        correlated_share=share, correlated_share_sd=share_sd,
        max_lag_s=max_lag * float(np.median(np.diff(problem.t))), window_s=problem.window,
        input_correlation_max=float(np.max(np.abs(ccf))), accel=a, mask=valid)
    axes = axis_values(problem, x1, x2)
    diag.axes = axes
    inertia = problem.base.inertia
    for name, v in axes.items():
        m = valid & np.isfinite(v)
        st = _bins(name, v[m], a[m])
        if st is not None:
            diag.structures[name] = st
    # periodograms of the window defects: along the unwrapped wheel angle and along time
    L_over_r = problem.base.L / problem.base.r
    acc, wins, trial_of = window_defects(problem, result.z, x2)
    diag.defects = acc
    if acc.size >= 20:
        diag.trend = drive_trend(problem, axes, acc, wins, trial_of)
        diag.session = session_drift(problem.trials, acc, trial_of, TREND_SIGNIFICANCE,
                                     MIN_AMPLITUDE)
        nuisance, cycles = scan_setup(problem, axes["time"], wins, trial_of, diag.trend)
        span = max(float(np.ptp(x1[problem.trial_slices[i]]))
                   for i in range(len(problem.trials)))
        duration = max(tr.duration for tr in problem.trials)
        for axis, x, fmax, res in (("wheel_angle_unwrapped", x1, 1.0, span),
                                   ("time", axes["time"], 0.45, duration)):
            step = 1.0 / (4.0 * res)
            freqs = np.arange(cycles / res, fmax, step)
            amp, p = _defect_scan(problem, x, acc, wins, nuisance, freqs)
            diag.spectra[axis] = (freqs, amp)
            order = np.argsort(p)
            taken: list[float] = []
            for i in order[:50]:
                if p[i] > SIGNIFICANCE or amp[i] < MIN_AMPLITUDE:
                    break
                f = freqs[i]
                if any(abs(f - g) < 8 * step for g in taken):   # within 2 resolution widths
                    continue
                taken.append(f)
                period = 1.0 / f
                turn = 2 * math.pi / period if axis != "time" else math.nan
                lap = 2 * math.pi * L_over_r / period if axis != "time" else math.nan
                diag.peaks.append(Peak(axis, period, float(amp[i]), float(p[i]), turn, lap))
                if len(taken) >= 3:
                    break
    diag.signatures = signatures(diag, inertia)
    return diag


def signatures(diag: Diagnostics, inertia: float) -> list[Signature]:
    """The significant structure in words: periodic peaks first, then binned axes."""
    out: list[Signature] = []
    for pk in diag.peaks:
        if pk.axis == "time":
            text = (f"periodic in time with period {pk.period:.3g} s, amplitude "
                    f"{pk.amplitude:.3g} rad/s^2 ({pk.amplitude * inertia:.2g} N*m)")
            out.append(Signature("time", "s", pk.period, pk.amplitude, pk.amplitude * inertia,
                                 pk.p_value, text))
            continue
        turns = pk.per_wheel_turn
        laps = pk.per_pivot_lap
        if abs(laps - round(laps)) < 0.05 and round(laps) >= 1 and \
                abs(turns - round(turns)) > 0.05:
            axis, unit, period = "pivot_angle", "rad", 2 * math.pi / round(laps)
            what = f"{round(laps)} per pivot lap"
        elif abs(turns - round(turns)) < 0.05 and round(turns) >= 1:
            axis, unit, period = "wheel_angle", "rad", 2 * math.pi / round(turns)
            what = f"{round(turns)} per wheel turn"
        else:
            axis, unit, period = "wheel_angle_unwrapped", "rad", pk.period
            what = f"{turns:.3g} per wheel turn, {laps:.3g} per pivot lap"
        text = (f"periodic in {axis.replace('_', ' ')} with period {period:.4g} rad "
                f"({what}; {pk.period:.4g} rad of wheel angle), amplitude {pk.amplitude:.3g} "
                f"rad/s^2 ({pk.amplitude * inertia:.2g} N*m)")
        out.append(Signature(axis, unit, period, pk.amplitude, pk.amplitude * inertia,
                             pk.p_value, text))
    # several peaks that name the same period (leakage around one line) are one signature:
    # keep the strongest (peaks come strongest first)
    unique: list[Signature] = []
    for sig in out:
        if not any(u.axis == sig.axis and u.period is not None and sig.period is not None and
                   abs(u.period - sig.period) <= 0.02 * u.period for u in unique):
            unique.append(sig)
    out = unique
    periodic_axes = {s.axis for s in out}
    if diag.trend is not None:
        out.append(trend_signature(diag.trend, inertia))
    if diag.session is not None:
        ses = diag.session
        half = 0.5 * abs(ses.change)
        out.append(Signature(ses.axis, SESSION_AXES[ses.axis][0], None, half, half * inertia,
                             ses.p, ses.text(inertia)))
    described = {s.axis for s in out}
    for name, st in diag.structures.items():
        if st.p_value > SIGNIFICANCE or st.amplitude < MIN_AMPLITUDE or name in described:
            continue
        if AXES[name][1] is not None and periodic_axes:
            continue                      # a periodic axis already described by a peak
        text = (f"varies with {name.replace('_', ' ')} [{st.unit}]: bin means span "
                f"+-{st.amplitude:.3g} rad/s^2 ({st.amplitude * inertia:.2g} N*m), "
                f"p = {st.p_value:.1e}")
        out.append(Signature(name, st.unit, None, st.amplitude, st.amplitude * inertia,
                             st.p_value, text))
    if not out:
        sig = autocorrelation_signature(diag, inertia)
        if sig is not None:
            out.append(sig)
    return out


#: Each axis of :data:`TREND_AXES` in words.
TREND_LABEL = {"time": "time since the trial's start",
               "hv_time": "accumulated HV on-time of the driven actuator", "speed": "speed"}


def trend_signature(tr: Trend, inertia: float) -> Signature:
    """The drive trend ``tr`` in words, as a signature along its axis (not periodic);
    ``inertia`` [kg*m^2] (J/L) turns accelerations into torques."""
    label = TREND_LABEL
    what = "grows" if tr.slope > 0 else "falls"
    text = (f"drifts during each drive: the unmodelled acceleration changes along "
            f"{label[tr.axis]}, +-{tr.amplitude:.3g} rad/s^2 ({tr.amplitude * inertia:.2g} N*m) "
            f"over the drives (a line and a bend), p = {tr.p_value:.1e}; its straight part "
            f"{what} by {abs(tr.slope):.3g} rad/s^2 per {tr.unit} "
            f"({abs(tr.slope) * inertia:.2g} N*m per {tr.unit})")
    others = [f"{label[k]} p = {tr.p_values[k]:.1e} (r = {c:+.2f} with it within the trials)"
              for k, c in tr.correlations.items()]
    if others:
        text += "; against " + ", ".join(others)
    alike = [label[k] for k, c in tr.correlations.items() if abs(c) > 0.9]
    if alike:
        text += (f": {' and '.join(alike)} rose with it in these trials, so the data cannot "
                 f"tell which of them the change follows")
    return Signature(tr.axis, tr.unit, None, tr.amplitude, tr.amplitude * inertia,
                     tr.p_value, text, drift=True)


def along_p(tr: Trend, axis: str) -> float:
    """The p-value of the trend ``tr`` along ``axis``, adjusted as the trend's own is for
    the :data:`TREND_AXES` tried (x their number, at most 1); 1 where that axis got no fit."""
    return min(len(TREND_AXES) * tr.p_values.get(axis, 1.0), 1.0)


def drift_along(sig: Signature, tr: Trend, axis: str, because: str) -> None:
    """Report the drift ``sig`` (the signature of the trend ``tr``) along ``axis`` (one of
    :data:`TREND_AXES`) in place of the axis the regression read, for the reason
    ``because`` (words): its unit and p-value (:func:`along_p`) become that axis's, and its
    text says so.  Its amplitude and torque stay those of the curve fitted along the axis
    the regression read.  Changed in place."""
    p = along_p(tr, axis)
    sig.text += (f"; reported along {TREND_LABEL[axis]} (p = {p:.1e}), not "
                 f"{TREND_LABEL[sig.axis]}, which the regression alone read (its size above "
                 f"is along that axis): {because}")
    sig.axis, sig.unit, sig.p_value = axis, AXES[axis][0], p


def autocorrelation_signature(diag: Diagnostics, inertia: float) -> Signature | None:
    """A residual that is not white although no axis shows structure, or None.

    The windows re-start the model from fitted states every ``window`` seconds, and a
    force law fitted freely can take up an effect the model lacks within each of them: the
    bins and spectra then find nothing, while the angle residual stays correlated from one
    sample to the next, and the free run drifts.  The mean autocorrelation over lags of up
    to 0.2 s is the measure: counted when above ``CORRELATED_SHARE`` [1] and five standard
    deviations of a white residual's (the evidence is in docs/identification.md).  The
    fraction of lags outside the 99 % band is no use for this: it grows with the length of
    the data for the right model too.  Tested in ``test_ident_residual.py``
    (``test_a_correlated_residual_without_structure_gets_a_signature_a_white_one_none``).

    Its size is given as an equivalent acceleration [rad/s^2]: the constant acceleration
    error a that, in a window of length T re-started from a fitted angle and speed, leaves
    a residual of RMS a T^2 / (2 sqrt(180)) (a t^2 / 2 less its best straight line), equal
    to the correlated part's RMS sqrt(share) x RMS(residual).  Below ``MIN_AMPLITUDE`` it is
    not reported: exact data (no encoder) leave a residual of ~1e-7 rad that is correlated
    only through the integrators' own differences.  ``inertia`` [kg*m^2] (J/L) turns it
    into a torque.  The equivalence assumes the correlated part stays correlated over the
    lags (a window-long shape does, roughly), so it is a lower bound rather than a
    measurement; and the p-value uses the white residual's sd, so it says only that the
    residual is not white, not how strongly.  The mean runs over the residual of all
    windows and trials joined end to end."""
    m, sd = diag.correlated_share, diag.correlated_share_sd
    if not (m > CORRELATED_SHARE and m > 5.0 * sd):
        return None
    amp = 2.0 * math.sqrt(180.0) * math.sqrt(m) * diag.rms_angle / diag.window_s ** 2
    if not amp >= MIN_AMPLITUDE:
        return None
    text = (f"not white, with no structure on any axis: on average {100 * m:.1f} % of the "
            f"residual's variance is correlated over lags of up to {diag.max_lag_s:.2g} s "
            f"(white: 0 +- {100 * sd:.2f} %), as much as a constant acceleration error of "
            f"{amp:.3g} rad/s^2 ({amp * inertia:.2g} N*m) in each {diag.window_s:.3g} s window "
            f"leaves; an effect the model lacks, taken up within each window by the fitted "
            f"force law")
    return Signature("autocorrelation", "s", None, amp, amp * inertia,
                     float(stats.norm.sf(m / sd)), text)
