"""Parameter files: the defaults, and a clear error for every kind of bad file."""
import math

import pytest
import yaml

from hasel_wheel_sim.effects import effects_from_mapping
from hasel_wheel_sim.params import (ParameterError, WheelParams, load_wheel_params,
                                    wheel_params_from_mapping)
from hasel_wheel_sim.plant import plant_config_from_mapping
from hasel_wheel_sim.params import packaged


def test_packaged_defaults_are_the_paper_values():
    p = load_wheel_params(packaged("hasel_wheel_sim", "wheel_params.yaml"))
    assert p == WheelParams()
    assert (p.M, p.L, p.r, p.I33, p.tau_f) == (0.979, 0.642, 0.157, 0.0759, 0.0104)
    assert (p.sigma1, p.sigma4, p.sigma6) == (1.214, -1.004, 22.357)


def test_inertia_matches_model_notes(params):
    # docs/model.md: J = L*I1 + L*M*r^2 + I33*r^2/L ~= 0.02301 (with the factor L)
    J = params.L * params.I1 + params.L * params.M * params.r**2 + params.I33 * params.r**2 / params.L
    assert J == pytest.approx(0.02301, abs=5e-6)
    assert params.inertia * params.L == pytest.approx(J, rel=1e-12)
    # friction alone: (r + L) tau_f / J ~= 0.36 rad/s^2
    assert params.friction_torque / params.inertia == pytest.approx(0.361, abs=1e-3)


def _write(tmp_path, data, raw=None):
    f = tmp_path / "p.yaml"
    f.write_text(raw if raw is not None else yaml.safe_dump(data))
    return f


def _good():
    return {"wheel": WheelParams().to_yaml_dict()}


@pytest.mark.parametrize("mutate, match", [
    (lambda d: d["wheel"].pop("tau_f"), r"\['tau_f'\]"),
    (lambda d: d["wheel"].update(mass={"value": 1.0, "unit": "kg"}), r"\['mass'\]"),
    (lambda d: d["wheel"]["r"].update(unit="mm"), r"'r'.*'mm'.*'m'"),
    (lambda d: d["wheel"]["M"].update(value=-1.0), r"'M' = -1.0.*\(0, 100\] kg"),
    (lambda d: d["wheel"]["M"].update(value=float("nan")), r"'M' = nan"),
    (lambda d: d["wheel"]["tau_f"].update(value=float("inf")), r"'tau_f' = inf"),
    (lambda d: d["wheel"]["sigma5"].update(value=0.0), r"'sigma5' = 0.0"),
    (lambda d: d["wheel"]["sigma3"].update(value=0.0), r"'sigma3' = 0.0.*\(0"),
    (lambda d: d["wheel"]["L"].update(value="long"), r"'L' = 'long'"),
    (lambda d: d["wheel"]["L"].update(value=True), r"'L' = True"),
    (lambda d: d["wheel"].update(I1=0.007), r"'I1'.*'kg\*m\^2'"),
    (lambda d: d.update(wheel=[1, 2]), r"wheel"),
    (lambda d: d.pop("wheel"), r"'wheel:'"),
])
def test_bad_wheel_files_name_the_field_and_range(tmp_path, mutate, match):
    data = _good()
    mutate(data)
    with pytest.raises(ParameterError, match=match):
        load_wheel_params(_write(tmp_path, data))


def test_unreadable_and_malformed_files(tmp_path):
    with pytest.raises(ParameterError, match=r"missing\.yaml"):
        load_wheel_params(tmp_path / "missing.yaml")
    with pytest.raises(ParameterError, match=r"p\.yaml"):
        load_wheel_params(_write(tmp_path, None, raw="wheel: {M: [unclosed"))


def test_empty_file_is_a_clear_error(tmp_path):
    with pytest.raises(ParameterError, match=r"'wheel:'"):
        load_wheel_params(_write(tmp_path, None, raw=""))


def test_nan_written_as_yaml_is_rejected(tmp_path):
    raw = yaml.safe_dump(_good()).replace("value: 0.979", "value: .nan")
    with pytest.raises(ParameterError, match=r"'M' = nan"):
        load_wheel_params(_write(tmp_path, None, raw=raw))


def test_constructor_validates_too():
    with pytest.raises(ParameterError, match=r"'r' = 0.0"):
        WheelParams(r=0.0)
    with pytest.raises(ParameterError, match=r"\['I1', .*'tau_f'\]"):
        wheel_params_from_mapping({})


@pytest.mark.parametrize("effects, match", [
    ({"wobble": {"enabled": True}}, r"\['wobble'\]"),
    ({"viscous_drag": {"enabled": "yes"}}, r"viscous_drag"),
    ({"viscous_drag": {"enabled": True}}, r"\['coefficient'\]"),
    ({"viscous_drag": {"enabled": True, "coefficient": {"value": 0.1, "unit": "N*m*s"}}},
     r"'coefficient'.*'N\*m\*s'.*'N\*m\*s/rad'"),
    ({"dropouts": {"enabled": True, "probability": {"value": 1.5, "unit": "1"}}},
     r"'probability' = 1.5 is out of range"),
    ({"actuator_gains": [1.0] * 15}, r"actuator_gains.*16"),
    ({"actuator_gains": [1.0] * 15 + [float("nan")]}, r"actuator_gains.*16"),
])
def test_bad_effects_are_named(effects, match):
    with pytest.raises(ParameterError, match=match):
        effects_from_mapping(effects)


def test_disabled_effect_may_omit_values_and_stays_off():
    cfg = effects_from_mapping({"viscous_drag": {"enabled": False}})
    assert not cfg.on("viscous_drag") and cfg.extensions().viscous == 0.0


@pytest.mark.parametrize("plant, match", [
    ({"seed": -1}, r"seed = -1"),
    ({"seed": 1.5}, r"seed = 1.5"),
    ({"switching": "fast"}, r"switching = 'fast'"),
    ({"speed": 1}, r"\['speed'\]"),
])
def test_bad_plant_config(plant, match):
    with pytest.raises(ParameterError, match=match):
        plant_config_from_mapping(plant)


def test_every_packaged_plant_file_loads():
    from hasel_wheel_sim.plant import load_plant_config
    nominal = load_plant_config(packaged("hasel_wheel_sim", "plant.yaml"))
    realistic = load_plant_config(packaged("hasel_wheel_sim", "plant_realistic.yaml"))
    assert nominal.effects.enabled == frozenset()
    assert realistic.switching == "tick"
    assert len(realistic.effects.enabled) == 11
    assert math.isclose(realistic.effects.get("encoder", "noise_std"), 0.001)
