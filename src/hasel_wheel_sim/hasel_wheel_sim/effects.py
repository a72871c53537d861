"""Real-wheel effects the paper's model lacks, configured from YAML (all off by default).

Model effects change the physics (or, for ``angle_eccentricity``, what the firmware's
angle sensor reads, on which it switches) and are passed to the model as
:class:`~hasel_wheel_sim.model.Extensions`, so the plant, the MPC predictor and the
identification share them.  Sensor noise and link effects only exist in the plant.

========================  =========================================================  ============
effect (YAML key)         what it does                                               direction
========================  =========================================================  ============
charge_retention          force x exp(-rate * Q_i); dQ_i/dt = q_i - Q_i / recovery   slows the wheel over time
gain_spread               actuator i's force x g_i, g_i ~ N(1, std) from the seed     16-sector speed ripple
com_offset                axle torque -torque * sin(xi1 + phase)                      1/rev speed ripple
viscous_drag              axle torque -coefficient * xi2                              lower speed, faster coast-down
rise_lag                  force x (1 - exp(-t_on / time_constant))                    weaker pushes, lower speed
platform_disturbance      axle torque torque * sin((r/L) xi1 + phase)                 ripple once per lap of the pivot
angle_eccentricity        angle read as xi1 + amplitude * sin(xi1 + phase)            1/rev reading error, ~ speed
start_push                a pad switched on at a slow wheel pushes (model.start_push)  a standing wheel can start
pad_death                 pad i's force x gain from a set time on (a broken pad)      a weak sector, every turn
obstacle                  extra Coulomb friction torque for a set time (a kerb)       the wheel slows or stops
encoder                   10-bit quantisation (floor) plus Gaussian angle noise       measured angle error
encoder_glitches          a sample's count replaced by a random one, probability p   isolated outliers
dropouts                  a telemetry sample is lost, probability p                  missing samples
serial_latency            commands reach the wheel, and samples the host, late        late switching decisions
========================  =========================================================  ============
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from hasel_wheel_sim.model import N_ACTUATORS, Extensions
from hasel_wheel_sim.params import FieldSpec, ParameterError, read_valued_mapping

INF = math.inf

#: effect -> {parameter -> spec}.  Each effect is written ``{enabled: bool, <param>: {value, unit}}``.
EFFECT_FIELDS: dict[str, dict[str, FieldSpec]] = {
    "charge_retention": {
        "rate": FieldSpec("1/s", 0.0, 10.0, low_closed=True, doc="force loss per second of HV time"),
        "recovery": FieldSpec("s", 0.0, 1e6, doc="recovery time constant of the retained charge"),
    },
    "gain_spread": {
        "std": FieldSpec("1", 0.0, 0.5, low_closed=True, high_closed=True,
                         doc="standard deviation of the 16 actuator gains around 1"),
    },
    "com_offset": {
        "torque": FieldSpec("N*m", 0.0, 1.0, low_closed=True, doc="m_offset * g * offset"),
        "phase": FieldSpec("rad", -math.pi, math.pi, True, True, doc="angle of the offset"),
    },
    "viscous_drag": {
        "coefficient": FieldSpec("N*m*s/rad", 0.0, 1.0, low_closed=True, doc="drag per speed"),
    },
    "rise_lag": {
        "time_constant": FieldSpec("s", 0.0, 1.0, doc="actuator force build-up time constant"),
    },
    "platform_disturbance": {
        "torque": FieldSpec("N*m", 0.0, 1.0, low_closed=True, doc="amplitude"),
        "phase": FieldSpec("rad", -math.pi, math.pi, True, True, doc="pivot angle of the peak"),
    },
    "angle_eccentricity": {
        "amplitude": FieldSpec("rad", 0.0, 0.2, low_closed=True, high_closed=True,
                               doc="first-harmonic error of the angle reading (disc offset / radius)"),
        "phase": FieldSpec("rad", -math.pi, math.pi, True, True, doc="phase of the error"),
    },
    "start_push": {
        "torque": FieldSpec("N*m", 0.0, 1.0, low_closed=True, high_closed=True,
                            doc="push of a pad switched on at a standing wheel"),
        "stroke": FieldSpec("rad", 0.0, 1.0, high_closed=True, doc="travel over which it falls to 0"),
        "speed": FieldSpec("rad/s", 0.0, 10.0, high_closed=True,
                           doc="switch-on speed at and above which a pad does not push"),
    },
    "pad_death": {
        "pad": FieldSpec("1", 0.0, 15.0, True, True, doc="index of the pad that fails (whole number)"),
        "time": FieldSpec("s", 0.0, 1e6, low_closed=True, high_closed=True,
                          doc="simulated time at which it fails"),
        "gain": FieldSpec("1", 0.0, 1.0, low_closed=True, high_closed=True,
                          doc="what is left of its force (0: none)"),
    },
    "obstacle": {
        "time": FieldSpec("s", 0.0, 1e6, low_closed=True, high_closed=True,
                          doc="simulated time at which the wheel meets it"),
        "duration": FieldSpec("s", 0.0, 1e6, high_closed=True,
                              doc="how long it holds the wheel back (1e6: for good)"),
        "torque": FieldSpec("N*m", 0.0, 1.0, high_closed=True,
                            doc="Coulomb friction torque it adds at the axle"),
    },
    "encoder": {
        "noise_std": FieldSpec("rad", 0.0, 0.1, low_closed=True, doc="Gaussian angle noise"),
    },
    "encoder_glitches": {
        "probability": FieldSpec("1", 0.0, 1.0, low_closed=True, high_closed=True,
                                 doc="chance per sample of a random count"),
    },
    "dropouts": {
        "probability": FieldSpec("1", 0.0, 1.0, low_closed=True, doc="chance per sample of loss"),
    },
    "serial_latency": {
        "command": FieldSpec("s", 0.0, 1.0, low_closed=True, doc="host -> wheel delay"),
        "telemetry": FieldSpec("s", 0.0, 1.0, low_closed=True, doc="wheel -> host delay"),
    },
}


#: Effects the model carries (they become :class:`Extensions`): the dynamics, and the angle
#: sensor's eccentricity, on whose reading the firmware switches; the others are the sensor
#: noise and link effects, which only the plant has.
DYNAMIC_EFFECTS = ("charge_retention", "gain_spread", "com_offset", "viscous_drag", "rise_lag",
                   "platform_disturbance", "angle_eccentricity", "start_push")
#: Events the plant alone has, at a set time (a failure the controller must notice itself).
EVENT_EFFECTS = ("pad_death", "obstacle")


@dataclass(frozen=True)
class EffectsConfig:
    """Enabled effects and their parameters (SI); ``enabled`` lists effect names."""

    enabled: frozenset[str] = frozenset()
    values: Mapping[str, Mapping[str, float]] = field(default_factory=dict)
    gains: tuple[float, ...] | None = None  # explicit actuator gains (override gain_spread)

    def on(self, effect: str) -> bool:
        return effect in self.enabled

    def get(self, effect: str, name: str, default: float = 0.0) -> float:
        return float(self.values.get(effect, {}).get(name, default)) if self.on(effect) else default

    def extensions(self, rng: np.random.Generator | None = None) -> Extensions:
        """The dynamic part as model extensions; actuator gains are drawn from ``rng``."""
        gains: tuple[float, ...] = (1.0,) * N_ACTUATORS
        if self.gains is not None:
            gains = tuple(self.gains)
        elif self.on("gain_spread"):
            if rng is None:
                raise ValueError("gain_spread needs a seeded random generator")
            std = self.get("gain_spread", "std")
            gains = tuple(float(g) for g in np.clip(rng.normal(1.0, std, N_ACTUATORS), 0.05, None))
        return Extensions(
            com_torque=self.get("com_offset", "torque"),
            com_phase=self.get("com_offset", "phase"),
            platform_torque=self.get("platform_disturbance", "torque"),
            platform_phase=self.get("platform_disturbance", "phase"),
            viscous=self.get("viscous_drag", "coefficient"),
            rise_time=self.get("rise_lag", "time_constant"),
            retention_rate=self.get("charge_retention", "rate"),
            retention_recovery=self.get("charge_retention", "recovery", 300.0),
            angle_eccentricity=self.get("angle_eccentricity", "amplitude"),
            angle_eccentricity_phase=self.get("angle_eccentricity", "phase"),
            start_torque=self.get("start_push", "torque"),
            start_stroke=self.get("start_push", "stroke", Extensions.start_stroke),
            start_speed=self.get("start_push", "speed", Extensions.start_speed),
            gains=gains,
        )

    def with_extensions(self, ext: Extensions, where: str = "effects") -> "EffectsConfig":
        """These sensor and link effects with the dynamics of ``ext`` (e.g. a model file's).

        ``extensions()`` of the result returns ``ext`` exactly and draws nothing from the
        generator.  The dynamics must come from one place only: if a dynamic effect is enabled
        here as well (or explicit actuator gains are set), :class:`ParameterError` names it.
        """
        clash = sorted(self.enabled & set(DYNAMIC_EFFECTS))
        if self.gains is not None:
            clash.append("actuator_gains")
        if clash:
            raise ParameterError(
                f"{where}: {clash} describe the wheel (its dynamics or its angle sensor), which "
                f"the model's extensions give here; disable them (keep only noise/link effects: "
                f"{sorted(set(EFFECT_FIELDS) - set(DYNAMIC_EFFECTS))})")
        values = {k: v for k, v in self.values.items() if k not in DYNAMIC_EFFECTS}
        values.update({
            "com_offset": {"torque": ext.com_torque, "phase": ext.com_phase},
            "platform_disturbance": {"torque": ext.platform_torque, "phase": ext.platform_phase},
            "viscous_drag": {"coefficient": ext.viscous},
            "rise_lag": {"time_constant": ext.rise_time},
            "charge_retention": {"rate": ext.retention_rate, "recovery": ext.retention_recovery},
            "angle_eccentricity": {"amplitude": ext.angle_eccentricity,
                                   "phase": ext.angle_eccentricity_phase},
            "start_push": {"torque": ext.start_torque, "stroke": ext.start_stroke,
                           "speed": ext.start_speed},
        })
        enabled = self.enabled | {"com_offset", "platform_disturbance", "viscous_drag", "rise_lag",
                                  "charge_retention", "angle_eccentricity", "start_push"}
        return EffectsConfig(frozenset(enabled), values, tuple(float(g) for g in ext.gains))


def effects_from_mapping(data: Any, where: str = "effects") -> EffectsConfig:
    """Parse ``{effect: {enabled: bool, param: {value, unit}, ...}}``; missing effects are off.

    Unknown effects or parameters, wrong units and bad values raise :class:`ParameterError`.
    An enabled effect must give all its parameters.
    """
    if data is None:
        return EffectsConfig()
    if not isinstance(data, Mapping):
        raise ParameterError(f"{where}: expected a mapping of effect names, got {type(data).__name__}")
    unknown = sorted(set(data) - set(EFFECT_FIELDS) - {"actuator_gains"})
    if unknown:
        raise ParameterError(f"{where}: unknown effect(s) {unknown}; known effects are "
                             f"{sorted(EFFECT_FIELDS)}")
    enabled: set[str] = set()
    values: dict[str, dict[str, float]] = {}
    for name, spec in EFFECT_FIELDS.items():
        entry = data.get(name)
        if entry is None:
            continue
        if not isinstance(entry, Mapping) or not isinstance(entry.get("enabled"), bool):
            raise ParameterError(f"{where}.{name}: expected {{enabled: true|false, ...}}, got {entry!r}")
        params = {k: v for k, v in entry.items() if k != "enabled"}
        values[name] = read_valued_mapping(params, spec, f"{where}.{name}", required=entry["enabled"])
        if entry["enabled"]:
            enabled.add(name)
    gains = data.get("actuator_gains")
    if gains is not None:
        if (not isinstance(gains, list) or len(gains) != N_ACTUATORS
                or not all(isinstance(g, (int, float)) and not isinstance(g, bool)
                           and math.isfinite(g) and 0.0 < g <= 10.0 for g in gains)):
            raise ParameterError(f"{where}.actuator_gains: expected a list of {N_ACTUATORS} "
                                 f"finite gains in (0, 10] (unit 1), got {gains!r}")
        gains = tuple(float(g) for g in gains)
    return EffectsConfig(frozenset(enabled), values, gains)


#: Every effect of a wheel switched on with representative values (used by ``--effects all``
#: and benchmarks); the events (:data:`EVENT_EFFECTS`) stay off.  The start push is the
#: Fig. 5 wheel of docs/model.md ("Start from rest").
REALISTIC = {
    "start_push": {"enabled": True, "torque": {"value": 0.05, "unit": "N*m"},
                   "stroke": {"value": 0.2, "unit": "rad"},
                   "speed": {"value": 0.5, "unit": "rad/s"}},
    "charge_retention": {"enabled": True, "rate": {"value": 0.01, "unit": "1/s"},
                         "recovery": {"value": 300.0, "unit": "s"}},
    "gain_spread": {"enabled": True, "std": {"value": 0.08, "unit": "1"}},
    "com_offset": {"enabled": True, "torque": {"value": 0.004, "unit": "N*m"},
                   "phase": {"value": 0.5, "unit": "rad"}},
    "viscous_drag": {"enabled": True, "coefficient": {"value": 0.0005, "unit": "N*m*s/rad"}},
    "rise_lag": {"enabled": True, "time_constant": {"value": 0.01, "unit": "s"}},
    "platform_disturbance": {"enabled": True, "torque": {"value": 0.002, "unit": "N*m"},
                             "phase": {"value": 0.0, "unit": "rad"}},
    "encoder": {"enabled": True, "noise_std": {"value": 0.001, "unit": "rad"}},
    "encoder_glitches": {"enabled": True, "probability": {"value": 0.001, "unit": "1"}},
    "dropouts": {"enabled": True, "probability": {"value": 0.002, "unit": "1"}},
    "serial_latency": {"enabled": True, "command": {"value": 0.004, "unit": "s"},
                       "telemetry": {"value": 0.002, "unit": "s"}},
}
