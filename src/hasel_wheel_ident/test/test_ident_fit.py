"""Identification of the nominal model: recovery of known parameters from plant data through
the 10-bit encoder, and the identifiability report against the analytic null directions."""
import dataclasses
import math

import numpy as np
import pytest

from hasel_wheel_ident import data as D
from hasel_wheel_ident import fit as F
from hasel_wheel_ident import identifiability as I
from hasel_wheel_ident import synthetic as S
from hasel_wheel_ident.screen import bent
from hasel_wheel_sim import layout as L
from hasel_wheel_sim.effects import effects_from_mapping
from hasel_wheel_sim.model import param_vector
from hasel_wheel_sim.params import WheelParams
from hasel_wheel_sim.plant import PlantConfig

ENCODER = S.ENCODER
TRUE = WheelParams()
SET = tuple(S.SyntheticTrial(math.radians(a), drive=30.0, coast=9.0) for a in (1.0, 4.0, 7.0))


@pytest.fixture(scope="module")
def nominal_trials():
    return S.record_set(SET, config=PlantConfig(seed=5, switching="tick",
                                                effects=effects_from_mapping(ENCODER)))


def test_force_coordinates_round_trip():
    c = F.force_coordinates(TRUE)
    back = F.from_force_coordinates(TRUE.with_values(sigma4=-0.5, sigma6=3.0), **c)
    for k in ("sigma2", "sigma4", "sigma5", "sigma6"):
        assert getattr(back, k) == pytest.approx(getattr(TRUE, k), rel=1e-12)
    # the bump's top is where the model notes put it: exp(centre) ~ 0.36 rad (~21 deg)
    assert math.exp(c["centre"]) == pytest.approx(0.364, abs=0.002)


def test_nominal_parameters_are_recovered(nominal_trials):
    fr = F.coastdown_friction(nominal_trials, TRUE)
    assert fr.tau_f == pytest.approx(TRUE.tau_f, rel=0.02)
    start = TRUE.with_values(sigma6=TRUE.sigma6 * 0.85, sigma2=TRUE.sigma2 * 1.15,
                             sigma4=TRUE.sigma4 * 0.97)
    res = F.Problem(nominal_trials, start).fit(start={"tau_f": fr.tau_f})
    assert res.converged, res.message
    true = F.force_coordinates(TRUE)
    for name in ("peak", "centre", "width", "b"):
        assert res.values[name] == pytest.approx(true[name], rel=0.05), name
    assert res.values["tau_f"] == pytest.approx(TRUE.tau_f, rel=0.02)
    # residual at the encoder's floor: quantisation (6.1 mrad / sqrt(12)) with 1 mrad noise
    assert res.rmse < 1.15 * math.hypot(2 * math.pi / 1024 / math.sqrt(12), 0.001)


def test_identifiability_finds_both_structural_null_directions(nominal_trials):
    short = [t.slice(0, 3000) for t in nominal_trials]
    ident = I.identifiability(F.Problem(short, TRUE), TRUE)
    s = ident.singular_values
    assert s[-1] < 1e-5 and s[-2] < 1e-5 and s[-3] > 1e-4      # exactly two, and only two
    null = ident.directions[-2:]                                # rows span the null space
    for v in (I.ratio_null_direction(), I.bump_null_direction(TRUE)):
        resid = v - null.T @ (null @ v)
        assert np.linalg.norm(resid) < 1e-3
    assert len(ident.undetermined()) == 2


def test_the_paper_trial_set_is_recovered_through_the_encoder():
    # the paper's five trials (phi_a 1..9 deg, 50 s + 10 s coast): taking each encoder
    # reading as the angle biased the peak by +5.5 % (aliased quantisation); the distance
    # from the count interval removes that bias, and every coordinate lands within 5 %
    trials = S.record_set(config=PlantConfig(seed=3, switching="tick",
                                             effects=effects_from_mapping(ENCODER)))
    prob = F.Problem(trials, TRUE)
    assert prob.quantum == pytest.approx(2 * math.pi / 1024)
    fr = F.coastdown_friction(trials, TRUE)
    res = prob.fit(start={"tau_f": fr.tau_f})
    true = F.force_coordinates(TRUE)
    for name in ("peak", "centre", "width", "b"):
        assert res.values[name] == pytest.approx(true[name], rel=0.05), name
    assert res.values["tau_f"] == pytest.approx(TRUE.tau_f, rel=0.02)
    plain = F.Problem(trials, TRUE, quantised=False).fit(start={"tau_f": fr.tau_f})
    assert abs(res.values["peak"] / true["peak"] - 1) < 0.5 * abs(plain.values["peak"] /
                                                                  true["peak"] - 1)


def test_encoder_quantum_is_found_only_in_counts():
    c = 2 * math.pi / 1024
    counts = np.cumsum(np.r_[0, np.random.default_rng(0).integers(0, 4, 500)]) * c
    assert F.encoder_quantum(counts + 7 * c) == pytest.approx(c)
    assert F.encoder_quantum(counts + 1e-3 * np.random.default_rng(1).normal(size=501)) is None


def test_the_braking_gain_is_fitted_when_the_data_brakes():
    # braking activations (phi_a, phi_d < 0) in the data add brake_gain to the fit; start it
    # 30 % off and it must come back within 5 % (it scales the braking force alone)
    brake = (4.0, math.radians(-22.0), math.radians(-20.0))
    specs = (S.SyntheticTrial(math.radians(3.0), drive=15.0, coast=5.0, brake=brake),
             S.SyntheticTrial(math.radians(6.0), drive=15.0, coast=5.0, brake=brake))
    trials = S.record_set(specs, config=PlantConfig(seed=2, switching="tick",
                                                    effects=effects_from_mapping(ENCODER)))
    assert any(a.phi_a < 0 for tr in trials for a in tr.activations)
    prob = F.Problem(trials, TRUE.with_values(brake_gain=TRUE.brake_gain * 1.3))
    assert "brake_gain" in prob.names
    res = prob.fit(start={"tau_f": TRUE.tau_f})
    assert res.values["brake_gain"] == pytest.approx(TRUE.brake_gain, rel=0.05)


def test_a_fit_that_stopped_or_ended_on_a_bound_is_called_bent(nominal_trials):
    prob = F.Problem(nominal_trials)
    res = prob.fit(start={"tau_f": TRUE.tau_f})
    assert res.converged and prob.at_bounds(res) == [] and bent(prob, res) is None
    short = prob.fit(start={"peak": 2.0 * res.values["peak"]}, max_nfev=2)
    assert not short.converged and bent(prob, short) == "stopped unconverged after 2 evaluations"
    # the width's range is 0.01..2 (fit.nominal_specs): a fit that ended on its floor
    edge = dataclasses.replace(res, values={**res.values, "width": 0.01})
    assert prob.at_bounds(edge) == ["width"] and bent(prob, edge) == "width on its bound"
    inside = dataclasses.replace(res, values={**res.values, "width": 0.01 + 1e-3})
    assert bent(prob, inside) is None
    both = dataclasses.replace(short, values={**res.values, "width": 2.0, "tau_f": 1e-5})
    assert bent(prob, both) == ("stopped unconverged after 2 evaluations; width, tau_f on their "
                                "bounds")


def test_a_kept_span_weighs_only_its_samples_and_keeps_the_history_before_it(nominal_trials):
    tr = nominal_trials[0]
    everything = F.Problem([tr], TRUE)
    span = (10.0, 20.0)
    kept = F.Problem([tr], TRUE, keep=span)
    inside = (kept.t >= span[0]) & (kept.t < span[1])
    assert np.array_equal(kept.ok, everything.ok & inside)
    assert kept.window == everything.window and np.array_equal(kept.starts, everything.starts)
    # the retained charge runs from the trial's start, not from the span's: the gains of a
    # retention model are the same sample for sample
    pv = param_vector(TRUE)
    pv[L.P_RET_RATE], pv[L.P_RET_RECOVERY] = 0.2, 300.0
    assert np.array_equal(kept.gains(pv), everything.gains(pv))
    assert np.any(kept.gains(pv)[inside] < 0.99)
    # outside the span the residual is 0, inside it is the whole problem's
    z = np.concatenate([[F.force_coordinates(TRUE)[k] for k in ("peak", "centre", "width", "b")],
                        [TRUE.tau_f], everything.initial_starts().ravel()])
    r_all, r_kept = everything.residual(z).copy(), kept.residual(z).copy()
    assert np.all(r_kept[~inside] == 0.0)
    assert np.array_equal(r_kept[inside], r_all[inside])


def test_the_force_takes_each_activations_own_angle_not_the_rows(nominal_trials):
    # a host logs its schedule when it sends it and the wheel's state when it arrives: with
    # a link delay the schedule columns lead.  Here they lead by three rows, so the rows that
    # end each activation already carry the next command's angles (after the priming pushes
    # at 3 deg, phi_a 7 deg where the contact angle is still below it), and the rows after
    # the drive have none.  The window fit at the true values must not change
    tr = nominal_trials[2]
    cols = {c: getattr(tr, c).copy() for c in ("t", "angle", "q", "eta", "n_a", "phi_a",
                                                 "phi_d")}
    for c in ("n_a", "phi_a", "phi_d"):
        cols[c][:-3] = cols[c][3:]
        cols[c][-3:] = -1 if c == "n_a" else math.nan
    led = D.Trial(tr.name, **cols)
    assert [(a.start, a.stop, a.eta, a.phi_a) for a in led.activations] == [
        (a.start, a.stop, a.eta, a.phi_a) for a in tr.activations]
    on = tr.q == 1
    assert np.any(on & (np.nan_to_num(led.phi_a) != np.nan_to_num(tr.phi_a)))  # it is real
    values = np.array([F.force_coordinates(TRUE)[n] for n in ("peak", "centre", "width", "b")]
                      + [TRUE.tau_f])
    rms = []
    for t in (tr, led):
        problem = F.Problem([t], TRUE)
        _, r, _, _ = problem.solve_starts(problem.full_theta(values), problem.initial_starts())
        rms.append(float(np.sqrt(np.mean(r[problem.ok] ** 2))))
    assert rms[1] == rms[0]
    np.testing.assert_array_equal(F.Problem([led], TRUE).phi_a, F.Problem([tr], TRUE).phi_a)
