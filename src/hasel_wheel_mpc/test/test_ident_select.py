"""The effect search on data with an effect the tool is not told about: it must name it,
estimate it, and cut the held-out error at least in half."""
import math

import pytest

from hasel_wheel_mpc.ident import candidates as C
from hasel_wheel_mpc.ident import select as SEL
from hasel_wheel_mpc.ident import synthetic as S
from hasel_wheel_sim.effects import effects_from_mapping
from hasel_wheel_sim.plant import PlantConfig

EFFECTS = {
    "encoder": {"enabled": True, "noise_std": {"value": 0.001, "unit": "rad"}},
    "com_offset": {"enabled": True, "torque": {"value": 0.004, "unit": "N*m"},
                   "phase": {"value": 0.5, "unit": "rad"}},
}
SET = tuple(S.SyntheticTrial(math.radians(a), drive=25.0, coast=9.0) for a in (1.0, 4.0, 7.0))


def test_an_undeclared_com_offset_is_named_and_measured():
    trials = S.record_set(SET, config=PlantConfig(seed=3, switching="tick",
                                                  effects=effects_from_mapping(EFFECTS)))
    lib = C.library(["viscous_drag", "com_offset", "rise_lag"])
    res = SEL.identify(trials, library=lib, k_folds=3, max_effects=1, analyse_residuals=False)
    assert res.chosen == ("com_offset",)
    assert res.final.heldout_rmse <= 0.5 * res.nominal.heldout_rmse
    got = C.BY_ID["com_offset"].describe([res.final.fit.values["A"], res.final.fit.values["B"]])
    assert got["torque_N_m"] == pytest.approx(0.004, rel=0.05)
    assert got["phase_rad"] == pytest.approx(0.5, abs=0.05)
    # the other candidates were tried and refused, with the reason on record
    refused = [e for e in res.rounds[0] if not e.accepted]
    assert {e.effects[0] for e in refused} == {"viscous_drag", "rise_lag"}
    assert all("held-out RMSE" in e.reason for e in refused)
