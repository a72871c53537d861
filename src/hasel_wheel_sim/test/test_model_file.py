"""Model files: wheel parameters plus extensions round-trip, old parameter files stay valid,
and every kind of bad file gets an error naming the key and what is expected."""
import dataclasses
import datetime
import math

import pytest
import yaml

from hasel_wheel_sim.effects import REALISTIC, effects_from_mapping
from hasel_wheel_sim.model import Extensions
from hasel_wheel_sim.model_file import (EXTENSION_FIELDS, extensions_to_yaml_dict, load_model,
                                        load_provenance, save_model)
from hasel_wheel_sim.params import ParameterError, WheelParams, load_wheel_params
from hasel_wheel_sim.plant import Plant, PlantConfig, plant_config_from_mapping, plant_with_model
from hasel_wheel_sim.params import packaged

GAINS = tuple(1.0 + 0.01 * i for i in range(16))
EXT = Extensions(com_torque=0.00398, com_phase=0.505, platform_torque=0.0021,
                 platform_phase=-1.25, viscous=4.5e-4, rise_time=0.012, retention_rate=0.0093,
                 retention_recovery=287.5, angle_eccentricity=0.0071, angle_eccentricity_phase=0.3,
                 gains=GAINS)
# not exactly representable in binary: the file must still give back the same doubles
PARAMS = WheelParams().with_values(tau_f=0.010412345678901234, sigma5=-0.1 / 3.0)


def test_every_extension_field_has_a_unit():
    names = [f.name for f in dataclasses.fields(Extensions)]
    assert set(names) == set(EXTENSION_FIELDS) | {"gains"}
    assert list(extensions_to_yaml_dict(Extensions())) == names


def test_round_trip_gives_back_every_value(tmp_path):
    f = tmp_path / "model.yaml"
    prov = {"tool": "hasel_wheel ident", "date": datetime.date(2025, 1, 2),
            "data": ["run1.csv", "out/demo/bag"], "effects": ["com_offset"]}
    save_model(f, PARAMS, EXT, prov)
    params, ext = load_model(f)
    assert params == PARAMS and ext == EXT
    assert params.tau_f == 0.010412345678901234 and params.sigma5 == -0.1 / 3.0
    assert (ext.com_torque, ext.com_phase, ext.retention_recovery) == (0.00398, 0.505, 287.5)
    assert ext.gains == GAINS and isinstance(ext.gains, tuple)
    assert load_provenance(f) == prov
    # the wheel section is the parameter file format: the old loader reads it as it is
    assert load_wheel_params(f) == PARAMS
    data = yaml.safe_load(f.read_text())
    assert data["extensions"]["com_phase"] == {"value": 0.505, "unit": "rad"}
    assert data["extensions"]["gains"]["unit"] == "1"


def test_without_provenance(tmp_path):
    f = tmp_path / "model.yaml"
    save_model(f, WheelParams(), Extensions())
    assert "provenance" not in yaml.safe_load(f.read_text())
    assert load_model(f) == (WheelParams(), Extensions()) and load_provenance(f) == {}


def test_a_wheel_params_file_is_a_model_file_without_extensions():
    params, ext = load_model(packaged("hasel_wheel_sim", "wheel_params.yaml"))
    assert params == WheelParams() and ext == Extensions()


def test_missing_extension_fields_keep_their_defaults(tmp_path):
    f = tmp_path / "m.yaml"
    f.write_text(yaml.safe_dump({"wheel": WheelParams().to_yaml_dict(),
                                 "extensions": {"viscous": {"value": 0.001, "unit": "N*m*s/rad"}}}))
    assert load_model(f)[1] == Extensions(viscous=0.001)
    f.write_text(yaml.safe_dump({"wheel": WheelParams().to_yaml_dict(), "extensions": None}))
    assert load_model(f)[1] == Extensions()


def _good():
    return {"wheel": WheelParams().to_yaml_dict(), "extensions": extensions_to_yaml_dict(EXT),
            "provenance": {"tool": "test"}}


def _ext(d):
    return d["extensions"]


@pytest.mark.parametrize("mutate, match", [
    (lambda d: _ext(d).update(com_mass={"value": 1.0, "unit": "kg"}),
     r"extensions: .*\['com_mass'\].*\[.*'com_phase'"),
    (lambda d: _ext(d)["com_phase"].update(unit="deg"),
     r"extensions: field 'com_phase'.*'deg'.*'rad'"),
    (lambda d: _ext(d)["viscous"].update(unit="N*m*s"),
     r"field 'viscous'.*'N\*m\*s'.*'N\*m\*s/rad'"),
    (lambda d: _ext(d)["rise_time"].update(value=-0.01),
     r"field 'rise_time' = -0.01 is out of range; allowed range is \[0, 1\] s"),
    (lambda d: _ext(d)["retention_recovery"].update(value=0.0),
     r"field 'retention_recovery' = 0.0 is out of range; allowed range is \(0, 1e\+06\] s"),
    (lambda d: _ext(d)["com_torque"].update(value=float("nan")), r"'com_torque' = nan"),
    (lambda d: _ext(d)["com_phase"].update(value=4.0),
     r"'com_phase' = 4.0 is out of range; allowed range is \[-3.14159, 3.14159\] rad"),
    (lambda d: _ext(d)["retention_rate"].update(value="fast"), r"'retention_rate' = 'fast'"),
    (lambda d: _ext(d).update(viscous=0.001),
     r"field 'viscous'.*'N\*m\*s/rad'"),
    (lambda d: _ext(d)["gains"].update(value=[1.0] * 15),
     r"extensions: field 'gains'.*15.*16.*\(0, 10\] 1"),
    (lambda d: _ext(d)["gains"].update(value=1.0), r"field 'gains'"),
    (lambda d: _ext(d)["gains"].update(unit="%"), r"field 'gains'.*'%'"),
    (lambda d: _ext(d)["gains"]["value"].__setitem__(3, 0.0),
     r"field 'gains': entry 3 = 0.0.*\(0, 10\] 1"),
    (lambda d: _ext(d)["gains"]["value"].__setitem__(0, True), r"field 'gains': entry 0 = True"),
    (lambda d: _ext(d).update(gains=list(GAINS)), r"field 'gains'.*16"),
    (lambda d: d.update(extensions=[1, 2]), r"extensions"),
    (lambda d: d.update(extension=d.pop("extensions")),
     r"\['extension'\]"),
    (lambda d: d.update(provenance="ident"), r"provenance"),
    (lambda d: d["wheel"]["r"].update(unit="mm"), r"wheel: field 'r'.*'mm'.*'m'"),
    (lambda d: d["wheel"].pop("tau_f"), r"wheel: .*\['tau_f'\]"),
    (lambda d: d.pop("wheel"), r"'wheel:'"),
])
def test_bad_model_files_name_the_key_and_the_expectation(tmp_path, mutate, match):
    data = _good()
    mutate(data)
    f = tmp_path / "m.yaml"
    f.write_text(yaml.safe_dump(data))
    with pytest.raises(ParameterError, match=match) as info:
        load_model(f)
    assert str(f) in str(info.value)                       # the file is named too


def test_save_refuses_what_it_could_not_load(tmp_path):
    f = tmp_path / "m.yaml"
    # out-of-range extensions cannot even be built (test_model.py); the provenance is checked
    with pytest.raises(ParameterError, match=r"provenance"):
        save_model(f, WheelParams(), Extensions(), {"tool": object()})
    assert not f.exists()


def test_a_missing_file_is_named(tmp_path):
    with pytest.raises(ParameterError, match=r"nope.yaml"):
        load_model(tmp_path / "nope.yaml")


def test_the_model_gives_the_plant_its_dynamics_and_keeps_its_sensors():
    sensors = plant_config_from_mapping({"seed": 3, "switching": "tick", "effects": {
        "encoder": REALISTIC["encoder"], "serial_latency": REALISTIC["serial_latency"],
        "com_offset": {**REALISTIC["com_offset"], "enabled": False}}})
    cfg = plant_with_model(sensors, EXT)
    assert (cfg.seed, cfg.switching) == (3, "tick")
    assert cfg.effects.extensions() == EXT                  # exactly the model's, no draws
    assert Plant(PARAMS, cfg).wheel.extensions == EXT
    assert cfg.effects.on("encoder") and cfg.effects.get("serial_latency", "command") == 0.004
    assert plant_with_model(PlantConfig(), Extensions()).effects.extensions() == Extensions()


def test_a_plant_with_dynamic_effects_of_its_own_is_refused():
    realistic = PlantConfig(effects=effects_from_mapping(REALISTIC))
    with pytest.raises(ParameterError, match=r"plant.effects: \['charge_retention', 'com_offset', "
                       r"'gain_spread', .*describe the wheel \(its dynamics or its angle sensor\).*disable them"):
        plant_with_model(realistic, EXT)
    gains = PlantConfig(effects=effects_from_mapping({"actuator_gains": [1.0] * 16}))
    with pytest.raises(ParameterError, match=r"\['actuator_gains'\]"):
        plant_with_model(gains, EXT)


def test_extension_phases_cover_what_atan2_returns():
    for phase in (-math.pi, math.pi):
        assert EXTENSION_FIELDS["com_phase"].accepts(phase)


def test_controller_nodes_build_their_model_from_one_file(tmp_path):
    # observer_node / mpc_node: wheel_params_file and model_file ('' = unset)
    from hasel_wheel_sim.model_file import controller_model
    f = tmp_path / "model.yaml"
    save_model(f, PARAMS, EXT)
    wheel = packaged("hasel_wheel_sim", "wheel_params.yaml")
    assert controller_model("", "") == (WheelParams(), Extensions())
    assert controller_model(wheel, "") == (WheelParams(), Extensions())
    assert controller_model("", str(f)) == (PARAMS, EXT)
    with pytest.raises(ParameterError, match=r"wheel_params_file = .* and model_file = .*"):
        controller_model(wheel, str(f))


def test_sim_node_plant_from_a_model_file(tmp_path):
    # sim_node: model_file replaces wheel_params_file and plant_file's dynamics
    from hasel_wheel_sim.plant import load_plant_model
    f = tmp_path / "model.yaml"
    save_model(f, PARAMS, EXT)
    wheel = packaged("hasel_wheel_sim", "wheel_params.yaml")
    plain, realistic = (packaged("hasel_wheel_sim", n) for n in ("plant.yaml", "plant_realistic.yaml"))
    params, cfg = load_plant_model(wheel, plain)
    assert params == WheelParams() and cfg.effects.extensions() == Extensions()
    params, cfg = load_plant_model(wheel, plain, str(f))
    assert params == PARAMS and cfg.effects.extensions() == EXT and cfg.switching == "exact"
    with pytest.raises(ParameterError, match=r"plant_realistic.yaml: plant.effects: \['charge_retention'"):
        load_plant_model(wheel, realistic, str(f))


def test_describe_model_names_the_source_and_what_differs_from_the_paper():
    from hasel_wheel_sim.model_file import describe_model
    assert describe_model("", "", Extensions()) == "model built-in paper values"
    line = describe_model("", "/tmp/m.yaml", Extensions(com_torque=0.004, com_phase=0.5))
    assert line == "model /tmp/m.yaml (com_torque=0.004, com_phase=0.5)"
