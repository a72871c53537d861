"""Open-loop characterisation trials (paper Sec. IV-B, Table II) in the embedded runner.

A trial starts the wheel at an initial speed, optionally primes it with a few activations
at 3 deg as the paper does, then lets the firmware's sequential schedule switch every
actuator at (phi_a, phi_d) for a fixed duration.  Results are the true speed trace, the
steady speed (mean over the last 10 s) and t90 (first time above 90 % of it).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from hasel_wheel_common.samples import Command
from hasel_wheel_sim import layout as L
from hasel_wheel_sim.params import (FieldSpec, ParameterError, WheelParams, check_value,
                                    read_valued_mapping)
from hasel_wheel_sim.plant import Plant, PlantConfig
from hasel_wheel_sim.wheel import TICK

from hasel_wheel_mpc.recorder import Recorder

STEADY_WINDOW = 10.0  # [s] steady speed = mean over the last 10 s


@dataclass(frozen=True)
class TrialSpec:
    """One open-loop trial (angles rad, speed rad/s, time s)."""

    phi_a: float
    phi_d: float
    duration: float = 60.0
    initial_speed: float = 1.0
    priming: int = 0
    priming_phi_a: float = math.radians(3.0)
    rule: str = "after_active"

    @property
    def label(self) -> str:
        a = f"phi_a_{math.degrees(self.phi_a):04.1f}deg".replace(".", "p")
        return a if abs(self.phi_d - math.radians(22.0)) < 1e-9 else \
            a + f"_phi_d_{math.degrees(self.phi_d):04.1f}deg".replace(".", "p")


@dataclass
class TrialResult:
    spec: TrialSpec
    switching: str
    t: np.ndarray       # (n,) sample times [s]
    speed: np.ndarray   # (n,) true speed [rad/s]
    steady_speed: float
    t90: float


def steady_speed(t: np.ndarray, v: np.ndarray, window: float = STEADY_WINDOW) -> float:
    """Mean of v [rad/s] over the last ``window`` seconds of t."""
    return float(np.mean(v[t > t[-1] - window]))


def rise_time_90(t: np.ndarray, v: np.ndarray, v_ss: float) -> float:
    """First time [s] at which v exceeds 90 % of v_ss (nan if never)."""
    above = np.nonzero(v > 0.9 * v_ss)[0]
    return float(t[above[0]]) if above.size else math.nan


def run_trial(spec: TrialSpec, params: WheelParams | None = None,
              config: PlantConfig | None = None, recorder: Recorder | None = None,
              namespace: str = "") -> TrialResult:
    """Run one open-loop trial on a fresh plant; record it under ``namespace`` if asked."""
    config = config or PlantConfig()
    plant = Plant(params, config, xi1=0.0, xi2=spec.initial_speed)
    plant.open_loop(spec.phi_a, spec.phi_d, spec.rule, spec.priming, spec.priming_phi_a)
    n = int(round(spec.duration / TICK))
    t = np.empty(n)
    v = np.empty(n)
    s = plant.wheel.s
    cycle = 0
    for k in range(n):
        sample = plant.step()
        t[k] = plant.t
        v[k] = s[L.S_XI2]
        if recorder is None:
            continue
        for ev in plant.last_events:
            if int(ev[2]) in (L.EV_OFF, L.EV_ARM) and s[L.S_ARMED]:
                cycle += 1
                recorder.command(namespace, Command(int(s[L.S_ETA]) % 16, float(s[L.S_PHI_A]),
                                                   float(s[L.S_PHI_D]), cycle), float(ev[0]))
        if sample is not None:
            recorder.telemetry(namespace, sample)
        recorder.true_state(namespace, plant.t, plant.wheel.state)
    ss = steady_speed(t, v)
    return TrialResult(spec, config.switching, t, v, ss, rise_time_90(t, v, ss))


_TRIAL_FIELDS = {
    "duration": FieldSpec("s", 0.0, 3600.0, doc="length of each trial"),
    "initial_speed": FieldSpec("rad/s", 0.0, 20.0, doc="wheel speed at t = 0"),
    "priming_phi_a": FieldSpec("rad", 0.0, math.pi / 8, low_closed=True, doc="priming phi_a"),
}
_ANGLE = FieldSpec("rad", 0.0, math.pi / 8, low_closed=True, high_closed=True)


def _angles(data: Any, name: str, where: str) -> list[float]:
    """``{value: x, unit: rad}`` (one angle) or ``{values: [...], unit: rad}`` (a list)."""
    if not isinstance(data, Mapping) or data.get("unit") != "rad" or not (
            ("value" in data) ^ ("values" in data)):
        raise ParameterError(f"{where}.{name}: expected {{value: <rad>, unit: rad}} or "
                             f"{{values: [<rad>, ...], unit: rad}}, got {data!r}")
    raw = [data["value"]] if "value" in data else data["values"]
    if not isinstance(raw, list) or not raw:
        raise ParameterError(f"{where}.{name}.values: expected a non-empty list of angles [rad]")
    key = f"{name}.values" if "values" in data else name
    return [check_value(f"{key}[{i}]" if "values" in data else key, a, _ANGLE, where)
            for i, a in enumerate(raw)]


def trials_from_mapping(data: Any, where: str = "open_loop") -> list[TrialSpec]:
    """Parse an ``open_loop:`` section into trials (one per phi_a value).

    Only ``phi_a`` is required; the rest default to the paper's set-up (60 s, 1 rad/s,
    phi_d = 22 deg, no priming, priming at 3 deg, targets after the actuator of interest).
    """
    if not isinstance(data, Mapping):
        raise ParameterError(f"{where}: expected a mapping, got {type(data).__name__}")
    known = set(_TRIAL_FIELDS) | {"phi_a", "phi_d", "priming_count", "sequential_rule"}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ParameterError(f"{where}: unknown key(s) {unknown}; expected {sorted(known)}")
    vals = read_valued_mapping({k: data[k] for k in _TRIAL_FIELDS if k in data}, _TRIAL_FIELDS,
                               where, required=False)
    phi_a = _angles(data.get("phi_a"), "phi_a", where)
    phi_d = _angles(data.get("phi_d", {"value": math.radians(22.0), "unit": "rad"}), "phi_d", where)
    if len(phi_d) == 1:
        phi_d = phi_d * len(phi_a)
    if len(phi_d) != len(phi_a):
        raise ParameterError(f"{where}: phi_d has {len(phi_d)} values but phi_a has {len(phi_a)}; "
                             f"give one phi_d for all trials or one per phi_a")
    priming = data.get("priming_count", 0)
    if isinstance(priming, bool) or not isinstance(priming, int) or not 0 <= priming <= 100:
        raise ParameterError(f"{where}.priming_count = {priming!r}: expected an integer 0..100")
    rule = data.get("sequential_rule", "after_active")
    if rule not in ("after_active", "after_measured"):
        raise ParameterError(f"{where}.sequential_rule = {rule!r}: expected 'after_active' or "
                             f"'after_measured'")
    out = []
    for i, (pa, pd) in enumerate(zip(phi_a, phi_d)):
        if not pa < pd:
            raise ParameterError(f"{where}: trial {i}: phi_a = {pa!r} rad must be smaller than "
                                 f"phi_d = {pd!r} rad")
        out.append(TrialSpec(phi_a=pa, phi_d=pd, duration=vals.get("duration", 60.0),
                             initial_speed=vals.get("initial_speed", 1.0), priming=priming,
                             priming_phi_a=vals.get("priming_phi_a", math.radians(3.0)),
                             rule=rule))
    return out
