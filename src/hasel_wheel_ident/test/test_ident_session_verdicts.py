"""The identification of whole sessions whose effects carry from one trial to the next
(synthetic.session_trials: the five paper trials back to back, 20 s at rest between them,
read from CSVs with session_t or from one bag): retention carried over is named with its
rate, a friction drift is measured along session time, a pad that breaks down between two
trials is named with its gains before and after, and a clean session names nothing.

Each case is a whole identification of 5 x 60 s (minutes), so the module is marked
``slow``: ``./dev test --slow`` runs it."""
import pytest

from hasel_wheel_ident import select as SEL
from hasel_wheel_ident import synthetic as S
from hasel_wheel_ident import truth_cases as T
from hasel_wheel_ident.session import as_session

pytestmark = pytest.mark.slow

RETENTION = {"charge_retention": {"enabled": True, "rate": {"value": 0.05, "unit": "1/s"},
                                  "recovery": {"value": 300.0, "unit": "s"}}}


@pytest.mark.parametrize("via", ["csv", "bag"])
def test_retention_that_persists_through_the_session_is_named_with_its_rate(via, tmp_path):
    trials = S.session_trials(RETENTION, via=via, directory=tmp_path)
    res = SEL.identify(trials, k_folds=5)
    assert res.chosen[:1] == ("charge_retention",)
    assert res.final.fit.values["rate"] == pytest.approx(0.05, rel=0.2)
    before, after = res.nominal.sim_heldout_rmse, res.final.sim_heldout_rmse
    true = T.true_model_error(as_session(trials).trials, "charge_retention",
                              {"rate": 0.05, "recovery": 300.0})
    assert before / true >= 2.0 and before / after >= 2.0


def test_friction_rising_over_the_session_is_measured_along_session_time(tmp_path):
    rate = 0.25 / 420.0
    trials = S.session_trials({}, S.SessionChanges(friction_rate=rate), directory=tmp_path)
    res = SEL.identify(trials, k_folds=5)
    assert res.chosen == ()                 # the library has no drifting friction
    assert res.friction_trend is not None and res.friction_trend.significant
    assert res.friction_trend.rate == pytest.approx(rate, rel=0.2)
    assert "session_time" in [s.axis for s in res.diagnostics_after.signatures]


def test_a_pad_that_breaks_down_between_trials_is_named_with_when_and_its_gains(tmp_path):
    trials = S.session_trials({}, S.SessionChanges(step_pad=5, step_trial=2, step_factor=0.15),
                              directory=tmp_path)
    res = SEL.identify(trials, k_folds=5)
    step = res.gain_step
    assert step is not None and (step.pad, step.index) == (5, 2)
    assert step.trial == as_session(trials).trials[2].name
    assert step.before == pytest.approx(1.0, rel=0.1)
    assert step.after == pytest.approx(0.15, rel=0.1)
    _, ext, _ = res.model()
    others = [g for i, g in enumerate(ext.gains) if i != 5]
    assert ext.gains[5] / sorted(others)[7] == pytest.approx(0.15, rel=0.1)


def test_a_clean_session_names_nothing(tmp_path):
    res = SEL.identify(S.session_trials({}, directory=tmp_path), k_folds=5)
    assert res.chosen == ()
    assert res.gain_step is None
    assert res.friction_trend is not None and not res.friction_trend.significant
