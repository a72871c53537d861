"""The whole identification on data with an undeclared effect, with none, and with one that
is outside the library (issue 5's acceptance), and the report it writes.

Each data set is three open-loop trials (phi_a 1, 4, 7 deg; 25 s driven, 9 s coasting) from
the plant simulator, through the 10-bit encoder with 1 mrad noise (the look-alike losses on
the paper's five trials of 60 s: ``bench_ident_effects.py --outside-only``).  The tool is never told
which effect is on; it searches the whole library."""
import dataclasses
import json
import math

import numpy as np
import pytest

from hasel_wheel_ident import candidates as C
from hasel_wheel_ident import evaluation as EV
from hasel_wheel_ident import refit_plan as PLAN
from hasel_wheel_ident import select as SEL
from hasel_wheel_ident import unexplained as UNX
from hasel_wheel_ident import device_verdict as K
from hasel_wheel_ident.identification import Identification
from hasel_wheel_ident import synthetic as S
from hasel_wheel_ident.fit import Problem, force_coordinates, from_force_coordinates
from hasel_wheel_ident import residual as RES
from hasel_wheel_ident.screen import bent
from hasel_wheel_ident.metrics import (model_error, pooled_rmse, speed_from_angle,
                                           trial_metrics)
from hasel_wheel_ident.report import write_report
from hasel_wheel_ident.reasons import Reason
from hasel_wheel_ident.report_json import to_json
from hasel_wheel_ident.report_md import RAN_ON_NOTE, to_markdown
from hasel_wheel_ident.report_text import fit_status_text
from hasel_wheel_sim.effects import effects_from_mapping
from hasel_wheel_sim.model_file import load_model
from hasel_wheel_sim.params import WheelParams
from hasel_wheel_sim.plant import PlantConfig

ENCODER = S.ENCODER
SET = S.SHORT_SET
COM = {"com_offset": {"enabled": True, "torque": {"value": 0.004, "unit": "N*m"},
                      "phase": {"value": 0.5, "unit": "rad"}}}
PLATFORM = {"platform_disturbance": {"enabled": True, "torque": {"value": 0.004, "unit": "N*m"},
                                     "phase": {"value": 1.0, "unit": "rad"}}}


_trials = S.encoder_trials


@pytest.fixture(scope="module")
def com_identification():
    return SEL.identify(_trials(COM), k_folds=3, max_effects=2)


#: the tests that read com_identification run on one worker (./dev test runs pytest-xdist),
#: which fits it once
ON_COM_WORKER = pytest.mark.xdist_group("com_identification")


def test_speed_from_angle_is_exact_on_a_parabola():
    # a quadratic Savitzky-Golay derivative reproduces a parabola's slope exactly
    t = np.arange(0, 2, 1 / 300)
    angle = 0.3 + 2.0 * t + 0.75 * t ** 2
    np.testing.assert_allclose(speed_from_angle(t, angle), 2.0 + 1.5 * t, atol=1e-9)


def test_the_true_model_reproduces_an_exact_trial():
    # no encoder, no noise: the free run of the true model from the true start follows the
    # recording (R^2 ~ 1); a force law 10 % too strong does visibly worse
    tr = S.record(SET[1], config=PlantConfig(seed=1, switching="tick"))
    prob = Problem([tr], WheelParams())
    theta = np.array([s.start for s in prob.specs])
    good = trial_metrics(prob, theta, tr, (tr.angle[0], SET[1].initial_speed))
    assert good.r2 > 0.995
    assert good.rmse < 0.02
    theta[0] *= 1.1                       # peak
    bad = trial_metrics(prob, theta, tr, (tr.angle[0], SET[1].initial_speed))
    assert bad.rmse > 3 * good.rmse


@ON_COM_WORKER
def test_an_undeclared_com_offset_is_named_measured_and_halves_the_error(com_identification):
    res = com_identification
    assert res.chosen == ("com_offset",)
    got = C.BY_ID["com_offset"].describe([res.final.fit.values["A"], res.final.fit.values["B"]])
    assert got["torque_N_m"] == pytest.approx(0.004, rel=0.05)
    assert got["phase_rad"] == pytest.approx(0.5, abs=0.05)
    # held out by trial: the simulation error (Table III's metric) and the window error
    assert res.final.sim_heldout_rmse <= 0.5 * res.nominal.sim_heldout_rmse
    assert res.final.heldout_rmse < 0.9 * res.nominal.heldout_rmse
    # the screening saw every other candidate, and none was added after the COM offset
    assert {s.candidate for s in res.screenings[0]} == {c.id for c in C.LIBRARY}
    assert all(not e.accepted for e in (res.rounds[1] if len(res.rounds) > 1 else []))
    # the once-per-turn structure is gone from the residual
    assert not any(s.axis == "wheel_angle" for s in res.diagnostics_after.signatures)


SPREAD = {"gain_spread": {"enabled": True, "std": {"value": 0.08, "unit": "1"}}}
VISCOUS = {"viscous_drag": {"enabled": True,
                            "coefficient": {"value": 0.001, "unit": "N*m*s/rad"}}}
RISE = {"rise_lag": {"enabled": True, "time_constant": {"value": 0.05, "unit": "s"}}}
RETENTION = {"charge_retention": {"enabled": True, "rate": {"value": 0.1, "unit": "1/s"},
                                  "recovery": {"value": 300.0, "unit": "s"}}}


def _realised_gain_std(seed: int, effects: dict = SPREAD) -> float:
    """The std of the 16 gains the plant drew (record_set draws them once from the seed)."""
    ext = effects_from_mapping(effects).extensions(np.random.default_rng(seed))
    g = np.array(ext.gains)
    return float(np.std(g / np.exp(np.mean(np.log(g)))))      # geometric mean 1, as fitted


@pytest.mark.parametrize("effect, cid, truth, halvable", [
    (SPREAD, "gain_spread", None, True),
    pytest.param(VISCOUS, "viscous_drag", {"c": 0.001}, True, marks=pytest.mark.avx512_route),
    # a 50 ms rise lag that the nominal force law half absorbs (screened from a single
    # start it scored chi^2 8 and was never refitted, and charge retention was named)
    (RISE, "rise_lag", {"tau": 0.05}, True),
    (RETENTION, "charge_retention", {"rate": 0.1, "recovery": 300.0}, False),
])
def test_other_undeclared_effects_are_named_and_measured(effect, cid, truth, halvable):
    trials = _trials(effect)
    res = SEL.identify(trials, k_folds=3, max_effects=1, analyse_residuals=False)
    assert res.chosen == (cid,)
    before, after = res.nominal.sim_heldout_rmse, res.final.sim_heldout_rmse
    v, ci = res.final.fit.values, res.final.fit.ci95
    if truth is None:                     # gain spread: the error can be halved
        assert after <= 0.5 * before
        got = C.BY_ID[cid].describe([v[f"d{i}"] for i in range(1, 16)])
        # 16 gains from ~100 s of data: their spread within 10 %
        assert got["std"] == pytest.approx(_realised_gain_std(3), rel=0.1)
        return
    assert v["tau_f"] == pytest.approx(WheelParams().tau_f, rel=0.02)
    if cid in ("viscous_drag", "rise_lag"):
        name = next(iter(truth))
        assert v[name] == pytest.approx(truth[name], rel=0.1)
        assert ci[name][0] < truth[name] < ci[name][1]     # its 95 % interval holds the truth
    else:
        # 34 s trials from rested actuators: Q_i stays far below the 300 s recovery time,
        # which then enters only at second order.  The rate is measured (within 15 %, its
        # 95 % interval holding the truth); the recovery time is not determined, and its
        # interval says so (wider than the value itself) without contradicting the truth.
        assert v["rate"] == pytest.approx(0.1, rel=0.15)
        assert ci["rate"][0] < 0.1 < ci["rate"][1]
        # its size grows with the three trials' speeds, so the search refitted it beside a
        # force that builds up after each switch-on, where the right retention still holds
        lag = res.consistency[cid].beside_lag
        assert lag is not None and lag.holds() and lag.values["rate"] == pytest.approx(0.1,
                                                                                      rel=0.15)
        lo, hi = ci["recovery"]
        assert lo < 300.0 < hi and hi - lo > v["recovery"]
    # The free run has a floor: even the true model drifts from the recording once a switch
    # crosses a tick.  Where that floor is below half the nominal model's error, the
    # identified model must halve the error (the bar).  Where it is not (retention
    # at 0.1/s: the true model gets to ~0.57x), halving is not something a model can do; the
    # identified one must come within 10 % of the true model and remove at least 90 % of
    # the error above it.
    floor = model_error(trials, WheelParams(), (C.BY_ID[cid],),
                        dict(force_coordinates(WheelParams()), tau_f=WheelParams().tau_f,
                             **truth))
    if halvable:
        assert floor < 0.5 * before
        assert after <= 0.5 * before
    else:
        assert 0.5 * before < floor < 0.7 * before
    assert after <= 1.1 * floor
    assert before - after >= 0.9 * (before - floor)


ECCENTRIC = {"angle_eccentricity": {"enabled": True, "amplitude": {"value": 0.005, "unit": "rad"},
                                    "phase": {"value": 0.3, "unit": "rad"}}}


def test_an_undeclared_sensor_eccentricity_is_named_as_a_reading_error_not_a_torque():
    # the sensor reads xi1 + 0.005 sin(xi1 + 0.3), and the firmware switches on that reading.
    # An off-centre mass makes a once-per-turn speed ripple too (its score test is
    # significant, chi^2 ~190); the reading error's ripple grows with the speed, the torque's
    # does not, and the three trials' speeds tell them apart
    trials = _trials(ECCENTRIC, seed=11)
    res = SEL.identify(trials, k_folds=3, max_effects=1, analyse_residuals=False)
    assert res.chosen == ("angle_eccentricity",)
    v = res.final.fit.values
    got = C.BY_ID["angle_eccentricity"].describe([v["E"], v["F"]])
    assert got["amplitude_rad"] == pytest.approx(0.005, rel=0.05)
    assert got["phase_rad"] == pytest.approx(0.3, abs=0.05)
    assert res.final.sim_heldout_rmse <= 0.5 * res.nominal.sim_heldout_rmse
    # the saved model carries it, in the plant's convention
    _, ext, _ = res.model()
    assert ext.angle_eccentricity == pytest.approx(got["amplitude_rad"])
    assert ext.angle_eccentricity_phase == pytest.approx(got["phase_rad"])


# The same eccentricity with its candidate left out (the off-centre mass cuts the held-out
# error by ~60 % and is refused as a stand-in whose torque grows with the speed):
# ``bench_ident_effects.py`` (run_sensor) prints its verdict; the check itself is tested in
# test_ident_consistency.py (a reading error standing in for an off-centre mass and back).


def test_an_effect_refused_from_a_bent_force_law_is_refitted_from_the_reference():
    # a weak off-centre mass (0.002 N*m at -2 rad, plant seed 7): the nominal fit bends its
    # force law (width 0.24, the truth 0.10), and the COM refit started there cut the window
    # RMSE by 41 % but not the free run's error (-1.7 %), so it was refused and nothing was
    # named.  Refitted from the reference force law it converges to the truth.  The
    # screening's short fits (short_fits) are off, so that the refit from the reference is
    # what is tested
    com = {"com_offset": {"enabled": True, "torque": {"value": 0.002, "unit": "N*m"},
                          "phase": {"value": -2.0, "unit": "rad"}}}
    trials = _trials(com, seed=7)
    res = SEL.identify(trials, k_folds=3, max_effects=1, analyse_residuals=False,
                       short_fits=False)
    assert res.chosen == ("com_offset",)
    assert res.rounds[0][0].codes[-1] == Reason.REFIT_FROM_REFERENCE
    v = res.final.fit.values
    got = C.BY_ID["com_offset"].describe([v["A"], v["B"]])
    assert got["torque_N_m"] == pytest.approx(0.002, rel=0.1)
    assert got["phase_rad"] == pytest.approx(-2.0, abs=0.1)
    # the true model gets 0.63x of the nominal fit's error here (halving is impossible); the
    # identified one must come within 10 % of it
    P = WheelParams()
    truth = dict(force_coordinates(P), tau_f=P.tau_f, A=-0.002 * math.sin(-2.0),
                 B=-0.002 * math.cos(-2.0))
    floor = model_error(trials, P, (C.BY_ID["com_offset"],), truth)
    before, after = res.nominal.sim_heldout_rmse, res.final.sim_heldout_rmse
    assert 0.5 * before < floor < 0.7 * before
    assert after <= 1.1 * floor


def test_a_slow_rise_lag_that_the_force_law_bends_to_mimic_is_found_by_the_scan():
    # a 120 ms rise lag (plant seed 7): the nominal fit bends its force law far (peak 83,
    # width 0.23; the truth 19.8, 0.10), and a Gauss-Newton step from there or from the
    # reference at 5, 20 or 60 ms predicted little (chi^2 46, fourth of seven at the time): an angle
    # offset led and was refused, and a gain spread and charge retention were named.  The
    # rise lag's scan finds where the error is lowest, and its short fit starts the refit.
    # The screening's short fits (short_fits) are off, so that the scan is what is tested
    rise = {"rise_lag": {"enabled": True, "time_constant": {"value": 0.12, "unit": "s"}}}
    trials = _trials(rise, seed=7)
    res = SEL.identify(trials, k_folds=3, max_effects=1, analyse_residuals=False,
                       short_fits=False)
    sc = {s.candidate: s for s in res.screenings[0]}
    assert sc["rise_lag"].scanned
    assert sc["rise_lag"].start["tau"] == pytest.approx(0.12, rel=0.1)
    assert sc["rise_lag"].log10_p == min(s.log10_p for s in sc.values())
    assert res.chosen == ("rise_lag",)
    v, ci = res.final.fit.values, res.final.fit.ci95
    assert v["tau"] == pytest.approx(0.12, rel=0.1)
    assert ci["tau"][0] < 0.12 < ci["tau"][1]
    P = WheelParams()
    floor = model_error(trials, P, (C.BY_ID["rise_lag"],),
                        dict(force_coordinates(P), tau_f=P.tau_f, tau=0.12))
    before, after = res.nominal.sim_heldout_rmse, res.final.sim_heldout_rmse
    assert floor < 0.5 * before
    assert after <= 0.5 * before
    # at least 90 % of the error that the true model removes (measured: 0.1266 -> 0.0294
    # rad/s held out, the true model 0.0252: 96 %)
    assert before - after >= 0.9 * (before - floor)


#: one pad that has broken down (0.05 of the others' force), and the widest spread the plant
#: draws (std 0.5, seed 3: two pads at 0.078 of the geometric mean, one at 4.2 times it)
BROKEN_PAD = {"actuator_gains": [1.0] * 5 + [0.05] + [1.0] * 10}
WIDE_SPREAD = {"gain_spread": {"enabled": True, "std": {"value": 0.5, "unit": "1"}}}


@pytest.mark.parametrize("effects", [BROKEN_PAD, WIDE_SPREAD], ids=["broken_pad", "std_0.5"])
def test_gains_far_from_the_mean_are_measured_not_stopped_at_a_bound(effects):
    # the plant's gains relative to their geometric mean, as the candidate reports them
    truth = np.array(effects_from_mapping(effects).extensions(np.random.default_rng(3)).gains)
    truth /= np.exp(np.mean(np.log(truth)))
    assert truth.min() < 0.1                       # beyond the old bound of e^-1.5 = 0.22
    res = SEL.identify(_trials(effects), k_folds=3, max_effects=1, analyse_residuals=False)
    assert res.chosen == ("gain_spread",)
    v = res.final.fit.values
    got = np.array(C.BY_ID["gain_spread"].describe([v[f"d{i}"] for i in range(1, 16)])["gains"])
    weak = truth < 0.1
    # a weak pad's gain is measured to about the same force as any other pad's, so its
    # tolerance is absolute: 0.03 of the mean's force (measured: 0.0001; 0.010 and 0.021),
    # and its 95 % interval holds the truth (log-gains d_i = ln g_i for pads 1..15; both
    # weak pads of the wide spread are among them); every other gain within 8 % (measured:
    # at most 3.0 % and 2.7 %)
    np.testing.assert_allclose(got[weak], truth[weak], atol=0.03)
    ci = res.final.fit.ci95
    for i in np.flatnonzero(weak):
        assert i > 0 and ci[f"d{i}"][0] < math.log(truth[i]) < ci[f"d{i}"][1]
    np.testing.assert_allclose(got[~weak], truth[~weak], rtol=0.08)
    assert res.final.sim_heldout_rmse <= 0.5 * res.nominal.sim_heldout_rmse


def test_two_effects_that_each_fail_the_free_run_alone_are_named_together():
    # viscous drag and a gain spread at once (plant seed 4): each refitted alone cuts the
    # window RMSE by ~14 %, but the gain spread alone raised the held-out simulation error
    # (-5.1 %) and the drag alone raised it on its own trials; nothing was named.  The two are
    # refitted together (select.supported_pair)
    both = {**VISCOUS, "gain_spread": {"enabled": True, "std": {"value": 0.1, "unit": "1"}}}
    trials = _trials(both, seed=4)
    res = SEL.identify(trials, k_folds=3, max_effects=2, analyse_residuals=False)
    singles = [e for e in res.rounds[0] if len(e.effects) == 1]
    assert {e.effects[0] for e in singles} == {"viscous_drag", "gain_spread"}
    assert not any(e.accepted for e in singles)
    assert set(res.chosen) == {"viscous_drag", "gain_spread"}
    v, ci = res.final.fit.values, res.final.fit.ci95
    assert v["c"] == pytest.approx(0.001, rel=0.1)
    assert ci["c"][0] < 0.001 < ci["c"][1]
    got = C.BY_ID["gain_spread"].describe([v[f"d{i}"] for i in range(1, 16)])
    assert got["std"] == pytest.approx(_realised_gain_std(4, both), rel=0.1)
    assert res.final.sim_heldout_rmse <= 0.5 * res.nominal.sim_heldout_rmse
    data = to_json(res, [], [])
    assert [(set(t["ids"]), t["accepted"]) for t in data["tried_together"]] == \
        [({"viscous_drag", "gain_spread"}, True)]
    assert {c["id"] for c in data["candidates"] if c["refitted"]} == \
        {"viscous_drag", "gain_spread"}


def test_a_second_effect_behind_a_refused_leader_is_refitted_and_both_are_named():
    # a 50 ms rise lag and viscous drag of 1e-3 at once (plant seed 11): the drag leads the
    # screening alone and, refitted alone, cuts the held-out simulation error by less than
    # the bar (it leaves the force law bent by the rise lag), so nothing was named.  Now the
    # next significant candidate is refitted as well (select.further_refits); the rise lag
    # alone passes, but the refused drag fits the held-out windows as well, so the two are
    # refitted together (select.tied_pair)
    trials = _trials({**RISE, **VISCOUS}, seed=11)
    res = SEL.identify(trials, k_folds=3, max_effects=2, analyse_residuals=False)
    singles = {e.effects[0]: e for e in res.rounds[0] if len(e.effects) == 1}
    assert not singles["viscous_drag"].accepted
    assert PLAN.backed(singles["viscous_drag"], res.nominal, 0.10)
    assert "rise_lag" in singles
    assert set(res.chosen) == {"viscous_drag", "rise_lag"}
    # named by the tie route: the rise lag alone passed, the drag alone tied it
    assert res.final.codes == [Reason.ACCEPTED, Reason.TRIED_TOGETHER]
    assert singles["rise_lag"].codes == [Reason.ACCEPTED]
    v, ci = res.final.fit.values, res.final.fit.ci95
    assert v["c"] == pytest.approx(0.001, rel=0.1)
    assert v["tau"] == pytest.approx(0.05, rel=0.1)
    assert ci["tau"][0] < 0.05 < ci["tau"][1]
    P = WheelParams()
    floor = model_error(trials, P, (C.BY_ID["viscous_drag"], C.BY_ID["rise_lag"]),
                        dict(force_coordinates(P), tau_f=P.tau_f, c=0.001, tau=0.05))
    before, after = res.nominal.sim_heldout_rmse, res.final.sim_heldout_rmse
    assert after <= 0.5 * before
    # at least 90 % of the error that the true model removes
    assert before - after >= 0.9 * (before - floor)


# Viscous drag of 1.5e-3 outside the library (plant seed 12), which the force law takes up
# within each window and so leaves a drift that falls through each drive:
# ``bench_ident_effects.py`` (run_two_and_outside) prints its verdict, with and without
# the candidate.  A drift left by a loss outside the library is tested below (the rise lag
# and retention look-alikes).


def test_a_gain_spread_outside_the_library_is_reported_along_the_actuator_index():
    # fabrication spread of std 0.1 with its candidate left out (plant seed 11): nothing is
    # named; the structure is reported along the actuator index, its force factors measured
    # by a refit, where the residual's bins saw nothing and a periodogram saw only the
    # pattern's first harmonic ("1 per wheel turn", which would name an off-centre mass)
    spread = {"gain_spread": {"enabled": True, "std": {"value": 0.1, "unit": "1"}}}
    trials = _trials(spread, seed=11)
    res = SEL.identify(trials, k_folds=3, library=C.library(exclude=["gain_spread"]))
    assert res.chosen == ()
    sigs = res.diagnostics_after.signatures
    assert [s.axis for s in sigs] == ["actuator"] and sigs[0].p_value < RES.SIGNIFICANCE
    # the plant's gains, as it drew them from the seed, relative to their geometric mean
    truth = np.array(effects_from_mapping({**ENCODER, **spread}).extensions(
        np.random.default_rng(11)).gains)
    truth /= np.exp(np.mean(np.log(truth)))
    factors = np.array(sigs[0].factors)
    assert np.corrcoef(np.log(factors), np.log(truth))[0, 1] > 0.95
    assert np.std(factors) == pytest.approx(np.std(truth), rel=0.15)
    assert np.max(np.abs(factors - truth)) < 0.03
    data = to_json(res, [], [])
    assert data["unexplained"][0]["actuator_factors"] == pytest.approx(list(factors))
    # the pattern's first harmonic, which the periodogram saw as once per wheel turn, is no
    # longer needed once the factors are beside it: set apart, not reported
    assert [(u.axis, u.period) for u in res.unconfirmed] == [("wheel_angle", 2 * math.pi)]
    assert res.unconfirmed[0].torque_ci95[0] == 0.0
    assert [u["axis"] for u in data["unconfirmed"]] == ["wheel_angle"]


def _retention(rate: float) -> dict:
    return {"charge_retention": {"enabled": True, "rate": {"value": rate, "unit": "1/s"},
                                 "recovery": {"value": 300.0, "unit": "s"}}}


# The look-alike losses on the paper's protocol (5 x 60 s; 50 s drives in which the speed
# levels off while the HV time keeps growing), each with the other's candidate left out:
# ``bench_ident_effects.py --outside-only`` runs them on plant seeds 11-13 with a verdict
# each (nothing named, the drift along the left-out loss's own axis).  They cost 4-5 minutes
# of the suite's ten; the tests below run the same look-alikes on 3 x 34 s, where they are
# harder to tell apart.


def test_a_rise_lag_outside_the_library_on_short_trials_leaves_a_drift_along_speed():
    # 3 x 34 s, plant seed 13: retention refitted to the rise lag grows with the trials'
    # speed and is refused as a stand-in; nothing is named, and the drift left goes with
    # speed.  (This run once broke the report: the actuator test beside the HV-time loss
    # with no periodic torque to size)
    rise = {"rise_lag": {"enabled": True, "time_constant": {"value": 0.04, "unit": "s"}}}
    res = SEL.identify(_trials(rise, seed=13), k_folds=3, library=C.library(exclude=["rise_lag"]))
    assert res.chosen == ()
    retention = [e for r in res.rounds for e in r if e.effects == ("charge_retention",)]
    assert retention and Reason.SPEED_STAND_IN in retention[0].codes
    drift = [s for s in res.diagnostics_after.signatures if UNX.drift_signature(s)]
    assert [s.axis for s in drift] == ["speed"]
    assert res.diagnostics_after.trend.p_value < 1e-20
    # and nothing beside it: the force factors per actuator are tested beside the device
    # that takes up the most of the drift, here the switch-on lag (near the plant's 40 ms).
    # (beside the HV-time loss they would take up structure the lag leaves)
    devices = drift[0].devices
    assert devices["on_lag"]["value"] == pytest.approx(0.04, rel=0.1)
    assert devices["on_lag"]["sim_rmse_rad_s"] < 0.9 * devices["hv_loss"]["sim_rmse_rad_s"]
    assert [s.axis for s in res.diagnostics_after.signatures] == ["speed"]


def _refused_leaving_a_drift(res: Identification, cid: str
                             ) -> tuple[list[Reason], RES.Signature]:
    """(The codes ``cid`` was refused with, the one drift left) of a search that named
    nothing, ``cid``
    refused in its first refit, and whose one drift names it as having taken up part of it."""
    assert res.chosen == ()
    refused = [e for r in res.rounds for e in r if e.effects == (cid,)]
    assert refused and not refused[0].accepted
    drift = [s for s in res.diagnostics_after.signatures if UNX.drift_signature(s)]
    assert len(drift) == 1 and f"{cid} took up part of it and was refused" in drift[0].text
    return refused[0].codes, drift[0]


@pytest.mark.parametrize("seed", [pytest.param(11, marks=pytest.mark.avx512_route), 12])
def test_retention_standing_in_for_a_rise_lag_outside_the_library_is_refused_beside_the_lag(seed):
    # 3 x 34 s: retention refitted to a 40 ms rise lag grows with the trials' speed, short of
    # the refusal (seed 11: k = +1.42, p = 0.0025; seed 12: k = +0.99, p = 0.045; README),
    # and was named.  Refitted beside a force that builds up after each switch-on (the
    # measuring device ON_LAG) it is no longer needed: refused, nothing is named, and the
    # drift it took up is left along speed, where the device measures the plant's lag
    tau = 0.04
    rise = {"rise_lag": {"enabled": True, "time_constant": {"value": tau, "unit": "s"}}}
    res = SEL.identify(_trials(rise, seed=seed), k_folds=3,
                       library=C.library(exclude=["rise_lag"]))
    why, drift = _refused_leaving_a_drift(res, "charge_retention")
    assert Reason.SWITCH_ON_LAG_STAND_IN in why
    assert drift.axis == "speed"
    # beside the final (nominal) model the device takes the plant's time constant, and the
    # free run with it comes near the true model's; the HV-time loss takes up far less
    lag, loss = drift.devices["on_lag"], drift.devices["hv_loss"]
    assert lag["value"] == pytest.approx(tau, rel=0.1) and lag["unit"] == "s"
    base = WheelParams()
    truth = model_error(res.trials, base, (C.BY_ID["rise_lag"],),
                        dict(force_coordinates(base), tau_f=base.tau_f, tau=tau))
    assert lag["sim_rmse_rad_s"] < 1.1 * truth
    assert lag["sim_rmse_rad_s"] < 0.8 * loss["sim_rmse_rad_s"] < loss["sim_rmse_model_rad_s"]
    assert K.lead_device(drift.devices, 0.10) == "on_lag"
    data = to_json(res, [], [])
    assert data["effects"] == []
    entry = next(u for u in data["unexplained"] if u["drift"])
    assert entry["drift_devices"]["on_lag"]["value"] == lag["value"]


# Retention of 0.2/s with its candidate left out, 3 x 34 s (plant seed 11): a rise lag
# that cuts the held-out error is refused, since it changes within the trials and no longer
# holds beside a force loss growing with HV time, and the drift is reported along HV time
# (the device that takes up the most), though the regression alone reads speed.
# ``bench_ident_effects.py --outside-only`` prints its verdict (seeds 11-13); the refusal is
# tested in test_ident_consistency.py (a drifting stand-in beside the measured loss), and
# the report along the device's axis with weak retention below (seed 12).


def test_a_rise_lag_standing_in_for_weak_retention_is_refused_though_it_does_not_drift():
    # retention of 0.05/s with its candidate left out, 3 x 34 s (plant seed 12): a rise lag
    # cuts the held-out error and would be named.  It is one value through each drive, so no drift calls for the HV-time loss;
    # refitted beside it all the same (consistency.LOSS_LOOKALIKES) it is no longer needed
    # while the loss is significant: refused, nothing is named
    res = SEL.identify(_trials(_retention(0.05), seed=12), k_folds=3,
                       library=C.library(exclude=["charge_retention"]))
    why, drift = _refused_leaving_a_drift(res, "rise_lag")
    assert Reason.HV_LOSS_LOOKALIKE in why
    # beside the final (nominal) model the switch-on lag alone runs the trials better than
    # the loss alone, yet refitted together only the loss stays significant: it takes up
    # the most, and the drift is reported along the HV time
    loss, lag = drift.devices["hv_loss"], drift.devices["on_lag"]
    assert loss["value"] == pytest.approx(0.05, rel=0.1)
    assert lag["sim_rmse_rad_s"] < loss["sim_rmse_rad_s"] < loss["sim_rmse_model_rad_s"]
    assert loss["wald_p_together"] < 1e-20 and lag["wald_p_together"] > 0.5
    assert ("of these, a force loss that grows with the accumulated HV time takes up the most "
            "of it: refitted together, only it stays significant") in drift.text
    assert drift.axis == "hv_time"
    data = to_json(res, [], [])
    assert data["effects"] == []
    entry = next(u for u in data["unexplained"] if u["drift"])
    assert entry["axis"] == "hv_time"
    assert entry["drift_devices"]["hv_loss"]["wald_p_together"] == loss["wald_p_together"]


@pytest.mark.avx512_route
def test_weak_retention_is_not_taken_for_a_rise_lag_once_the_coast_downs_end_at_rest():
    # retention of 0.05/s with the whole library, 3 x 34 s (plant seed 13).  While each
    # coast-down ran on to the last change of a stopped wheel's flickering count, the rest
    # went into the parabola, tau_f came out low, and a rise lag was named here (with a
    # caution: it held beside the HV-time loss by a 5.4 % cut, 5 % needed).  With the
    # coast-downs ending where the wheel rests, tau_f is the plant's and nothing is named:
    # retention grows with the trials' speed and is refused, and beside the HV-time loss
    # the rise lag no longer cuts the free run.  A miss (the loss is weak on these short
    # trials), not a wrong name; the caution itself: test_ident_consistency.py
    res = SEL.identify(_trials(_retention(0.05), seed=13), k_folds=3, analyse_residuals=False)
    assert res.friction.tau_f == pytest.approx(WheelParams().tau_f, rel=0.02)
    assert res.chosen == ()
    why = {e.effects: e.codes for r in res.rounds for e in r}
    assert Reason.SWITCH_ON_LAG_STAND_IN in why[("charge_retention",)]
    assert Reason.HV_LOSS_LOOKALIKE in why[("rise_lag",)]


def test_an_effect_refused_in_a_bent_fit_is_refitted_from_the_reference_law():
    # a sensor eccentricity of 9.4 mrad, 3 x 34 s (plant seed 9589; a draw of
    # benchmarks/sweep_ident.py): the nominal fit stops at its limit with its force law
    # bent, and the eccentricity refitted from there (window RMSE 0.577 mrad, its amplitude
    # 3.8-7.4 mrad trial by trial) was refused as a stand-in; nothing was named, though the
    # true model runs the held-out trials 11x better.  A refit refused for its values while
    # the current fit stopped at its limit is fitted once more from the reference force law.
    # (Its rival, the off-centre mass, is left out of the library here: refitted twice too,
    # and refused as a stand-in both times, it cost the test 25 s)
    amp, phase = 0.009359965103300314, -1.73559707198218
    ecc = {"angle_eccentricity": {"enabled": True, "amplitude": {"value": amp, "unit": "rad"},
                                  "phase": {"value": phase, "unit": "rad"}}}
    res = SEL.identify(_trials(ecc, seed=9589), k_folds=3, max_effects=1,
                       library=C.library(exclude=["com_offset"]), analyse_residuals=False)
    (ev,) = [e for r in res.rounds for e in r if e.effects == ("angle_eccentricity",)]
    assert ev.accepted and ev.codes == [Reason.ACCEPTED, Reason.REFIT_FROM_REFERENCE]
    assert res.chosen == ("angle_eccentricity",)
    v = res.final.fit.values
    got = C.BY_ID["angle_eccentricity"].describe([v["E"], v["F"]])
    assert got["amplitude_rad"] == pytest.approx(amp, rel=0.05)
    assert got["phase_rad"] == pytest.approx(phase, abs=0.05)
    assert res.final.sim_heldout_rmse < 0.2 * res.nominal.sim_heldout_rmse


def test_strong_retention_that_bends_the_nominal_fit_is_screened_from_the_reference_law():
    # retention of 0.29/s, recovery 311 s, plant seed 3807 (a draw of
    # benchmarks/sweep_ident.py, 5 x 60 s; here three of its trials, phi_a 1, 5 and 9 deg):
    # the nominal fit bends its force law to follow the fading pushes and stops at its
    # limit, and from there no candidate's score test was significant (retention chi2 3-8 on
    # 5 x 60 s): nothing was named, though the true model runs the held-out trials 28x
    # better.  When the steps find nothing to refit and the fit looks
    # bent, each candidate is screened by a short fit from the reference force law as well
    rate, recovery = 0.29332667419442765, 310.72778178230834
    retention = {"charge_retention": {"enabled": True, "rate": {"value": rate, "unit": "1/s"},
                                      "recovery": {"value": recovery, "unit": "s"}}}
    res = SEL.identify(_trials(retention, seed=3807, specs=S.PAPER_SET[::2]), k_folds=3,
                       max_effects=1, analyse_residuals=False)
    assert {s.candidate: s for s in res.screenings[0]}["charge_retention"].restarted
    assert res.chosen == ("charge_retention",)
    assert res.final.fit.values["rate"] == pytest.approx(rate, rel=0.15)
    before, after = res.nominal.sim_heldout_rmse, res.final.sim_heldout_rmse
    assert after < 0.1 * before


#: the sensor and link defects the plant makes besides the encoder's noise: random counts
#: and lost samples, 0.2 % of the samples each
DEFECTS = {"encoder_glitches": {"enabled": True, "probability": {"value": 0.002, "unit": "1"}},
           "dropouts": {"enabled": True, "probability": {"value": 0.002, "unit": "1"}}}


@pytest.mark.parametrize("defects, seed", [({}, 5), (DEFECTS, 11)], ids=["clean", "defects"])
def test_on_data_without_an_effect_nothing_is_added(defects, seed):
    # with the defects, seed 11: a random count in a trial's tail at rest once kept the tail
    # (fit.at_rest_trimmed), whose constant residual was reported as "not white"
    res = SEL.identify(_trials(defects, seed=seed), k_folds=3)
    assert res.chosen == ()
    assert all(s.p_value > 1e-6 for s in res.screenings[0])
    # the scan finds no place where the effect is significant, so it adds no fit
    assert not any(s.scanned for r in res.screenings for s in r)
    # the nominal fit converged inside its ranges: no short fits from the reference either
    assert bent(Problem(res.trials), res.nominal.fit) is None
    assert not any(s.restarted for r in res.screenings for s in r)
    assert res.diagnostics_after.signatures == []


def test_a_platform_torque_through_a_delayed_link_is_found_with_an_unbent_force_law():
    # the platform torque through a link with 10 ms of latency each way and the defects
    # (plant seed 11).  Its fit once ended with the force law bent (peak 398, width 0.034;
    # held-out 0.1150 rad/s): rows that end an activation carried the next command's angle.
    # The restart from a poorer optimum (select.poorer_optimum, tested with stubs in
    # test_ident_candidates.py) mended it first, from a refused drag's fit; each activation
    # taking its own angles (fit.Problem) then removed the cause.  Either passes this test;
    # without both it fails
    link = {"serial_latency": {"enabled": True, "command": {"value": 0.01, "unit": "s"},
                               "telemetry": {"value": 0.01, "unit": "s"}}}
    platform = {"platform_disturbance": {"enabled": True,
                                         "torque": {"value": 0.004, "unit": "N*m"},
                                         "phase": {"value": 0.5, "unit": "rad"}}}
    res = SEL.identify(_trials({**platform, **DEFECTS, **link}, seed=11), k_folds=3,
                       analyse_residuals=False)
    assert res.chosen == ("platform_periodic",)
    assert res.final.sim_heldout_rmse < 0.5 * res.nominal.sim_heldout_rmse
    base = WheelParams()
    truth = model_error(res.trials, base, (C.BY_ID["platform_periodic"],),
                        dict(force_coordinates(base), tau_f=base.tau_f, P=0.004 * math.cos(0.5),
                             Q=0.004 * math.sin(0.5)))
    assert res.final.sim_heldout_rmse < 1.25 * truth
    assert res.final.fit.values["width"] == pytest.approx(force_coordinates(base)["width"],
                                                          rel=0.1)


def test_a_torque_a_closed_loop_leans_against_is_found_from_the_reference_force_law(
        tmp_path):
    # two 45 s runs of the embedded closed loop (observer and MPC) up to 2.2 rad/s and back
    # down to 1.6, so that it brakes, on a platform torque.  The loop answers the torque with
    # its pushes and brakes, so the nominal fit bends its force law to take it up (peak 244,
    # braking gain 49; the truth 20 and 3) and stops unconverged.  Screened only by one
    # Gauss-Newton step, from there and from the reference force law, the platform's refit
    # started in the bent law, fitted worse than the nominal model and was refused: nothing
    # named.  A short fit from the reference force law (screen.bent) finds it.  The
    # reference is not the wheel: a user's reference values are only near their wheel's, so
    # here every one of them is off (peak +30 %, ln contact angle +0.1, width +20 %, b -20 %,
    # tau_f +15 %, braking gain 2x)
    trials = S.closed_loop_trials(PLATFORM, ((0.0, 1.0), (15.0, 2.2), (30.0, 1.6)), 45.0,
                                  (3, 4), tmp_path)
    truth = WheelParams()
    c = force_coordinates(truth)
    base = from_force_coordinates(truth, 1.3 * c["peak"], c["centre"] + 0.1, 1.2 * c["width"],
                                  0.8 * c["b"], tau_f=1.15 * truth.tau_f,
                                  brake_gain=2.0 * truth.brake_gain)
    # one round: the search for a second effect is tested elsewhere
    res = SEL.identify(trials, base=base, k_folds=2, max_effects=1, analyse_residuals=False)
    why = bent(Problem(trials, base), res.nominal.fit)
    assert why is not None
    assert res.chosen == ("platform_periodic",)
    # the platform's refit started from the short fit, not from a step
    first = {s.candidate: s for s in res.screenings[0]}["platform_periodic"]
    assert first.restarted and first.p_value < 1e-6
    got = C.BY_ID["platform_periodic"].describe([res.final.fit.values["P"],
                                                 res.final.fit.values["Q"]])
    assert got["torque_N_m"] == pytest.approx(0.004, rel=0.05)
    assert got["phase_rad"] == pytest.approx(1.0, abs=0.05)
    assert res.final.sim_heldout_rmse <= 0.5 * res.nominal.sim_heldout_rmse
    assert res.final.fit.values["brake_gain"] == pytest.approx(truth.brake_gain, rel=0.1)
    assert res.final.fit.values["tau_f"] == pytest.approx(truth.tau_f, rel=0.05)


def test_a_periodic_torque_that_gains_could_imitate_is_not_forced_onto_them():
    # an off-centre mass with its candidate left out: fifteen free gains can imitate it (on
    # 5 x 60 s their refit cut the held-out error by 65 %; candidates.spread_pattern refuses
    # such a pattern, tested in test_ident_candidates.py); here nothing is chosen, and the
    # signature is the torque, sized by the refit at its period
    lib = C.library(exclude=["com_offset"])
    com = {"com_offset": {"enabled": True, "torque": {"value": 0.004, "unit": "N*m"},
                          "phase": {"value": 1.0, "unit": "rad"}}}
    res = SEL.identify(_trials(com), library=lib, k_folds=3)
    assert res.chosen == ()
    sig = [s for s in res.diagnostics_after.signatures if s.axis == "wheel_angle"]
    assert sig and sig[0].period == pytest.approx(2 * math.pi, rel=0.02)
    # -0.004 sin(xi1 + 1.0) = 0.004 sin(xi1 + 1.0 - pi)
    assert sig[0].torque == pytest.approx(0.004, rel=0.1)
    assert sig[0].phase == pytest.approx(1.0 - math.pi, abs=0.1)


def test_a_refit_refused_on_all_trials_is_not_cross_validated():
    # a fit whose values are refused (an implausible gain pattern) cannot be accepted, so
    # its folds are not fitted: on 5 x 60 s with an off-centre mass outside the library that
    # saved 33 s of 153 (benchmarks/bench_ident.py).  The gates need no long trials: three
    # of 8 s driven and 3 s coasting
    short = tuple(dataclasses.replace(s, drive=8.0, coast=3.0) for s in SET)
    trials = S.record_set(short, config=PlantConfig(seed=3, switching="tick",
                                                    effects=effects_from_mapping(ENCODER)))
    folds = EV.folds_of(len(trials), 3)
    asked = []

    def refuse(fit):
        asked.append(fit.rmse)
        return "implausible values"

    ev = EV.evaluate(trials, WheelParams(), (), 1.0, {}, folds, refuse=refuse)
    assert asked == [ev.fit.rmse]
    assert math.isnan(ev.heldout_rmse) and not ev.fold_values and not ev.sim_heldout
    # nor is a fit whose simulation error on its own trials (scored before the gates) does
    # not fall below the current model's: the same fit here, the runs being deterministic
    fitted = pooled_rmse(ev.sim_fitted)
    same = EV.evaluate(trials, WheelParams(), (), 1.0, {}, folds, sim_below=fitted)
    assert pooled_rmse(same.sim_fitted) == fitted
    assert math.isnan(same.heldout_rmse) and not same.fold_values
    # a refuse that finds nothing lets the folds run, and so does a bar just above the
    # fit's error, with the same fold results as a run without any gate
    ok = EV.evaluate(trials, WheelParams(), (), 1.0, {}, folds, refuse=lambda fit: None)
    assert ok.heldout_rmse > 0.0 and set(ok.fold_values) == {t.name for t in trials}
    assert set(ok.sim_heldout) == {t.name for t in trials}
    above = EV.evaluate(trials, WheelParams(), (), 1.0, {}, folds, sim_below=1.001 * fitted)
    assert above.heldout_rmse == ok.heldout_rmse and above.fold_values == ok.fold_values


def test_an_effect_outside_the_library_is_reported_not_forced():
    # the platform disturbance is periodic in the pivot angle psi = (r/L) xi1; without its
    # candidate nothing may be chosen, and the residual must show that period and size
    lib = C.library(exclude=["platform_periodic"])
    res = SEL.identify(_trials(PLATFORM), library=lib, k_folds=3)
    assert res.chosen == ()
    # a refit that was not cross-validated says so, and why
    for ev in (e for r in res.rounds for e in r):
        assert math.isnan(ev.heldout_rmse) == (Reason.NOT_CROSS_VALIDATED in ev.codes)
    sig = [s for s in res.diagnostics_after.signatures if s.axis == "pivot_angle"]
    assert sig, [s.text for s in res.diagnostics_after.signatures]
    assert sig[0].period == pytest.approx(2 * math.pi, rel=0.02)      # once per pivot lap
    # size and phase: the residual alone shows only what the nominal fit did not absorb
    # (0.0027 of 0.004 N*m here), so the signature is sized by refitting a torque at its
    # period with the model: 0.004 sin(psi + 1.0), and the interval holds it
    assert sig[0].torque == pytest.approx(0.004, rel=0.1)
    assert sig[0].phase == pytest.approx(1.0, abs=0.1)
    assert sig[0].torque_ci95[0] < 0.004 < sig[0].torque_ci95[1]


@ON_COM_WORKER
def test_the_report_carries_the_documented_keys_and_a_loadable_model(com_identification,
                                                                     tmp_path):
    data = write_report(com_identification, tmp_path)
    on_disk = json.loads((tmp_path / "report.json").read_text())
    assert on_disk["chosen_effects"] == ["com_offset"] == data["chosen_effects"]
    for key in ("schema", "trials", "friction", "nominal", "effects", "candidates",
                "near_misses", "unexplained", "metrics", "diagnostics", "paper_table3", "model_file",
                "figures", "fits", "session"):
        assert key in on_disk
    # trials without a session time: taken in the order given, the report says so
    ses = on_disk["session"]
    assert ses["timed"] is False and ses["warning"] and ses["gain_step"] is None
    assert [c["session_t_s"] for c in ses["coast_friction"]] == [None] * len(
        ses["coast_friction"]) and ses["friction_trend"] is None
    # every trial says what rest at its end the fits left out: these open-loop trials end in
    # a coast-down to rest, with nothing scheduled, so none is a stall
    for t in on_disk["trials"]:
        rt = t["rest_tail"]
        assert rt is not None and rt["scheduled_share"] == 0.0 and rt["stalled"] is False
        assert rt["text"] is None
    assert "Stalled" not in (tmp_path / "report.md").read_text()
    # the fits' status is the record's, whatever the optimiser did
    final = on_disk["fits"]["final"]
    assert final == {"converged": com_identification.final.fit.converged,
                     "evaluations": com_identification.final.fit.nfev,
                     "message": com_identification.final.fit.message}
    assert all(c["converged"] is None for c in on_disk["candidates"] if not c["refitted"])
    # every candidate's verdict is in codes: a refitted one's are its record's, one that was
    # not refitted says why
    for c in on_disk["candidates"]:
        assert c["codes"] and all(Reason(code) for code in c["codes"])
        if not c["refitted"]:
            assert c["codes"] in (["score_not_significant"], ["others_more_promising"])
    assert "accepted" in next(c["codes"] for c in on_disk["candidates"]
                              if c["id"] == "com_offset" and c["accepted"])
    # every refit carries the values it reached, accepted or not, in the candidate's own
    # parameters (with 95 % intervals) and in physical terms; the off-centre mass's are the
    # plant's (0.004 N*m at 0.5 rad)
    for c in on_disk["candidates"]:
        if not c["refitted"]:
            assert c["parameters"] is None and c["physical"] is None
            continue
        assert list(c["parameters"]) == [p.name for p in C.BY_ID[c["id"]].params]
        for p in c["parameters"].values():
            assert None not in p["ci95"] and p["ci95"][0] <= p["value"] <= p["ci95"][1]
    com = next(c for c in on_disk["candidates"] if c["id"] == "com_offset" and c["accepted"])
    assert com["physical"]["torque_N_m"] == pytest.approx(0.004, rel=0.05)
    assert com["physical"]["phase_rad"] == pytest.approx(0.5, abs=0.05)
    assert com["parameters"]["A"]["unit"] == "N*m"
    # report.md's candidates table: every row has the header's cells, and the fitted values
    md = (tmp_path / "report.md").read_text().splitlines()
    head = md.index(next(r for r in md if r.startswith("| round | candidate |")))
    rows = md[head:md.index("", head)]
    assert len(rows) == 2 + len(on_disk["candidates"]) + len(on_disk["tried_together"])
    assert {r.count(" | ") for r in rows if not r.startswith("|---")} == {7}
    assert any("`com_offset`" in r and "torque_N_m 0.00" in r for r in rows)
    # ran_on marks the record's ran_on_from and nothing else
    ran_on = com_identification.ran_on_from
    assert [c["id"] for c in on_disk["candidates"] if c["ran_on"]] == (
        [] if ran_on is None else [ran_on.effects[-1]])
    chosen = on_disk["effects"][0]
    assert chosen["id"] == "com_offset"
    assert chosen["physical"]["torque_N_m"] == pytest.approx(0.004, rel=0.05)
    for name in on_disk["figures"]:
        assert (tmp_path / name).stat().st_size > 5000
    per_trial = on_disk["metrics"]["after"]["simulation"]["per_trial"]
    assert set(per_trial) == {t.name for t in com_identification.trials}
    prediction = on_disk["metrics"]["after"]["prediction"]
    assert set(prediction) == {t.name for t in com_identification.trials}
    assert all(0.0 <= p["whiteness_outside"] <= 1.0 and p["rms_rad"] > 0
               for p in prediction.values())
    # the physical values come with intervals that hold the truth
    lo, hi = on_disk["effects"][0]["physical_ci95"]["torque_N_m"]
    assert lo < 0.004 < hi and hi - lo < 0.001
    # a physical off-centre mass is one value in every trial and through each drive: its
    # checks are reported, without a caution
    k = on_disk["effects"][0]["consistency"]
    assert k["caution"] is None and k["speed_trend_p"] > 1e-3 and k["drift_p"] > 1e-3
    assert k["beside_hv_loss"] is None            # it does not drift: not refitted beside
    assert abs(k["speed_exponent"]) < 0.5 and abs(k["drift_exponent"]) < 0.05
    params, ext = load_model(tmp_path / on_disk["model_file"])
    assert ext.com_torque == pytest.approx(0.004, rel=0.05)
    assert ext.com_phase == pytest.approx(0.5, abs=0.05)
    assert params.tau_f == pytest.approx(com_identification.final.fit.values["tau_f"])
    md = (tmp_path / "report.md").read_text()
    assert "com_offset" in md and "Table III" in md
    assert "refitted trial by trial: size ~ speed^k" in md and "caution" not in md
    assert fit_status_text(com_identification.final, "identified") in md


@ON_COM_WORKER
def test_a_refit_that_ran_on_is_marked_in_the_report(com_identification):
    # built from the known record: the accepted off-centre mass refit is the one that ran on
    refit = next(e for r in com_identification.rounds for e in r
                 if e.effects == ("com_offset",) and e.accepted)
    ident = dataclasses.replace(com_identification, ran_on_from=refit)
    data = to_json(ident, [], [])
    assert [c["id"] for c in data["candidates"] if c["ran_on"]] == ["com_offset"]
    rows = [r for r in to_markdown(ident, data).splitlines() if r.startswith("| 1 | `com_offset`")]
    assert len(rows) == 1 and RAN_ON_NOTE in rows[0]


@ON_COM_WORKER
def test_a_fit_stopped_at_its_limit_is_reported_as_not_converged(com_identification):
    ev = dataclasses.replace(com_identification.nominal, fit=dataclasses.replace(
        com_identification.nominal.fit, converged=False, nfev=100,
        message="The maximum number of function evaluations is exceeded."))
    text = fit_status_text(ev, "nominal")
    assert "did not converge" in text and "limit of 100 evaluations" in text
    done = dataclasses.replace(ev, fit=dataclasses.replace(ev.fit, converged=True, nfev=42))
    assert fit_status_text(done, "identified") == ("The identified fit converged after 42 "
                                                    "evaluations.")


@ON_COM_WORKER
def test_the_one_step_prediction_residual_is_white_only_with_the_missing_effect(
        com_identification):
    # the observer's innovations under the nominal model stay correlated over many samples
    # (a once-per-turn torque it is told nothing about); with the identified COM offset they
    # are close to white and close to the size the observer predicts
    before = list(com_identification.prediction_before.values())
    after = list(com_identification.prediction_after.values())
    assert all(b.whiteness_outside > 0.5 for b in before)
    assert all(a.whiteness_outside < 0.2 for a in after)
    assert all(a.normalised_rms < b.normalised_rms for a, b in zip(after, before))
    assert all(0.8 < a.normalised_rms < 1.3 for a in after)
