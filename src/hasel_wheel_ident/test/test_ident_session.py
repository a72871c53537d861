"""Trials as a session: order, gaps and carried switching (session.py), session time in
CSVs and bags (data.py), friction per coast-down and its trend (friction_trend.py), a pad's
gain step between trials (steps.py).  Numbers from closed forms and known values; the
identification of whole sessions is in test_ident_session_verdicts.py (slow)."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from hasel_wheel_ident import session as S
from hasel_wheel_ident.consistency import Consistency
from hasel_wheel_ident.data import Trial, TrialError, hv_time, read_csv, write_csv
from hasel_wheel_ident.friction_trend import CoastFriction, along_the_trend, friction_trend
from hasel_wheel_ident.session_trend import SESSION_AXES, session_drift
from hasel_wheel_ident.simulate import retention_charge
from hasel_wheel_ident.steps import MIN_STEP, gain_step, latest_gains

DT = 1.0 / 300.0


def _trial(name: str, q: np.ndarray, eta: np.ndarray, start: float | None = None,
           t0: float = 0.0, speed: float = 1.0) -> Trial:
    """A trial of len(q) samples at 300 Hz rolling at ``speed`` [rad/s], pad ``eta`` driven
    where q = 1 (scheduled throughout)."""
    n = q.shape[0]
    t = t0 + DT * np.arange(n)
    angle = speed * (t - t0) + eta * math.pi / 8
    sched = np.where(q > 0, eta, 0)
    return Trial(name, t, angle, q.astype(np.int8), eta.astype(np.int64), sched.astype(np.int64),
                 np.full(n, 0.05), np.full(n, 0.3), None, "test", start)


def _pushes(n: int, on: int, off: int, pads: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """q and eta of n samples: pads 0, 1, ... in turn, each on for ``on`` samples then off
    for ``off``."""
    q, eta = np.zeros(n, dtype=int), np.zeros(n, dtype=int)
    for k in range(n):
        cycle = k // (on + off)
        eta[k] = cycle % pads
        q[k] = 1 if k % (on + off) < on else 0
    return q, eta


def test_the_charge_a_trial_starts_with_is_the_closed_form_of_its_prior_switching() -> None:
    T = 50.0
    q, eta = np.zeros(60, dtype=int), np.full(60, 3)
    tr = replace(_trial("b", q, eta, t0=100.0), prior=np.array([[10.0, 14.0, 3.0],
                                                              [20.0, 21.0, 5.0]]))
    got = S.prior_charge(tr, T)
    want3 = T * (1 - math.exp(-4.0 / T)) * math.exp(-(100.0 - 14.0) / T)
    want5 = T * (1 - math.exp(-1.0 / T)) * math.exp(-(100.0 - 21.0) / T)
    assert got[3] == pytest.approx(want3, rel=1e-12)
    assert got[5] == pytest.approx(want5, rel=1e-12)
    assert np.count_nonzero(got) == 2


def test_a_record_cut_in_two_carries_its_charge_across_the_cut() -> None:
    """The retained charge of a record equals that of its second half started from the
    charge its first half leaves (prior_charge of the slice): carrying is exact."""
    q, eta = _pushes(3000, 40, 20, pads=4)
    whole = _trial("w", q, eta)
    T = 30.0
    full = retention_charge(whole.t, whole.q.astype(np.int64), whole.eta_unwrapped % 16, T,
                            np.zeros(16))
    part = whole.slice(1700, 3000)
    tail = retention_charge(part.t, part.q.astype(np.int64), part.eta_unwrapped % 16, T,
                            S.prior_charge(part, T))
    np.testing.assert_allclose(tail, full[1700:], rtol=1e-9, atol=1e-12)


def test_a_session_is_put_in_order_with_its_gaps_and_each_trial_carries_the_switching_before_it(
        ) -> None:
    q, eta = _pushes(600, 30, 30)
    a = _trial("a", q, eta, start=1000.0)             # 2 s each
    b = _trial("b", q, eta, start=1012.0, t0=5.0)     # its own clock starts at 5 s
    ses = S.as_session([b, a])
    assert [tr.name for tr in ses.trials] == ["a", "b"] and ses.timed and ses.warning is None
    assert [e.start for e in ses.entries] == [0.0, 12.0]
    assert ses.entries[1].gap == pytest.approx(12.0 - a.duration)
    first, second = ses.trials
    assert first.prior.shape == (0, 3)
    own = a.switch_ons()
    assert second.prior.shape == own.shape
    # a's switch-ons in b's clock: b's t[0] = 5 s is session time 12 s
    np.testing.assert_allclose(second.prior[:, :2], own[:, :2] - 12.0 + 5.0)
    # the session's HV time of each pad runs on from the trials before
    on_before = np.bincount(own[:, 2].astype(int), weights=own[:, 1] - own[:, 0], minlength=16)
    assert hv_time(second)[0] == pytest.approx(on_before[second.eta_unwrapped[0] % 16])


@pytest.mark.parametrize("starts", [(None, None), (0.0, None), (0.0, 1.0)])
def test_without_a_session_time_for_every_trial_or_with_overlaps_the_order_given_stands(
        starts: tuple) -> None:
    q, eta = _pushes(600, 30, 30)
    trials = [_trial("x", q, eta, start=starts[0]), _trial("y", q, eta, start=starts[1])]
    ses = S.as_session(trials)
    assert not ses.timed and ses.warning
    assert [tr.name for tr in ses.trials] == ["x", "y"]
    assert all(tr.prior.shape == (0, 3) for tr in ses.trials)


def test_one_recording_of_a_session_is_cut_at_its_rests() -> None:
    q, eta = _pushes(900, 30, 30)
    drive = _trial("d", q, eta)
    rest = 3000                                        # 10 s at rest, HV off
    n = 900 + rest + 900
    t = DT * np.arange(n)
    angle = np.concatenate([drive.angle, np.full(rest, drive.angle[-1]),
                            drive.angle[-1] + drive.angle])
    qq = np.concatenate([q, np.zeros(rest, dtype=int), q])
    ee = np.concatenate([eta, np.full(rest, eta[-1]), eta])
    na = np.concatenate([drive.n_a, np.full(rest, -1), drive.n_a])
    pa = np.where(na >= 0, 0.05, np.nan)
    pd = np.where(na >= 0, 0.3, np.nan)
    whole = Trial("bag", t, angle, qq.astype(np.int8), ee, na, pa, pd, None, "bag", 50.0)
    parts = S.split_stream(whole)
    assert [p.name for p in parts] == ["bag_trial1", "bag_trial2"]
    assert parts[0].t.shape[0] == 901                   # the first sample at rest is kept
    assert parts[1].session_start == pytest.approx(50.0 + (900 + rest) * DT)
    assert S.split_stream(drive) == [drive]             # no rest: the record stays whole


def test_session_time_round_trips_through_csv_and_a_column_off_the_clock_is_refused(
        tmp_path) -> None:
    q, eta = _pushes(600, 30, 30)
    tr = _trial("s", q, eta, start=123.5)
    write_csv(tr, tmp_path / "s.csv")
    back = read_csv(tmp_path / "s.csv")
    assert back.session_start == pytest.approx(123.5)
    text = (tmp_path / "s.csv").read_text().splitlines()
    cols = text[0].split(",")
    k = cols.index("session_t")
    row = text[10].split(",")
    row[k] = "999.0"
    text[10] = ",".join(row)
    (tmp_path / "bad.csv").write_text("\n".join(text) + "\n")
    with pytest.raises(TrialError, match=r"row 11, column session_t"):
        read_csv(tmp_path / "bad.csv")


def _coasts(slope: float, tau0: float = 0.0104, n: int = 5, sd: float = 2e-6,
            seed: int = 0) -> list[CoastFriction]:
    rng = np.random.default_rng(seed)
    out = []
    for k in range(n):
        t = 55.0 + 80.0 * k
        e = tau0 + slope * t + sd * rng.standard_normal()
        out.append(CoastFriction(f"t{k}", t, e, (e - 1.96 * sd, e + 1.96 * sd)))
    return out


def test_a_friction_rising_along_the_session_is_measured_with_its_rate() -> None:
    rate = 0.25 / 420.0                                 # +25 % per 7 min
    tr = friction_trend(_coasts(0.0104 * rate))
    assert tr is not None and tr.significant
    assert tr.rate == pytest.approx(rate, rel=0.02)
    assert tr.span == pytest.approx(320.0)


def test_a_steady_friction_shows_no_trend() -> None:
    tr = friction_trend(_coasts(0.0, seed=3))
    assert tr is not None and not tr.significant
    assert friction_trend(_coasts(0.0, n=2)) is None    # a line needs three coast-downs


def _spread_refits(step: float, at: int, pad: int = 5, m: int = 5, sd: float = 0.03,
                   seed: int = 1) -> Consistency:
    """A gain spread refitted trial by trial: log-gains (sum 0) of 16 pads near 1, pad
    ``pad``'s gain times ``step`` from trial ``at`` on, each estimate with noise ``sd``."""
    rng = np.random.default_rng(seed)
    est = []
    for j in range(m):
        g = np.ones(16)
        if j >= at:
            g[pad] *= step
        d = np.log(g) - np.mean(np.log(g)) + sd * rng.standard_normal(16)
        est.append(d[1:])
    est = np.array(est)
    sds = np.full_like(est, sd)
    return Consistency("gain_spread", [f"d{i}" for i in range(1, 16)],
                       [f"trial{j + 1}" for j in range(m)], est, sds, est.mean(axis=0), 0.0, 1,
                       1.0, [1.0] * m, 0.0, 1.0, 1.0)


def test_a_pad_that_breaks_down_between_two_trials_is_named_with_its_gains_before_and_after(
        ) -> None:
    st = gain_step(_spread_refits(0.15, at=2))
    assert st is not None
    assert (st.pad, st.index, st.trial, st.previous) == (5, 2, "trial3", "trial2")
    assert st.before == pytest.approx(1.0, rel=0.05)
    assert st.after == pytest.approx(0.15, rel=0.05)
    gains = latest_gains(np.ones(16), st)
    assert gains[5] == pytest.approx(st.after) and np.all(np.delete(gains, 5) == 1.0)


@pytest.mark.parametrize("factor", [1.0, 0.9])
def test_no_step_or_one_below_the_smallest_named_is_not_reported(factor: float) -> None:
    assert factor < MIN_STEP and 1 / factor < MIN_STEP
    assert gain_step(_spread_refits(factor, at=2)) is None


def _timed_session(m: int = 5) -> list[Trial]:
    q, eta = _pushes(900, 30, 30)
    return S.as_session([_trial(f"t{j}", q, eta, start=100.0 * j) for j in range(m)]).trials


@pytest.mark.parametrize("slope", [0.0, 2e-4])
def test_a_change_of_the_trials_defects_along_the_session_is_found_with_its_slope(
        slope: float) -> None:
    """Window defects [rad/s^2] with a mean that moves along session time by ``slope`` per
    second: found with that slope (the HV time of these trials grows in step with session
    time, so either axis may read it: its change over the session is the same), or nothing
    for a steady mean."""
    trials = _timed_session()
    rng = np.random.default_rng(5)
    mids = np.array([tr.session_start + 0.5 * tr.duration for tr in trials])
    trial_of = np.repeat(np.arange(len(trials)), 40)
    acc = 0.01 + slope * mids[trial_of] + 0.002 * rng.standard_normal(trial_of.size)
    drift = session_drift(trials, acc, trial_of, 1e-4, 0.005)
    if slope == 0.0:
        assert drift is None
        return
    assert drift is not None and drift.axis in SESSION_AXES
    assert drift.change == pytest.approx(slope * np.ptp(mids), rel=0.1)
    untimed = [replace(tr, session_start=None) for tr in trials]
    assert session_drift(untimed, acc, trial_of, 1e-4, 0.005) is None


def test_the_fits_take_each_trials_friction_from_the_trend_relative_to_the_last() -> None:
    trials = _timed_session(3)
    trend = friction_trend(_coasts(0.0104 * 1e-3, n=3))
    out = along_the_trend(trials, trend)
    at = [trend.tau_start + trend.slope * (tr.session_start + 0.5 * tr.duration) for tr in out]
    assert [tr.friction_scale for tr in out] == pytest.approx([a / at[-1] for a in at])
    assert out[-1].friction_scale == 1.0 and out[0].friction_scale < 1.0
