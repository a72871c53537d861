"""Physical parameters of the wheel, loaded from YAML files with units.

Every value in a parameter file is written as ``name: {value: <number>, unit: <unit>}``.
The unit must be exactly the one documented in :data:`WHEEL_FIELDS` (SI, angles in
radians).  Anything missing, non-finite, of the wrong unit or outside its physical
range raises :class:`ParameterError` naming the field and the allowed range.

The defaults are the paper's Table I, its friction torque (Sec. IV-A) and force
parameters (Sec. IV-C), read as described in ``docs/model.md`` (the pivot arm's
"I21" is its I33).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from importlib import resources
from pathlib import Path
from typing import Any, Mapping

import yaml


def packaged(pkg: str, name: str) -> Path:
    """Path of a default config file shipped with package ``pkg`` (``<pkg>/config/<name>``)."""
    return Path(str(resources.files(pkg) / "config" / name))


class ParameterError(ValueError):
    """A parameter file or value is unusable; the message names the field and the fix."""


@dataclass(frozen=True)
class FieldSpec:
    """Unit and allowed range of one parameter (bounds are open unless marked closed)."""

    unit: str
    low: float = -math.inf
    high: float = math.inf
    low_closed: bool = False
    high_closed: bool = False
    nonzero: bool = False
    doc: str = ""

    def describe(self) -> str:
        lo = ("[" if self.low_closed else "(") + f"{self.low:g}"
        hi = f"{self.high:g}" + ("]" if self.high_closed else ")")
        extra = ", non-zero" if self.nonzero else ""
        return f"{lo}, {hi}{extra} {self.unit}"

    def accepts(self, v: float) -> bool:
        if not math.isfinite(v):
            return False
        if v < self.low or (v == self.low and not self.low_closed):
            return False
        if v > self.high or (v == self.high and not self.high_closed):
            return False
        return not (self.nonzero and v == 0.0)


#: The model's parameters: name -> unit, range and meaning.
WHEEL_FIELDS: dict[str, FieldSpec] = {
    "M": FieldSpec("kg", 0.0, 100.0, high_closed=True, doc="mass of the wheel"),
    "L": FieldSpec("m", 0.0, 10.0, high_closed=True, doc="pivot centre to wheel COM"),
    "r": FieldSpec("m", 0.0, 5.0, high_closed=True, doc="wheel radius"),
    "I13": FieldSpec("kg*m^2", doc="pivot-arm product of inertia (not used by (38))"),
    "I23": FieldSpec("kg*m^2", doc="pivot-arm product of inertia (not used by (38))"),
    "I33": FieldSpec("kg*m^2", 0.0, 100.0, low_closed=True, doc="pivot-arm inertia about its vertical axis"),
    "I1": FieldSpec("kg*m^2", 0.0, 100.0, doc="wheel inertia about its axle"),
    "I2": FieldSpec("kg*m^2", 0.0, 100.0, low_closed=True, doc="wheel inertia (transverse)"),
    "I3": FieldSpec("kg*m^2", 0.0, 100.0, low_closed=True, doc="wheel inertia (transverse)"),
    "tau_f": FieldSpec("N*m", 0.0, 10.0, low_closed=True, doc="bearing friction torque, each bearing set"),
    "sigma1": FieldSpec("1", -20.0, 20.0, doc="force law (43): power of the contact angle"),
    "sigma2": FieldSpec("s/rad", 0.0, 1e3, low_closed=True, doc="force law (43): speed weakening"),
    "sigma3": FieldSpec("1", 0.0, 1e3, doc="force law (43): speed weakening offset (>0)"),
    "sigma4": FieldSpec("1", -10.0, 10.0, doc="force law (43): log of the bump's peak angle [ln rad]"),
    "sigma5": FieldSpec("1", -10.0, 10.0, nonzero=True, doc="force law (43): bump width in ln rad"),
    "sigma6": FieldSpec("N/rad", 0.0, 1e4, doc="force law (43): gain of the rise term (>0)"),
    "brake_gain": FieldSpec("1", 0.0, 100.0, low_closed=True, high_closed=True,
                            doc="braking-force model: gain of the mirrored force law"),
}


@dataclass(frozen=True)
class WheelParams:
    """Parameters of the hybrid model, SI units (see :data:`WHEEL_FIELDS`)."""

    M: float = 0.979
    L: float = 0.642
    r: float = 0.157
    I13: float = -0.00176
    I23: float = -4.97e-6
    I33: float = 0.0759
    I1: float = 0.00717
    I2: float = 0.00402
    I3: float = 0.00391
    tau_f: float = 0.0104
    sigma1: float = 1.214
    sigma2: float = 1.997
    sigma3: float = 3.836
    sigma4: float = -1.004
    sigma5: float = -0.1009
    sigma6: float = 22.357
    brake_gain: float = 3.0

    def __post_init__(self) -> None:
        for f in fields(self):
            check_value(f.name, getattr(self, f.name), WHEEL_FIELDS[f.name])

    @property
    def inertia(self) -> float:
        """Effective inertia J/L of (38) in kg*m^2, so that J/L * xi2' is a torque at the axle.

        (38) multiplied through by 1/L: (I1 + M r^2 + I33 r^2/L^2) * phi'' =
        r F_a2 - (r + L)/L * tau_f * sign(phi').  With Table I this is 0.02301/0.642.
        """
        return self.I1 + self.M * self.r**2 + self.I33 * self.r**2 / self.L**2

    @property
    def friction_torque(self) -> float:
        """Total Coulomb friction torque at the axle in N*m: (r + L)/L * tau_f."""
        return (self.r + self.L) / self.L * self.tau_f

    def with_values(self, **changes: float) -> "WheelParams":
        """Return a copy with some fields changed (validated)."""
        return replace(self, **changes)

    def to_yaml_dict(self) -> dict[str, dict[str, Any]]:
        """The ``{name: {value, unit}}`` mapping that :func:`wheel_params_from_mapping` reads."""
        return {f.name: {"value": float(getattr(self, f.name)), "unit": WHEEL_FIELDS[f.name].unit}
                for f in fields(self)}


def check_value(name: str, value: Any, spec: FieldSpec, where: str = "") -> float:
    """Return ``value`` as float if it is a finite number within ``spec``, else raise.

    The error names the field, the bad value and the allowed range with its unit.
    """
    prefix = f"{where}: " if where else ""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ParameterError(f"{prefix}field '{name}' = {value!r} is not a number; "
                             f"expected a number in {spec.describe()}")
    v = float(value)
    if not spec.accepts(v):
        why = "not finite" if not math.isfinite(v) else "out of range"
        raise ParameterError(f"{prefix}field '{name}' = {v!r} is {why}; "
                             f"allowed range is {spec.describe()}")
    return v


def read_valued_mapping(data: Any, specs: Mapping[str, FieldSpec], where: str,
                        required: bool = True) -> dict[str, float]:
    """Check a ``{name: {value, unit}}`` mapping against ``specs`` and return plain floats.

    Unknown names, missing names (when ``required``), wrong units, and bad values all
    raise :class:`ParameterError` with the field named.
    """
    if not isinstance(data, Mapping):
        raise ParameterError(f"{where}: expected a mapping of fields to {{value, unit}}, "
                             f"got {type(data).__name__}")
    unknown = sorted(set(data) - set(specs))
    if unknown:
        raise ParameterError(f"{where}: unknown field(s) {unknown}; known fields are {sorted(specs)}")
    if required:
        missing = sorted(set(specs) - set(data))
        if missing:
            raise ParameterError(f"{where}: missing field(s) {missing}; every field needs "
                                 f"{{value: <number>, unit: <unit>}}")
    out: dict[str, float] = {}
    for name, entry in data.items():
        spec = specs[name]
        if not isinstance(entry, Mapping) or set(entry) != {"value", "unit"}:
            raise ParameterError(f"{where}: field '{name}' must be written as "
                                 f"{{value: <number>, unit: '{spec.unit}'}}, got {entry!r}")
        if entry["unit"] != spec.unit:
            raise ParameterError(f"{where}: field '{name}' has unit {entry['unit']!r}; "
                                 f"expected {spec.unit!r} (SI, angles in rad)")
        out[name] = check_value(name, entry["value"], spec, where)
    return out


def load_yaml_file(path: str | Path) -> Any:
    """Read a YAML file, turning I/O and syntax problems into :class:`ParameterError`."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise ParameterError(f"{p}: cannot read parameter file ({exc.strerror})") from exc
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ParameterError(f"{p}: not valid YAML ({exc})") from exc


def wheel_params_from_mapping(data: Any, where: str = "wheel parameters") -> WheelParams:
    """Build :class:`WheelParams` from a ``{name: {value, unit}}`` mapping (all fields required)."""
    return WheelParams(**read_valued_mapping(data, WHEEL_FIELDS, where))


def load_wheel_params(path: str | Path) -> WheelParams:
    """Load the ``wheel:`` section of a parameter file (see ``config/wheel_params.yaml``)."""
    data = load_yaml_file(path)
    if not isinstance(data, Mapping) or "wheel" not in data:
        raise ParameterError(f"{path}: expected a top-level 'wheel:' section")
    return wheel_params_from_mapping(data["wheel"], where=f"{path}: wheel")
