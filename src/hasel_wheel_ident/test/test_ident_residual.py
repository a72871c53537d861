"""Whiteness of the residual: the mean autocorrelation against its closed form, and the
signature a correlated residual gets when no axis shows structure (ident/residual.py)."""
import dataclasses
import math
import re

import numpy as np
import pytest
from scipy import signal

from hasel_wheel_ident import residual as R
from hasel_wheel_ident.unexplained import device_axis


def _ar1(phi: float, n: int, seed: int = 0) -> np.ndarray:
    e = np.random.default_rng(seed).standard_normal(n)
    return signal.lfilter([1.0], [1.0, -phi], e)


def _diagnostics(r: np.ndarray, max_lag: int = 60, dt: float = 1 / 300,
                 window: float = 1.0) -> R.Diagnostics:
    acf = R.correlation(r, r, max_lag)[max_lag:]
    share, sd = R.correlated_share(acf, r.size)
    return R.Diagnostics(rms_angle=float(np.sqrt(np.mean(r ** 2))), rms_accel=math.nan,
                         acf_lags=np.arange(max_lag + 1), acf=acf, ccf_lags=np.arange(1),
                         ccf_q=np.zeros(1), band99=2.576 / math.sqrt(r.size),
                         whiteness_outside=0.0, input_correlation_max=0.0,
                         correlated_share=share, correlated_share_sd=sd,
                         max_lag_s=max_lag * dt, window_s=window)


@pytest.mark.parametrize("phi, tol", [(0.0, 5e-4), (0.3, 8e-4), (0.5, 1.2e-3), (0.9, 5e-3)])
def test_the_mean_autocorrelation_of_an_ar1_residual_matches_its_closed_form(phi, tol):
    # phi (1 - phi^L) / ((1 - phi) L), averaged over 8 series of 400,000 samples; the
    # tolerance is about 5 standard deviations of that average (the lags of an AR(1)
    # series are correlated, so its sd is several times a white series' 1/sqrt(nL))
    n, lags = 400_000, 60
    got = np.mean([R.correlated_share(R.correlation(x, x, lags)[lags:], n)[0]
                   for x in (_ar1(phi, n, seed) for seed in range(8))])
    assert got == pytest.approx(phi * (1 - phi ** lags) / ((1 - phi) * lags), abs=tol)


def test_a_correlated_residual_without_structure_gets_a_signature_a_white_one_none():
    # mean acf over 60 lags: phi = 0.5 -> 1/60 = 0.0167 (above CORRELATED_SHARE = 0.01);
    # phi = 0.3 -> 0.3 / (0.7 * 60) = 0.0071 (below); white -> 0
    n = 100_000
    white = np.random.default_rng(1).standard_normal(n)
    assert R.autocorrelation_signature(_diagnostics(white), 1.0) is None
    assert R.autocorrelation_signature(_diagnostics(_ar1(0.3, n)), 1.0) is None
    sig = R.autocorrelation_signature(_diagnostics(_ar1(0.5, n)), 1.0)
    assert sig is not None and sig.axis == "autocorrelation" and sig.period is None
    share = re.search(r"on average ([\d.]+) % of the residual's variance is correlated over "
                      r"lags of up to 0.2 s", sig.text)
    assert share and float(share[1]) == pytest.approx(100 / 60, abs=0.25)
    # as correlated but far too small to matter (exact data: integrator differences)
    assert R.autocorrelation_signature(_diagnostics(1e-7 * _ar1(0.5, n)), 1.0) is None
    # the same correlation on too few samples to tell it from white is not reported
    assert R.autocorrelation_signature(_diagnostics(_ar1(0.5, 200)), 1.0) is None


def test_a_constant_acceleration_error_per_window_is_sized_from_the_correlation():
    # a residual that a missing constant acceleration a leaves in 1 s windows re-started
    # from fitted angle and speed: a t^2 / 2 less its least-squares line, RMS a / (2
    # sqrt(180)) = 1.04 mrad at a = 0.028 rad/s^2, plus 1 mrad of white noise.  The
    # signature reads the correlated part's RMS as sqrt(mean acf) x RMS: a lower bound,
    # since the window-long shape decorrelates a little over 0.2 s (here it reads 0.84 a)
    a, per_window, windows = 0.028, 300, 200
    t = np.arange(per_window) / per_window
    shape = 0.5 * a * t ** 2
    shape -= np.polyval(np.polyfit(t, shape, 1), t)
    assert np.sqrt(np.mean(shape ** 2)) == pytest.approx(a / (2 * math.sqrt(180)), rel=1e-2)
    r = np.tile(shape, windows) + 1e-3 * np.random.default_rng(2).standard_normal(
        per_window * windows)
    sig = R.autocorrelation_signature(_diagnostics(r), 0.0357)
    assert sig is not None
    assert 0.75 * a < sig.amplitude <= a
    assert sig.torque == pytest.approx(0.0357 * sig.amplitude)


def test_correlated_share_needs_lags():
    with pytest.raises(ValueError, match="acf needs lags 0..L with L >= 1"):
        R.correlated_share(np.ones(1), 100)


@pytest.fixture(scope="module")
def windows():
    """A problem on three clean plant trials (3 x 34 s), its windows as the defects see
    them (all but each trial's last), and the trend axes from the data."""
    from hasel_wheel_ident import synthetic as S
    from hasel_wheel_ident.data import hv_time
    from hasel_wheel_ident.fit import Problem
    prob = Problem(S.encoder_trials({}, seed=5))
    wins = np.array([w for w in range(prob.n_windows - 1)
                     if prob.window_trial[w] == prob.window_trial[w + 1]])
    hv = np.concatenate([hv_time(tr) for tr in prob.trials])
    axes = {"time": np.concatenate([tr.t - tr.t[0] for tr in prob.trials]),
            "hv_time": np.where(prob.q > 0, hv, np.nan),
            "speed": np.gradient(prob.y, prob.t)}
    return prob, wins, prob.window_trial[wins], axes


def _window_mean(prob, wins, v):
    ok = np.isfinite(v)
    num = np.add.reduceat(np.where(ok, v, 0.0), prob.starts[:-1])[wins]
    cnt = np.add.reduceat(ok.astype(float), prob.starts[:-1])[wins]
    return np.where(cnt > 0, num / np.maximum(cnt, 1.0), np.nan)   # nan: never on


def test_a_drift_with_hv_time_is_found_with_its_slope_and_white_defects_give_none(windows):
    prob, wins, trial_of, axes = windows
    rng = np.random.default_rng(1)
    driven = R.driven_windows(prob, wins)
    assert 0.6 < driven.mean() < 0.9          # 25 s driven and 9 s coasting per trial
    hv = np.nan_to_num(_window_mean(prob, wins, axes["hv_time"]))
    level = np.array([0.01, -0.02, 0.005])[trial_of]
    slope, noise = -0.03, 0.002                 # [rad/s^2 per s], [rad/s^2]
    a = level + np.where(driven, slope * hv, 0.0) + noise * rng.standard_normal(wins.size)
    tr = R.drive_trend(prob, axes, a, wins, trial_of)
    assert tr is not None and tr.axis == "hv_time" and tr.unit == "s"
    # least squares with one level per trial: the slope within a few of its standard errors
    x = hv[driven]
    xc = x - np.array([x[trial_of[driven] == j].mean() for j in trial_of[driven]])
    assert tr.slope == pytest.approx(slope, abs=4 * noise / math.sqrt(xc @ xc))
    assert tr.p_value < 1e-10
    # half the change that the true slope makes over the driven windows' HV times
    assert tr.amplitude == pytest.approx(0.5 * abs(slope) * np.ptp(x), rel=0.05)
    # time since the start rises with the HV time in these trials: said, not hidden
    assert tr.correlations["time"] > 0.9
    sig = R.trend_signature(tr, 0.0357)
    assert sig.period is None and sig.axis == "hv_time" and "falls" in sig.text
    assert "cannot tell" in sig.text
    assert R.drive_trend(prob, axes, level + noise * rng.standard_normal(wins.size), wins,
                         trial_of) is None


def test_a_drift_reported_along_another_axis_takes_that_axis_unit_and_p_value():
    # the trend's own p is adjusted for the three axes tried (3 x 8e-19); the new axis's is
    # adjusted the same way (3 x 3e-9), and an axis that got no fit reads 1
    tr = R.Trend("speed", "rad/s", -0.004, 0.015, 2.4e-18,
                 {"speed": 8e-19, "time": 1e-11, "hv_time": 3e-9}, {"time": 0.9, "hv_time": 0.9})
    assert R.along_p(tr, "hv_time") == pytest.approx(9e-9, rel=1e-12)
    assert R.along_p(dataclasses.replace(tr, p_values={"speed": 8e-19}), "hv_time") == 1.0
    sig = R.trend_signature(tr, 0.0357)
    assert (sig.axis, sig.unit, sig.p_value) == ("speed", "rad/s", 2.4e-18)
    amplitude = sig.amplitude
    R.drift_along(sig, tr, "hv_time", "a reason")
    assert (sig.axis, sig.unit) == ("hv_time", "s") and sig.drift
    assert sig.p_value == pytest.approx(9e-9, rel=1e-12) and sig.amplitude == amplitude
    assert sig.text.endswith("; reported along accumulated HV on-time of the driven actuator "
                             "(p = 9.0e-09), not speed, which the regression alone read (its "
                             "size above is along that axis): a reason")


@pytest.mark.parametrize("hv_p, errors, moved", [
    (3e-9, (0.0345, 0.0633), "hv_time"),   # the HV-time loss leads, HV time shows the drift
    (5e-5, (0.0345, 0.0633), None),        # HV time's adjusted p 1.5e-4: not significant
    (3e-9, (0.0633, 0.0345), None),        # the switch-on lag leads: speed, already the axis
    (3e-9, (0.0345, 0.0350), None)])       # no device leads by 5 %
def test_a_drift_moves_to_the_axis_of_the_leading_device_only_where_that_axis_shows_it(
        hv_p, errors, moved):
    tr = R.Trend("speed", "rad/s", -0.004, 0.015, 2.4e-18,
                 {"speed": 8e-19, "time": 1e-11, "hv_time": hv_p}, {"time": 0.9, "hv_time": 0.9})
    sig = R.trend_signature(tr, 0.0357)
    sig.devices = {k: {"sim_rmse_rad_s": e, "sim_rmse_model_rad_s": 0.0765}
                   for k, e in zip(("hv_loss", "on_lag"), errors)}
    assert device_axis(sig, tr, min_gain=0.1) == moved
    assert device_axis(sig, None, min_gain=0.1) is None


def test_a_slow_drift_is_not_taken_for_a_period_but_a_real_one_is_found(windows):
    prob, wins, trial_of, axes = windows
    rng = np.random.default_rng(2)
    t = _window_mean(prob, wins, axes["time"])
    driven = R.driven_windows(prob, wins)
    drive = np.array([t[(trial_of == j) & driven].max() for j in range(3)])[trial_of]
    # a drift that bends where the wheel spins up and falls through the drive, then a step
    # at the coast: the shape charge retention leaves in a nominal fit
    u = t / drive
    drift = np.where(driven, 0.03 * np.sin(1.3 * math.pi * u) - 0.02 * u, 0.001)
    a = drift + 0.002 * rng.standard_normal(wins.size)
    duration = max(tr.duration for tr in prob.trials)
    freqs = np.arange(R.MIN_CYCLES / duration, 0.45, 1 / (4 * duration))
    D = R.scan_nuisance(prob, axes["time"], wins, trial_of)
    _, p = R._defect_scan(prob, axes["time"], a, wins, D, freqs)
    assert p.min() > R.SIGNIFICANCE
    # one level per trial and the scan from 1.5 cycles, as before: the drift reads as a
    # period of about one cycle per trial
    levels = (trial_of[:, None] == np.arange(3)[None, :]).astype(float)
    slow = np.arange(1.5 / duration, 0.45, 1 / (4 * duration))
    _, p_old = R._defect_scan(prob, axes["time"], a, wins, levels, slow)
    assert p_old.min() < R.SIGNIFICANCE and 1 / slow[np.argmin(p_old)] > duration / 3
    # a real periodic torque of period 5 s on top is found, at its size
    f0 = 0.2
    ripple = 0.01 * np.add.reduceat(np.sin(2 * math.pi * f0 * axes["time"]),
                                    prob.starts[:-1])[wins] / np.diff(prob.starts)[wins]
    amp, p2 = R._defect_scan(prob, axes["time"], a + ripple, wins, D, freqs)
    i = int(np.argmin(p2))
    assert p2[i] < R.SIGNIFICANCE and abs(freqs[i] - f0) <= 1 / (4 * duration)
    assert amp[i] == pytest.approx(0.01, rel=0.15)


def test_a_drift_does_not_hide_structure_binned_against_an_angle():
    # a drift is not periodic: binned structure against the pivot angle (no periodogram
    # peak describes it) is still reported beside it
    diag = _diagnostics(np.random.default_rng(3).standard_normal(5000))
    diag.structures["pivot_angle"] = R.AxisStructure("pivot_angle", "rad", np.zeros(3),
                                                     np.zeros(3), np.zeros(3), 1e-12, 0.05)
    assert [s.axis for s in R.signatures(diag, 1.0)] == ["pivot_angle"]
    diag.trend = R.Trend("hv_time", "s", -0.03, 0.02, 1e-8, {"hv_time": 1e-8}, {})
    assert [s.axis for s in R.signatures(diag, 1.0)] == ["hv_time", "pivot_angle"]


def test_without_a_drift_the_scans_keep_one_level_per_trial_and_slow_periods(windows):
    # (FEWEST_CYCLES: a pivot lap of 25.66 rad on trials spanning 51 rad or more)
    prob, wins, trial_of, axes = windows
    D, cycles = R.scan_setup(prob, axes["time"], wins, trial_of, None)
    assert cycles == R.FEWEST_CYCLES and D.shape == (wins.size, 3)
    assert np.array_equal(D.argmax(axis=1), trial_of)
    # a period of 2.5 cycles per trial is scanned and found, at its size
    duration = max(tr.duration for tr in prob.trials)
    f0 = 2.5 / duration
    ripple = 0.01 * np.add.reduceat(np.sin(2 * math.pi * f0 * axes["time"]),
                                    prob.starts[:-1])[wins] / np.diff(prob.starts)[wins]
    a = ripple + 0.002 * np.random.default_rng(4).standard_normal(wins.size)
    freqs = np.arange(cycles / duration, 0.45, 1 / (4 * duration))
    amp, p = R._defect_scan(prob, axes["time"], a, wins, D, freqs)
    i = int(np.argmin(p))
    assert p[i] < R.SIGNIFICANCE and abs(freqs[i] - f0) <= 1 / (4 * duration)
    assert amp[i] == pytest.approx(0.01, rel=0.15)
    # with a drift, the drive's quadratic and the coast's level, from MIN_CYCLES
    trend = R.Trend("time", "s", -0.001, 0.01, 1e-8, {"time": 1e-8}, {})
    D2, cycles2 = R.scan_setup(prob, axes["time"], wins, trial_of, trend)
    assert cycles2 == R.MIN_CYCLES
    assert D2.shape[1] == 3 * (1 + 3)          # each trial: a coast level, a drive quadratic
    # any quadratic drift through each drive, with its own level in each coast, lies in the
    # nuisance's span: nothing of it is left for a sinusoid to take
    t = _window_mean(prob, wins, axes["time"])
    driven = R.driven_windows(prob, wins)
    coef = np.array([[0.01, -0.002, 3e-5], [-0.02, 0.001, -4e-5], [0.005, 0.0, 2e-5]])
    drift = np.where(driven, coef[trial_of, 0] + coef[trial_of, 1] * t
                     + coef[trial_of, 2] * t ** 2, np.array([0.001, -0.003, 0.002])[trial_of])
    left = drift - D2 @ np.linalg.lstsq(D2, drift, rcond=None)[0]
    assert np.max(np.abs(left)) < 1e-12 * np.max(np.abs(drift)) + 1e-15
    # with one level per trial, most of it is left
    left1 = drift - D @ np.linalg.lstsq(D, drift, rcond=None)[0]
    assert np.linalg.norm(left1) > 0.5 * np.linalg.norm(drift - drift.mean())


def test_a_period_is_confirmed_by_its_refits_wald_test_against_the_closed_form():
    from hasel_wheel_ident.fit import FitResult
    from hasel_wheel_ident.periodic import confirmed, sized
    from hasel_wheel_sim.params import WheelParams
    base = WheelParams()
    sig = R.Signature("wheel_angle", "rad", 2 * math.pi, 0.02, 0.0007, 1e-9,
                      "periodic in wheel angle with period 6.283 rad, amplitude 0.02 rad/s^2")
    assert confirmed(sig)                                   # sized from the residual alone

    def refit(p, q, sd):
        return FitResult(["P_sig", "Q_sig"], ["N*m", "N*m"], np.array([p, q]),
                         np.array([p, q]), np.diag([sd * sd, sd * sd]), 1e-3, {}, 10, True,
                         "", 1.0, values={"P_sig": p, "Q_sig": q})

    # 2 dof: chi^2 = (P^2 + Q^2) / sd^2, p = exp(-chi^2 / 2)
    for p, q, sd in ((0.003, 0.004, 0.001), (0.0003, 0.0004, 0.0001), (0.0002, 0.0, 0.0001)):
        out = sized(sig, refit(p, q, sd), 1.0, base)
        chi2 = (p * p + q * q) / (sd * sd)
        assert out.p_value == pytest.approx(math.exp(-chi2 / 2), rel=1e-9)
        assert out.torque == pytest.approx(math.hypot(p, q))
        assert out.amplitude == pytest.approx(math.hypot(p, q) / base.inertia)
        assert out.torque_ci95 == pytest.approx((max(math.hypot(p, q) - 1.96 * sd, 0.0),
                                                 math.hypot(p, q) + 1.96 * sd))
    # confirmed only when significant (p < 1e-6) and above the reporting floor
    big = sized(sig, refit(0.003, 0.004, 0.001), 1.0, base)         # chi^2 25, p 3.7e-6
    assert not confirmed(big)
    clear = sized(sig, refit(0.003, 0.004, 0.0005), 1.0, base)      # chi^2 100
    assert clear.amplitude >= R.MIN_AMPLITUDE and confirmed(clear)
    tiny = sized(sig, refit(0.00003, 0.00004, 0.000001), 1.0, base)  # significant, tiny
    assert tiny.p_value < 1e-100 and tiny.amplitude < R.MIN_AMPLITUDE and not confirmed(tiny)
