"""The identification's acceptance cases (hasel_wheel_ident.truth_cases), each a test that
fails when the search concludes wrongly: undeclared effects in the library named and
measured against the plant's values, or missed only below the floor; losses outside the
library named as nothing, with the drift along their own axis.

Every case is a whole identification (3 x 34 s: seconds to a minute; 5 x 60 s: up to a few
minutes), so the module is marked ``slow``: ``./dev test --slow`` runs it, ``./dev test``
leaves it out."""
import pytest

from hasel_wheel_ident import candidates as C
from hasel_wheel_ident import select as SEL
from hasel_wheel_ident import synthetic as S
from hasel_wheel_ident import truth_cases as T
from hasel_wheel_ident import verdict as V

pytestmark = pytest.mark.slow


@pytest.mark.parametrize("case", T.IN_LIBRARY, ids=lambda c: c.id)
def test_an_undeclared_effect_in_the_library_is_named_and_measured_or_missed_below_the_floor(
        case):
    trials = S.encoder_trials(case.effects, seed=case.seed, specs=case.specs)
    res = SEL.identify(trials, k_folds=min(5, len(trials)))
    before, after = res.nominal.sim_heldout_rmse, res.final.sim_heldout_rmse
    floor = (T.true_model_error(trials, case.cid, case.true_values)
             if case.true_values is not None else None)
    assert V.verdict(res.chosen, case.cid, before, floor) == case.expect, res.chosen
    if case.expect != "right":
        return
    got = T.estimates(case.cid, res)
    for name, (truth, tol) in case.within.items():
        assert abs(got[name] - truth) <= tol, (name, got[name], truth)
    assert before / after >= case.min_cut


@pytest.mark.parametrize("case", T.LOOK_ALIKES, ids=lambda c: c.id)
def test_a_loss_outside_the_library_names_nothing_and_drifts_along_its_own_axis(case):
    trials = S.encoder_trials(case.effects, seed=case.seed, specs=case.specs)
    res = SEL.identify(trials, k_folds=min(5, len(trials)), library=C.library(exclude=[case.cid]))
    code, figures = T.look_alike_code(res, case)
    assert code in T.LOOK_ALIKE_RIGHT, figures


@pytest.mark.parametrize("whole_library", [False, True], ids=["left out", "whole library"])
def test_drag_outside_the_library_leaves_a_falling_trend_and_inside_it_is_named(whole_library):
    trials = S.encoder_trials(T.DRAG_OUTSIDE, seed=T.DRAG_SEED)
    lib = C.LIBRARY if whole_library else C.library(exclude=["viscous_drag"])
    res = SEL.identify(trials, library=lib, k_folds=3)
    assert T.drag_failures(res, whole_library) == []


def test_an_eccentric_sensor_outside_the_library_leaves_a_once_per_turn_signature():
    trials = S.encoder_trials(T.ECCENTRIC_OUTSIDE, seed=T.ECCENTRIC_SEED)
    res = SEL.identify(trials, k_folds=3, library=C.library(exclude=["angle_eccentricity"]),
                       analyse_residuals=True)
    assert T.eccentricity_failures(res) == []
