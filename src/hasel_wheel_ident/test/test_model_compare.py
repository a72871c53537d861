"""Closing the identification loop: one plant with an off-centre mass, controlled once with the
paper's model and once with the true (identified) extensions; metrics are deterministic.

The plant: com_offset 0.004 N*m at 0.5 rad (the example in docs/identification.md) plus the
10-bit encoder, ticks, seed 1; 20 s at 1.0 rad/s then 20 s at 1.5 rad/s (about 4 s wall per
pair of runs).  The effect's convention -T sin(xi1 + phase) (effects.py) is the model's
Extensions.com_torque/com_phase term (model.py), and EffectsConfig.extensions() copies them
one to one, so Extensions(com_torque=0.004, com_phase=0.5) is the plant's exact physics.
"""
import math

import numpy as np
import pytest

from hasel_wheel_mpc import closed_loop
from hasel_wheel_ident.model_compare import compare_controllers, tracking_metrics
from hasel_wheel_mpc.observer import ObserverConfig
from hasel_wheel_sim.effects import effects_from_mapping
from hasel_wheel_sim.model import Extensions
from hasel_wheel_sim.params import WheelParams
from hasel_wheel_sim.plant import PlantConfig

TORQUE, PHASE = 0.004, 0.5                       # [N*m], [rad]
EFFECTS = {"com_offset": {"enabled": True, "torque": {"value": TORQUE, "unit": "N*m"},
                          "phase": {"value": PHASE, "unit": "rad"}},
           "encoder": {"enabled": True, "noise_std": {"value": 0.001, "unit": "rad"}}}
PLANT = PlantConfig(seed=1, switching="tick", effects=effects_from_mapping(EFFECTS))
PROFILE = ((0.0, 1.0), (20.0, 1.5))              # (start [s], reference [rad/s])
DURATION = 40.0                                  # [s]
MODELS = {"nominal": (WheelParams(), None),
          "true": (WheelParams(), Extensions(com_torque=TORQUE, com_phase=PHASE))}


@pytest.fixture(scope="module")
def default_observer():
    """Both models with the observer as configured for the demo (its a_d state on)."""
    return compare_controllers(None, PLANT, MODELS, PROFILE, DURATION)


@pytest.fixture(scope="module")
def no_disturbance_state():
    """Both models with the observer's acceleration-disturbance states (c, a, b, e, f) off."""
    return compare_controllers(None, PLANT, MODELS, PROFILE, DURATION,
                               observer_config=ObserverConfig(disturbance_rate=0.0,
                                                                 pivot_rate=0.0))


def test_metrics_are_sane(default_observer):
    for m in default_observer.values():
        assert set(m) >= {"rmse", "nrmse", "segment_mean_error", "segment_steady_error", "segments"}
        assert 0.0 < m["rmse"] < 0.1 and 0.0 < m["nrmse"] < 0.1          # [rad/s], [1]
        assert len(m["segment_mean_error"]) == len(m["segment_steady_error"]) == 2
        assert m["deadline_misses"] == 0 and m["braking"] == 0 and m["decisions"] > 100


def test_the_true_model_tracks_as_well_as_the_nominal_one(default_observer):
    # Measured (seed 1, 2 s settling): RMSE nominal 0.0535, true 0.0539 rad/s; NRMSE 0.0431 both.
    # The true model does NOT track measurably better here, and should not be expected to: the
    # observer's a_d(xi1) = c + a cos xi1 + b sin xi1 has exactly the COM torque's form
    # (-T sin(xi1 + phase) / J gives a = -T sin(phase)/J, b = -T cos(phase)/J), so the nominal
    # controller learns the offset online within a few turns (test_observer recovers it) and
    # predicts with it.  Over seeds 0..5 the ratio true/nominal is 0.83 .. 1.05 (mean RMSE
    # 0.0555 vs 0.0536 rad/s): noise of either sign.  We assert "no worse than 5 %" on this
    # fixed, deterministic run (ratio 1.007).
    nom, true = default_observer["nominal"], default_observer["true"]
    assert true["rmse"] <= 1.05 * nom["rmse"]
    assert true["nrmse"] <= 1.05 * nom["nrmse"]


def test_the_true_model_is_what_tracks_when_the_observer_cannot_learn_the_offset(no_disturbance_state):
    # Without the observer's (c, a, b) only the model knows the offset.  T/J = 0.004/0.0358
    # = 0.112 rad/s^2; at 1 rad/s that is a once-per-turn speed swing of up to ~0.11 rad/s
    # (0.08 rad/s RMS) if nothing counters it.  Measured (seed 1, 2 s settling): RMSE nominal
    # 0.0828, true 0.0518 rad/s (ratio 0.63; seeds 0..5: 0.61 .. 0.74);
    # the true model's RMSE equals the default observer's (0.054), the nominal one's does not.
    # Steady error at 1.0 rad/s: 0.80 % nominal, 0.10 % true.  A sign or phase error in the
    # convention would double the disturbance instead and make "true" the worse one.
    nom, true = no_disturbance_state["nominal"], no_disturbance_state["true"]
    assert true["rmse"] <= 0.75 * nom["rmse"]
    assert true["nrmse"] <= 0.75 * nom["nrmse"]
    assert true["segment_steady_error"][0] < 0.5 * nom["segment_steady_error"][0]


def test_same_seed_same_metrics(default_observer):
    # the nominal run again, and once with explicit all-off extensions (the same model)
    again = compare_controllers(None, PLANT, {"again": MODELS["nominal"],
                                              "zero": (WheelParams(), Extensions())},
                                PROFILE, DURATION, seed=1)
    np.testing.assert_equal(again["again"], default_observer["nominal"])
    np.testing.assert_equal(again["zero"], default_observer["nominal"])


def _logged(log: closed_loop.LoopLog) -> dict:
    """Everything a run logged, decisions included, for comparing two runs."""
    return {**{k: v.tolist() for k, v in log.arrays().items()},
            "decisions": [(t, repr(d)) for t, d in log.decisions]}


def _frozen() -> float:
    return 0.0


def test_the_controller_gets_its_own_model_and_the_plant_keeps_its_own():
    # run_closed_loop with a controller model runs exactly as that controller against the
    # plant given; without one, the controller takes the plant's parameters and no extension
    plant = WheelParams().with_values(tau_f=0.012)
    ctrl = WheelParams().with_values(sigma6=20.0)
    ext = Extensions(viscous=1e-4)

    def run(cfg_params, cfg_ext, plant_params):
        cfg = closed_loop.controller_config(controller_params=cfg_params,
                                            controller_extensions=cfg_ext)
        return _logged(closed_loop.run_controller(cfg, PROFILE, 1.0, None, plant_params,
                                                  clock=_frozen))

    own = _logged(closed_loop.run_closed_loop(PROFILE, 1.0, params=plant, controller_params=ctrl,
                                              controller_extensions=ext, clock=_frozen))
    assert own == run(ctrl, ext, plant)
    assert own != run(plant, Extensions(), plant) and own != run(ctrl, ext, ctrl)
    default = _logged(closed_loop.run_closed_loop(PROFILE, 1.0, params=plant, clock=_frozen))
    assert default == run(plant, Extensions(), plant)


def test_tracking_metrics_leave_out_the_settling_time():
    log = closed_loop.LoopLog()
    t = np.arange(0.0, 40.0, 0.01)
    ref = np.where(t < 20.0, 1.0, 1.5)
    v = ref + np.where((t % 20.0) < 2.0, 0.5, 0.01)        # big error while settling, then 0.01
    log.t, log.true_speed, log.reference = list(t), list(v), list(ref)
    log.est_speed, log.d = list(v), list(0.0 * v)
    m = tracking_metrics(log, PROFILE, DURATION, settle=2.0)
    assert m["rmse"] == pytest.approx(0.01, rel=1e-9)
    assert m["nrmse"] == pytest.approx(math.sqrt((0.01 ** 2 + (0.01 / 1.5) ** 2) / 2), rel=1e-3)
    assert m["segment_mean_error"] == pytest.approx([0.01, 0.01])
    assert m["segment_steady_error"] == pytest.approx([1.0, 1.0 / 1.5])   # [%]
    assert tracking_metrics(log, PROFILE, DURATION, settle=0.0)["rmse"] > 0.1
