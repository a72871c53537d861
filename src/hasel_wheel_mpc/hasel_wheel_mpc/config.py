"""What the controller is: :class:`ControllerConfig` (model, observer and MPC tuning, the
disturbance estimator, the speed source), its YAML form and the ROS parameter files it maps to.

The configuration is written into a bag as YAML (``<namespace>/controller.yaml`` in the bag's
configuration) and read back by the replay.  Tests: ``test_replay.py``
(``test_configuration_yaml_round_trip_and_errors``,
``test_the_packaged_ros_parameter_files_are_the_core_defaults``).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import yaml

from hasel_wheel_sim.model import Extensions
from hasel_wheel_sim.model_file import extensions_to_yaml_dict, model_from_mapping
from hasel_wheel_sim.params import ParameterError, WheelParams

from hasel_wheel_mpc.disturbance import ESTIMATOR_GATE, TRACKING_GAIN
from hasel_wheel_mpc.mpc import MpcConfig
from hasel_wheel_mpc.observer import ObserverConfig
from hasel_wheel_mpc.start_policy import StartConfig

SPEED_SOURCES = ("observer", "finite_difference")
#: Sections of the configuration's YAML form (every one optional when read).
SECTIONS = ("model", "observer", "mpc", "estimator", "speed_source", "start")
ESTIMATOR_MODES = ("tracking", "paper")


@dataclass(frozen=True)
class ControllerConfig:
    """What the controller is: model, tuning and estimator (SI units, angles rad).

    ``estimator_gain`` None: no disturbance estimator.  ``speed_source`` 'observer' or
    'finite_difference' (what the MPC sees as xi2; with the finite difference the observer's
    disturbance is not used either).  ``start``: the start and stall policies.
    """

    params: WheelParams = field(default_factory=WheelParams)
    extensions: Extensions = field(default_factory=Extensions)
    observer: ObserverConfig = field(default_factory=ObserverConfig)
    mpc: MpcConfig = field(default_factory=MpcConfig)
    estimator_gain: float | None = TRACKING_GAIN   # K [1 per cycle]
    estimator_mode: str = "tracking"         # 'tracking' or 'paper' ((57)-(58))
    estimator_gate: float = ESTIMATOR_GATE   # [rad/s]
    speed_source: str = "observer"
    start: StartConfig = field(default_factory=StartConfig)

    def __post_init__(self) -> None:
        if self.speed_source not in SPEED_SOURCES:
            raise ValueError(f"speed_source = {self.speed_source!r}: expected one of "
                             f"{list(SPEED_SOURCES)}")
        k = self.estimator_gain
        if k is not None and not (_number(k) and 0.0 < k < 2.0):
            raise ValueError(f"estimator gain = {k!r}: expected null (no estimator) or a "
                             f"number 0 < K < 2 [1 per cycle]")
        if self.estimator_mode not in ESTIMATOR_MODES:
            raise ValueError(f"estimator mode = {self.estimator_mode!r}: expected 'tracking' "
                             f"or 'paper'")
        if not (_number(self.estimator_gate) and self.estimator_gate > 0.0):
            raise ValueError(f"estimator gate = {self.estimator_gate!r}: expected a positive "
                             f"speed band [rad/s]")

    def to_yaml(self) -> str:
        """The configuration as YAML text (floats in full precision: :meth:`from_yaml` gives
        back an equal configuration)."""
        data = {"model": {"wheel": self.params.to_yaml_dict(),
                          "extensions": extensions_to_yaml_dict(self.extensions)},
                "observer": _plain(dataclasses.asdict(self.observer)),
                "mpc": _plain(dataclasses.asdict(self.mpc)),
                "estimator": {"gain": self.estimator_gain, "mode": self.estimator_mode,
                              "gate": self.estimator_gate},
                "speed_source": self.speed_source,
                "start": _plain(dataclasses.asdict(self.start))}
        return yaml.safe_dump(data, sort_keys=False, default_flow_style=None)

    @classmethod
    def from_yaml(cls, text: str, where: str = "controller.yaml") -> "ControllerConfig":
        """Parse :meth:`to_yaml`'s text; a wrong section or field raises ParameterError."""
        data = yaml.safe_load(text)
        return cls.from_mapping(data, where)

    @classmethod
    def from_mapping(cls, data: Any, where: str = "controller") -> "ControllerConfig":
        """Build from the mapping of :meth:`to_yaml` (every section optional)."""
        if not isinstance(data, Mapping):
            raise ParameterError(f"{where}: expected a mapping with sections {list(SECTIONS)}; "
                                 f"got {type(data).__name__}")
        unknown = sorted(set(data) - set(SECTIONS))
        if unknown:
            raise ParameterError(f"{where}: unknown section(s) {unknown}; expected "
                                 f"{list(SECTIONS)}")
        kw: dict[str, Any] = {}
        if "model" in data:
            kw["params"], kw["extensions"] = model_from_mapping(data["model"], f"{where}: model")
        if "observer" in data:
            kw["observer"] = _dataclass_from(ObserverConfig, data["observer"], f"{where}: observer")
        if "mpc" in data:
            kw["mpc"] = _dataclass_from(MpcConfig, data["mpc"], f"{where}: mpc")
        if "start" in data:
            kw["start"] = _dataclass_from(StartConfig, data["start"], f"{where}: start")
        est = data.get("estimator") or {}
        unknown = sorted(set(est) - {"gain", "mode", "gate"})
        if unknown:
            raise ParameterError(f"{where}: estimator: unknown field(s) {unknown}; expected "
                                 f"gain, mode, gate")
        for name in ("gain", "mode", "gate"):
            if name in est:
                kw[f"estimator_{name}"] = est[name]
        if "speed_source" in data:
            kw["speed_source"] = data["speed_source"]
        try:
            return cls(**kw)
        except (TypeError, ValueError) as exc:
            raise ParameterError(f"{where}: {exc}") from exc

    def with_overrides(self, overrides: Mapping[str, Any]) -> "ControllerConfig":
        """A copy with ``{'section.field': value}`` changed, e.g. ``{'mpc.brake_threshold':
        0.4, 'estimator.gain': None, 'speed_source': 'observer'}``; model fields are
        ``model.wheel.<name>`` and ``model.extensions.<name>`` (SI values, units as in the
        model file)."""
        data = yaml.safe_load(self.to_yaml())
        for key, value in overrides.items():
            path = key.split(".")
            node = data
            for part in path[:-1]:
                if not isinstance(node, dict) or part not in node:
                    raise ParameterError(f"override {key!r}: no section {part!r}; known: "
                                         f"{sorted(node) if isinstance(node, dict) else []}")
                node = node[part]
            if not isinstance(node, dict) or path[-1] not in node:
                raise ParameterError(f"override {key!r}: no field {path[-1]!r}; known: "
                                     f"{sorted(node) if isinstance(node, dict) else []}")
            if isinstance(node[path[-1]], dict) and "value" in node[path[-1]]:
                node[path[-1]]["value"] = value        # a {value, unit} model field
            else:
                node[path[-1]] = value
        return ControllerConfig.from_mapping(data, "overrides")


#: ROS parameters of observer_node / mpc_node that are fields of ObserverConfig / MpcConfig.
OBSERVER_PARAMS = ("accel_noise", "encoder_noise", "gate_sigma", "disturbance_rate",
                   "pivot_rate", "learn_speed")
MPC_PARAMS = ("brake_threshold", "brake_phi_a", "brake_phi_d", "terminal_weight",
              "horizon_pads", "time_weighted", "deadline_margin", "max_horizon", "phi_a_min", "phi_a_max")
#: mpc_node's ROS parameters that are fields of StartConfig.
START_PARAMS = ("still_speed", "stall_time", "max_restarts")


def _node_parameters(text: str, node: str, where: str) -> dict[str, Any]:
    """``ros__parameters`` of ``node`` in a ROS parameter file's text (keys such as
    ``/**/node``, ``node`` or ``/ns/node``)."""
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ParameterError(f"{where}: not YAML ({exc})") from exc
    for key, value in (data or {}).items() if isinstance(data, Mapping) else ():
        if str(key).rstrip("/").split("/")[-1] == node and isinstance(value, Mapping):
            params = value.get("ros__parameters")
            if isinstance(params, Mapping):
                return dict(params)
    raise ParameterError(f"{where}: no '{node}: ros__parameters:' section")


def controller_from_ros_files(observer_yaml: str, mpc_yaml: str,
                              where: str = "ROS parameter files") -> ControllerConfig:
    """The controller that observer_node and mpc_node build from these parameter files'
    texts (as recorded in a ROS bag's custom data): tuning and estimator (``estimator_*``,
    mpc_node's; a file that gives them to observer_node is read too); the model is the
    paper's unless the files name a model file that exists here (``model_file`` or
    ``wheel_params_file``).  Run-time changes (``ros2 param set``) are not in the files."""
    from hasel_wheel_sim.model_file import controller_model

    obs = _node_parameters(observer_yaml, "observer_node", f"{where}: observer")
    mpc = _node_parameters(mpc_yaml, "mpc_node", f"{where}: mpc")
    data: dict[str, Any] = {
        "observer": {k: obs[k] for k in OBSERVER_PARAMS if k in obs},
        "mpc": {k: mpc[k] for k in MPC_PARAMS if k in mpc},
        "start": {k: mpc[k] for k in START_PARAMS if k in mpc},
        "estimator": {k: src[f"estimator_{k}"] for k in ("gain", "mode", "gate")
                      for src in (obs, mpc) if f"estimator_{k}" in src}}
    if data["estimator"].get("gain") == 0:
        data["estimator"]["gain"] = None                  # 0 = estimator off (the node's rule)
    cfg = ControllerConfig.from_mapping(data, where)
    files = [obs.get("wheel_params_file") or "", obs.get("model_file") or ""]
    if any(files) and all(not f or Path(f).is_file() for f in files):
        params, ext = controller_model(*files)
        cfg = dataclasses.replace(cfg, params=params, extensions=ext)
    return cfg


def _number(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _plain(d: dict) -> dict:
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in d.items()}


def _dataclass_from(cls, data: Any, where: str):
    """``cls(**data)`` with each value checked against the type of the field's default
    (numbers, booleans, lists of numbers), so a wrong value names the field."""
    if not isinstance(data, Mapping):
        raise ParameterError(f"{where}: expected a mapping of fields, got {type(data).__name__}")
    defaults = cls()
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - names)
    if unknown:
        raise ParameterError(f"{where}: unknown field(s) {unknown}; known: {sorted(names)}")
    kw = {}
    for name, v in data.items():
        default = getattr(defaults, name)
        if isinstance(default, bool):
            ok, want = isinstance(v, bool), "true or false"
        elif isinstance(default, int):
            ok, want = _number(v) and float(v).is_integer(), "a whole number"
            v = int(v) if ok else v
        elif isinstance(default, float):
            ok, want = _number(v), "a finite number"
        elif isinstance(default, tuple):
            ok, want = isinstance(v, (list, tuple)) and all(_number(x) for x in v), \
                "a list of finite numbers"
            v = tuple(v) if ok else v
        else:
            ok, want = True, ""
        if not ok:
            raise ParameterError(f"{where}: {name} = {v!r}: expected {want} (SI units, "
                                 f"angles in rad; default {default!r})")
        kw[name] = float(v) if isinstance(default, float) else v
    try:
        return cls(**kw)
    except (TypeError, ValueError) as exc:
        raise ParameterError(f"{where}: {exc}") from exc
