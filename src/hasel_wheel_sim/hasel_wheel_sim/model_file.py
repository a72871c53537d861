"""Model files: the paper's parameters plus the extensions identification adds, in one YAML file.

A model file is a ``wheel_params.yaml`` with two optional sections more::

    wheel:                       # exactly as in config/wheel_params.yaml (all fields required)
      M: {value: 0.979, unit: kg}
      ...
    extensions:                  # hasel_wheel_sim.model.Extensions; missing fields keep defaults
      com_torque:         {value: 0.004, unit: N*m}
      com_phase:          {value: 0.5,   unit: rad}
      platform_torque:    {value: 0.0,   unit: N*m}
      platform_phase:     {value: 0.0,   unit: rad}
      viscous:            {value: 0.0,   unit: N*m*s/rad}
      rise_time:          {value: 0.0,   unit: s}
      retention_rate:     {value: 0.0,   unit: 1/s}
      retention_recovery: {value: 300.0, unit: s}
      angle_eccentricity: {value: 0.0,   unit: rad}
      angle_eccentricity_phase: {value: 0.0, unit: rad}
      gains:              {value: [1.0, ..., 1.0], unit: "1"}     # 16 entries
    provenance:                  # free mapping, not interpreted: tool, date, data files, effects
      tool: hasel_wheel ident

So every existing ``wheel_params.yaml`` is a model file (no extensions: ``Extensions()``).
The ``wheel:`` section is read by :func:`hasel_wheel_sim.params.wheel_params_from_mapping`,
the same reader ``load_wheel_params`` uses.  Every problem raises
:class:`~hasel_wheel_sim.params.ParameterError` naming the file, the key and what is expected.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping

import yaml

from hasel_wheel_sim.model import EXTENSION_FIELDS, GAIN_SPEC, N_ACTUATORS, Extensions
from hasel_wheel_sim.params import (ParameterError, WheelParams, load_wheel_params, load_yaml_file,
                     read_valued_mapping, wheel_params_from_mapping)

#: Top-level sections of a model file.
SECTIONS = ("wheel", "extensions", "provenance")

def extensions_to_yaml_dict(ext: Extensions) -> dict[str, dict[str, Any]]:
    """The ``{field: {value, unit}}`` mapping of ``ext`` that :func:`extensions_from_mapping` reads."""
    out: dict[str, dict[str, Any]] = {
        name: {"value": float(getattr(ext, name)), "unit": spec.unit}
        for name, spec in EXTENSION_FIELDS.items()}
    out["gains"] = {"value": [float(g) for g in ext.gains], "unit": GAIN_SPEC.unit}
    return out


def extensions_from_mapping(data: Any, where: str = "extensions") -> Extensions:
    """Build :class:`Extensions` from ``{field: {value, unit}}``; missing fields keep defaults.

    Scalars go through :func:`hasel_wheel_sim.params.read_valued_mapping` (unknown fields,
    units, ranges); ``gains`` must be ``{value: [16 numbers in (0, 10]], unit: "1"}``.
    ``None`` (an empty section) gives ``Extensions()``.
    """
    if data is None:
        return Extensions()
    if not isinstance(data, Mapping):
        raise ParameterError(f"{where}: expected a mapping of extension fields to "
                             f"{{value, unit}}, got {type(data).__name__}")
    known = dict(EXTENSION_FIELDS, gains=GAIN_SPEC)
    scalars = read_valued_mapping({k: v for k, v in data.items() if k != "gains"},
                                  known, where, required=False)
    if "gains" in data:
        scalars["gains"] = _read_gains(data["gains"], f"{where}: field 'gains'")
    return Extensions(**scalars)


def _read_gains(entry: Any, where: str) -> tuple[float, ...]:
    expected = (f"expected {{value: [{N_ACTUATORS} numbers in {GAIN_SPEC.describe()}], "
                f"unit: '{GAIN_SPEC.unit}'}}")
    if not isinstance(entry, Mapping) or set(entry) != {"value", "unit"}:
        raise ParameterError(f"{where}: {expected}, got {entry!r}")
    if entry["unit"] != GAIN_SPEC.unit:
        raise ParameterError(f"{where}: unit {entry['unit']!r}; expected {GAIN_SPEC.unit!r}")
    values = entry["value"]
    if not isinstance(values, list):
        raise ParameterError(f"{where}: value is a {type(values).__name__}, not a list; {expected}")
    if len(values) != N_ACTUATORS:
        raise ParameterError(f"{where}: got {len(values)} entries; {expected}")
    gains = []
    for i, g in enumerate(values):
        if isinstance(g, bool) or not isinstance(g, (int, float)) or not GAIN_SPEC.accepts(float(g)):
            raise ParameterError(f"{where}: entry {i} = {g!r}; each gain must be a finite number "
                                 f"in {GAIN_SPEC.describe()}")
        gains.append(float(g))
    return tuple(gains)


def model_from_mapping(data: Any, where: str = "model") -> tuple[WheelParams, Extensions]:
    """Parse a whole model file's content ``{wheel, extensions?, provenance?}``."""
    if not isinstance(data, Mapping) or "wheel" not in data:
        raise ParameterError(f"{where}: expected a top-level 'wheel:' section")
    unknown = sorted(set(data) - set(SECTIONS))
    if unknown:
        raise ParameterError(f"{where}: unknown top-level section(s) {unknown}; a model file has "
                             f"'wheel:' and optionally 'extensions:' and 'provenance:'")
    prov = data.get("provenance")
    if prov is not None and not isinstance(prov, Mapping):
        raise ParameterError(f"{where}: provenance: expected a mapping (tool, date, data files, "
                             f"effects ...), got {type(prov).__name__}")
    params = wheel_params_from_mapping(data["wheel"], where=f"{where}: wheel")
    return params, extensions_from_mapping(data.get("extensions"), f"{where}: extensions")


def load_model(path: str | Path) -> tuple[WheelParams, Extensions]:
    """Load a model file (or a plain ``wheel_params.yaml``): (parameters, extensions)."""
    return model_from_mapping(load_yaml_file(path), where=str(path))


def load_provenance(path: str | Path) -> dict[str, Any]:
    """The ``provenance:`` mapping of a model file ({} when absent); the file is validated too."""
    data = load_yaml_file(path)
    model_from_mapping(data, where=str(path))
    return dict(data.get("provenance") or {})


def controller_model(wheel_params_file: str, model_file: str) -> tuple[WheelParams, Extensions]:
    """The model a controller node builds from its parameters (each '' = not set).

    ``model_file`` set: :func:`load_model`; else ``wheel_params_file`` (no extensions), else
    the paper's values.  Both set is ambiguous and raises :class:`ParameterError`.
    """
    if wheel_params_file and model_file:
        raise ParameterError(f"wheel_params_file = {wheel_params_file!r} and model_file = "
                             f"{model_file!r}: set only one (a model file holds the wheel "
                             f"parameters too)")
    if model_file:
        return load_model(model_file)
    params = load_wheel_params(wheel_params_file) if wheel_params_file else WheelParams()
    return params, Extensions()


def save_model(path: str | Path, params: WheelParams, ext: Extensions,
               provenance: Mapping[str, Any] | None = None) -> None:
    """Write ``params`` and ``ext`` (and ``provenance``, plain YAML data) to a model file.

    The content is checked with the loader before anything is written, so a file this
    writes always loads (an out-of-range extension cannot even be built: :class:`Extensions`
    checks its fields).
    Floats are written with full precision: :func:`load_model` gives back equal values.
    """
    data: dict[str, Any] = {"wheel": params.to_yaml_dict(), "extensions": extensions_to_yaml_dict(ext)}
    if provenance is not None:
        data["provenance"] = dict(provenance)
    model_from_mapping(data, where=f"{path} (not written)")
    try:
        text = yaml.safe_dump(data, sort_keys=False, default_flow_style=None)
    except yaml.YAMLError as exc:
        raise ParameterError(f"{path}: provenance must be plain YAML data (str, numbers, lists, "
                             f"mappings, dates): {exc}") from exc
    header = ("# Model file (hasel_wheel_sim.model_file): the paper's parameters (wheel), the\n"
              "# extensions of hasel_wheel_sim.model.Extensions, and where they came from.\n"
              "# SI units, angles in rad; every value is {value, unit}.\n")
    Path(path).write_text(header + text, encoding="utf-8")


def describe_model(wheel_params_file: str, model_file: str, ext: Extensions) -> str:
    """One log line naming where a node's model came from and its non-default extensions."""
    source = model_file or wheel_params_file or "built-in paper values"
    default = Extensions()
    changed = [f"{name}={getattr(ext, name):.4g}" for name in
               ("com_torque", "com_phase", "platform_torque", "platform_phase", "viscous",
                "rise_time", "retention_rate", "retention_recovery", "angle_eccentricity",
                "angle_eccentricity_phase")
               if getattr(ext, name) != getattr(default, name)]
    if tuple(ext.gains) != tuple(default.gains):
        changed.append(f"gains {min(ext.gains):.3f}..{max(ext.gains):.3f}")
    return f"model {source}" + (f" ({', '.join(changed)})" if changed else "")
