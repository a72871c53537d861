"""Recordings from the plant simulator, for tests, benchmarks and the worked example.

Each trial is the paper's open-loop characterisation run (Sec. IV-B): start at an initial
speed, let the firmware switch every actuator at (phi_a, phi_d) on its ticks, then switch HV
off and record the coast-down, all through the simulated 10-bit encoder.
:func:`closed_loop_trials` records runs of the embedded closed loop instead (observer and MPC
choosing every push), read back from their bag as a user's ``hasel_wheel demo`` bag would be.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from hasel_wheel_sim import layout as L
from hasel_wheel_sim.effects import effects_from_mapping
from hasel_wheel_sim.params import WheelParams
from hasel_wheel_sim.plant import Plant, PlantConfig, run_configs
from hasel_wheel_sim.wheel import TICK

from hasel_wheel_ident.data import Trial


@dataclass(frozen=True)
class SyntheticTrial:
    """Open-loop drive at (phi_a, phi_d) [rad] for ``drive`` [s], optionally braking, then a
    coast of ``coast`` [s]."""

    phi_a: float
    phi_d: float = math.radians(22.0)
    drive: float = 50.0
    coast: float = 10.0
    initial_speed: float = 1.0
    priming: int = 6
    #: optional braking after the drive: (duration [s], phi_a [rad], phi_d [rad]), both <= 0
    brake: tuple[float, float, float] | None = None


#: The paper's five fitting trials (Fig. 9): phi_a = 1, 3, 5, 7, 9 deg at phi_d = 22 deg.
PAPER_SET = tuple(SyntheticTrial(math.radians(a)) for a in (1.0, 3.0, 5.0, 7.0, 9.0))
#: Three short trials (phi_a 1, 4, 7 deg; 25 s driven, 9 s coasting): the tests' data set.
SHORT_SET = tuple(SyntheticTrial(math.radians(a), drive=25.0, coast=9.0) for a in (1.0, 4.0, 7.0))
#: The 10-bit encoder with 1 mrad Gaussian noise, as a plant ``effects`` entry.
ENCODER = {"encoder": {"enabled": True, "noise_std": {"value": 0.001, "unit": "rad"}}}


def record(spec: SyntheticTrial, params: WheelParams | None = None,
           config: PlantConfig | None = None, name: str = "") -> Trial:
    """Run one trial on a fresh plant (tick switching unless ``config`` says otherwise)."""
    config = config or PlantConfig(switching="tick")
    plant = Plant(params, config, xi1=0.0, xi2=spec.initial_speed)
    plant.open_loop(spec.phi_a, spec.phi_d, priming=spec.priming)
    n_drive = int(round(spec.drive / TICK))
    n_brake = int(round(spec.brake[0] / TICK)) if spec.brake else 0
    n = n_drive + n_brake + int(round(spec.coast / TICK))
    cols = np.zeros((n, 7))
    s = plant.wheel.s
    k = 0
    for i in range(n):
        if i == n_drive and n_brake:
            plant.open_loop(spec.brake[1], spec.brake[2], priming=0,
                            priming_phi_a=spec.brake[1])
        if i == n_drive + n_brake:
            plant.wheel.cut_hv()
        sample = plant.step()
        if sample is None:           # a dropped sample is simply missing from the log
            continue
        armed = s[L.S_ARMED] != 0.0
        cols[k] = (sample.t, sample.angle, sample.q, sample.eta,
                   int(s[L.S_ETA]) % 16 if armed else -1,
                   s[L.S_PHI_A] if armed else math.nan, s[L.S_PHI_D] if armed else math.nan)
        k += 1
    c = cols[:k]
    return Trial(name or f"phi_a_{math.degrees(spec.phi_a):.0f}deg", c[:, 0], c[:, 1],
                 c[:, 2].astype(np.int8), c[:, 3].astype(np.int64), c[:, 4].astype(np.int64),
                 c[:, 5], c[:, 6], None, "plant simulator")


def record_set(specs=PAPER_SET, params: WheelParams | None = None,
               config: PlantConfig | None = None) -> list[Trial]:
    """Several trials of the same wheel: trial i draws its noise from seed ``config.seed + i``,
    while the wheel's actuator gains (if spread) are drawn once, from ``config.seed``."""
    specs = list(specs)
    if not specs:
        return []
    configs = run_configs(config or PlantConfig(switching="tick"), len(specs), same_wheel=True)
    return [record(spec, params, cfg) for spec, cfg in zip(specs, configs)]


def encoder_trials(effects: dict, seed: int = 3, specs=SHORT_SET) -> list[Trial]:
    """:func:`record_set` of ``specs`` on a plant with :data:`ENCODER` and ``effects`` (a plant
    ``effects`` mapping, see :mod:`hasel_wheel_sim.effects`), tick switching, seed ``seed``."""
    cfg = PlantConfig(seed=seed, switching="tick",
                      effects=effects_from_mapping({**ENCODER, **effects}))
    return record_set(specs, config=cfg)


def closed_loop_trials(effects: Mapping[str, Any], profile: tuple[tuple[float, float], ...],
                       duration: float, seeds: tuple[int, ...], directory: Path) -> list[Trial]:
    """One run of the embedded closed loop (:func:`~hasel_wheel_mpc.closed_loop.run_closed_loop`,
    the paper's model in the controller) per plant seed in ``seeds``, on ``profile`` ((start
    [s], reference [rad/s]), ...) for ``duration`` [s], on a plant with :data:`ENCODER` and
    ``effects``, tick switching.  All runs go into one bag under ``directory`` (namespace
    ``/wheel<seed>``), which is read back as the trials."""
    from hasel_wheel_mpc.closed_loop import run_closed_loop          # the loop needs the MPC: only here
    from hasel_wheel_mpc.recorder import Recorder
    from hasel_wheel_ident.data import load_trials
    path = Path(directory) / "bag"
    rec = Recorder(path)
    try:
        for seed in seeds:
            cfg = PlantConfig(seed=seed, switching="tick",
                              effects=effects_from_mapping({**ENCODER, **effects}))
            run_closed_loop(profile, duration, cfg, recorder=rec, ns=f"/wheel{seed}",
                            clock=lambda: 0.0)
    finally:
        rec.close()
    return load_trials([path])
