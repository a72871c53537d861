"""The speed controller of the embedded runner as one object: observer -> estimator -> MPC.

:class:`SpeedController` takes device samples one at a time (``step(sample, reference)``)
and answers with the estimate and, at decision points, the MPC's decision.  The closed loop
(:func:`~hasel_wheel_mpc.closed_loop.run_closed_loop`) feeds it from the plant; the bag
replay (:mod:`~hasel_wheel_bringup.replay`) feeds it from a recording.  Both hand it the sample
as a node receives it (:func:`hasel_wheel_common.samples.as_received`), so a recorded run
can be re-computed exactly.

:class:`ControllerConfig` is everything that decides what the controller does (its model,
the observer's and the MPC's tuning, the estimator); it is written into the bag as YAML
(``<namespace>/controller.yaml`` in the bag's configuration) and read back by the replay.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, NamedTuple

import numpy as np
import yaml

from hasel_wheel_common.samples import PadEdges, TelemetrySample
from hasel_wheel_sim.model import Extensions
from hasel_wheel_sim.model_file import extensions_to_yaml_dict, model_from_mapping
from hasel_wheel_sim.params import ParameterError, WheelParams
from hasel_wheel_sim.wheel import TICK

from hasel_wheel_mpc.disturbance import TRACKING_GAIN, IntegralEstimator
from hasel_wheel_mpc.mpc import Decision, Mpc, MpcConfig, next_pad
from hasel_wheel_mpc.observer import Estimate, Observer, ObserverConfig

D = math.radians
#: The command that starts a wheel (sequence 1), and the angles [rad] the first pad runs with.
START_ANGLES = (D(3.0), D(22.0))
#: Decide on an idle wheel after this many samples with HV off [samples].
IDLE_SAMPLES = 150
#: Re-decide on a new reference only if the current actuator stays on this long [s].
REDECIDE_MIN_TIME = 0.02
SPEED_SOURCES = ("observer", "finite_difference")


@dataclass(frozen=True)
class ControllerConfig:
    """What the controller is: model, tuning and estimator (SI units, angles rad).

    ``estimator_gain`` None: no disturbance estimator.  ``speed_source`` 'observer' or
    'finite_difference' (what the MPC sees as xi2; with the finite difference the observer's
    disturbance is not used either).
    """

    params: WheelParams = field(default_factory=WheelParams)
    extensions: Extensions = field(default_factory=Extensions)
    observer: ObserverConfig = field(default_factory=ObserverConfig)
    mpc: MpcConfig = field(default_factory=MpcConfig)
    estimator_gain: float | None = TRACKING_GAIN   # K [1 per cycle]
    estimator_mode: str = "tracking"         # 'tracking' or 'paper' ((57)-(58))
    estimator_gate: float = 0.64             # [rad/s]
    speed_source: str = "observer"

    def __post_init__(self) -> None:
        if self.speed_source not in SPEED_SOURCES:
            raise ValueError(f"speed_source = {self.speed_source!r}: expected one of "
                             f"{list(SPEED_SOURCES)}")
        k = self.estimator_gain
        if k is not None and not (_number(k) and 0.0 < k < 2.0):
            raise ValueError(f"estimator gain = {k!r}: expected null (no estimator) or a "
                             f"number 0 < K < 2 [1 per cycle]")
        if self.estimator_mode not in ("tracking", "paper"):
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
                "speed_source": self.speed_source}
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
            raise ParameterError(f"{where}: expected a mapping with sections model, observer, "
                                 f"mpc, estimator, speed_source; got {type(data).__name__}")
        unknown = sorted(set(data) - {"model", "observer", "mpc", "estimator", "speed_source"})
        if unknown:
            raise ParameterError(f"{where}: unknown section(s) {unknown}; expected model, "
                                 f"observer, mpc, estimator, speed_source")
        kw: dict[str, Any] = {}
        if "model" in data:
            kw["params"], kw["extensions"] = model_from_mapping(data["model"], f"{where}: model")
        if "observer" in data:
            kw["observer"] = _dataclass_from(ObserverConfig, data["observer"], f"{where}: observer")
        if "mpc" in data:
            kw["mpc"] = _dataclass_from(MpcConfig, data["mpc"], f"{where}: mpc")
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
                   "pivot_rate")
MPC_PARAMS = ("brake_threshold", "brake_phi_a", "brake_phi_d", "terminal_weight",
              "horizon_pads", "time_weighted", "deadline_margin", "max_horizon", "phi_a_min", "phi_a_max")


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
    texts (as recorded in a ROS bag's custom data): tuning and estimator; the model is the
    paper's unless the files name a model file that exists here (``model_file`` or
    ``wheel_params_file``).  Run-time changes (``ros2 param set``) are not in the files."""
    from hasel_wheel_sim.model_file import controller_model

    obs = _node_parameters(observer_yaml, "observer_node", f"{where}: observer")
    mpc = _node_parameters(mpc_yaml, "mpc_node", f"{where}: mpc")
    data: dict[str, Any] = {
        "observer": {k: obs[k] for k in OBSERVER_PARAMS if k in obs},
        "mpc": {k: mpc[k] for k in MPC_PARAMS if k in mpc},
        "estimator": {k: obs[f"estimator_{k}"] for k in ("gain", "mode", "gate")
                      if f"estimator_{k}" in obs}}
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


#: Why the MPC decides at a sample (:func:`decision_point`).
SWITCH_ON, IDLE, NEW_REFERENCE, BETWEEN_PADS = "switch_on", "idle", "new_reference", "between_pads"


def decision_point(reference_changed: bool, q: int, switched_on: bool, idle: int,
                   idle_samples: int, act_counter: float, deact_counter: float, speed: float,
                   min_time: float) -> str | None:
    """Why the MPC decides at this sample, or None (shared by the embedded loop and mpc_node).

    SWITCH_ON: the actuator of interest just switched on (paper Sec. V-B).  IDLE: HV has been
    off for ``idle_samples`` samples.  On a new reference, if there is at least ``min_time``
    [s] at ``speed`` [rad/s] before the next switching: NEW_REFERENCE while an actuator is on
    (``deact_counter`` [rad] to its switch-off; the waiting command is replaced), and
    BETWEEN_PADS while none is (``act_counter`` [rad] to the pending switch-on; that target
    is replaced, by a braking pad only, because the MPC predicts from a pad that is on).
    """
    if switched_on:
        return SWITCH_ON
    if idle == idle_samples:
        return IDLE
    if reference_changed:
        lead = min_time * max(speed, 0.1)
        if q == 1 and deact_counter > lead:
            return NEW_REFERENCE
        if q == 0 and act_counter > lead:
            return BETWEEN_PADS
    return None


def decide_at(mpc: Mpc, why: str, xi1: float, speed: float, eta_unwrapped: int,
              phi_a_now: float, phi_d_now: float, reference: float, d: float,
              disturbance: tuple, act_counter: float) -> Decision | None:
    """The MPC's decision at a :func:`decision_point` ``why`` (shared by the embedded loop and
    mpc_node), or None: between two pads only a braking command replaces the pending target,
    and only when the speed (+ d) is ``brake_threshold`` above the reference.  On an idle
    wheel a driving command latches on arrival and the telemetry's pad is stale, so its pad
    is the first whose switch-on is still ahead then (:func:`next_pad`).  Angles rad (xi1
    unwrapped), speeds rad/s, ``act_counter`` rad to the pending switch-on."""
    if why == BETWEEN_PADS:
        if speed + d < reference + mpc.config.brake_threshold:
            return None
        return mpc.brake_now(xi1, speed, d, act_counter)
    dec = mpc.decide(xi1, speed, eta_unwrapped, phi_a_now, phi_d_now, reference, d,
                     disturbance, pad_on=why != IDLE)
    if why == IDLE and not dec.braking:
        n_a = next_pad(xi1, speed, dec.command.phi_a, TICK + mpc.config.deadline_margin)
        dec = dec._replace(command=dec.command._replace(n_a=n_a))
    return dec


class ControlStep(NamedTuple):
    """What the controller made of one sample."""

    estimate: Estimate
    d_before: float              # the estimator's d [rad/s] when the sample arrived
    d: float                     # d [rad/s] after this sample (changes at switch-offs)
    speed: float                 # xi2 the MPC sees [rad/s] (observer or finite difference)
    decision: Decision | None    # the MPC's decision at this sample, if it decided


class SpeedController:
    """Observer, disturbance estimator and MPC, with the decision points of paper Sec. V-B.

    Decides where :func:`decision_point` says: at each switch-on of the actuator of interest,
    on an idle wheel after ``IDLE_SAMPLES`` samples with HV off, and at once when the
    reference changes with at least ``REDECIDE_MIN_TIME`` left before the next switching.
    ``clock`` [s] is the MPC's clock for its deadline
    (default wall time).
    """

    def __init__(self, config: ControllerConfig | None = None,
                 clock: Callable[[], float] | None = None) -> None:
        cfg = self.config = config or ControllerConfig()
        self.observer = Observer(cfg.params, cfg.extensions, config=cfg.observer)
        self.mpc = Mpc(cfg.params, cfg.extensions, config=cfg.mpc,
                       **({"clock": clock} if clock is not None else {}))
        self.estimator = (IntegralEstimator(gain=cfg.estimator_gain, mode=cfg.estimator_mode,
                                            gate=cfg.estimator_gate)
                          if cfg.estimator_gain else None)
        self.observer.command_sent(0, *START_ANGLES)
        self._angles = {0: START_ANGLES}
        self._edges = PadEdges()
        self._idle = 0
        self._cycle: list[float] = []
        self._queued: list[float | None] = []    # predictions of cycles starting at switch-offs
        self._window_pred: float | None = None
        self._prev: tuple[float, float] | None = None
        self._fd = 0.0
        self._last_ref: float | None = None
        self._new_ref = False

    @property
    def d(self) -> float:
        """The disturbance estimate [rad/s] (0 without an estimator)."""
        return self.estimator.d if self.estimator else 0.0

    def step(self, s: TelemetrySample, reference: float) -> ControlStep:
        """One device sample ``s`` with the reference [rad/s] in force at its time."""
        e = self.observer.step(s)
        d_before = self.d
        if self._prev is not None and s.t > self._prev[0]:
            self._fd = (s.angle - self._prev[1]) / (s.t - self._prev[0])
        self._prev = (s.t, s.angle)
        observer = self.config.speed_source == "observer"
        speed = e.xi2 if observer else self._fd
        self._cycle.append(speed)
        self._idle = 0 if s.q else self._idle + 1
        switched_on, switched_off = self._edges.step(s.q, s.eta_unwrapped)
        last = reference if self._last_ref is None else self._last_ref
        self._last_ref = reference
        # a new reference counts until the next decision: one that arrives too close to a
        # switch-off is taken up between the pads or at the next switch-on
        self._new_ref = self._new_ref or reference != last
        if reference != last:
            # cycles predicted for the old reference say nothing about the model's error
            # against the new one (a step down would read as the wheel being too fast), also
            # the one ending at this very sample.  (observer_node learns of the new reference
            # only with the MPC's next status, so it still scores that one, against the old.)
            self._window_pred = None
            self._queued = [None] * len(self._queued)
        if switched_off:
            # the window [previous switch-off, this one) is a cycle some decision predicted
            if self.estimator and self._window_pred is not None and len(self._cycle) > 1:
                self.estimator.step(float(np.mean(self._cycle[:-1])), self._window_pred,
                                    reference)
            self._window_pred = self._queued.pop(0) if self._queued else None
            self._cycle = [speed]
        d = self.d
        why = decision_point(self._new_ref, s.q, switched_on, self._idle, IDLE_SAMPLES,
                             e.act_counter, e.deact_counter, speed, REDECIDE_MIN_TIME)
        if why is not None:
            self._new_ref = False
        dec = None
        if why is not None:
            pa_now, pd_now = self._angles.get(s.last_command_sequence, START_ANGLES)
            dec = decide_at(self.mpc, why, e.xi1, speed, s.eta_unwrapped, pa_now, pd_now,
                            reference, d, e.accel_coefficients if observer else (0.0, 0.0, 0.0),
                            e.act_counter)
        if dec is not None:
            c = dec.command
            self._angles[c.sequence] = (c.phi_a, c.phi_d)
            self.observer.command_sent(c.sequence, c.phi_a, c.phi_d)
            prediction = None if dec.braking else dec.predicted_speed - d   # model-only mean
            if why == BETWEEN_PADS:           # the pending pad's cycle is now a braking one
                self._window_pred = None
            elif why == NEW_REFERENCE and self._queued:
                self._queued[-1] = prediction
            else:
                self._queued.append(prediction)
            self._idle = 0
        return ControlStep(e, d_before, d, speed, dec)
