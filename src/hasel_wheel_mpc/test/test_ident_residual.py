"""Whiteness of the residual: the mean autocorrelation against its closed form, and the
signature a correlated residual gets when no axis shows structure (ident/residual.py)."""
import math
import re

import numpy as np
import pytest
from scipy import signal

from hasel_wheel_mpc.ident import residual as R


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
