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
from typing import Any, Callable, Mapping

import numpy as np

from hasel_wheel_bag.progress import progress_bar
from hasel_wheel_sim import layout as L
from hasel_wheel_sim.effects import effects_from_mapping
from hasel_wheel_sim.params import WheelParams
from hasel_wheel_sim.plant import Plant, PlantConfig, run_configs
from hasel_wheel_sim.model import SECTOR
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
    c = _run(plant, spec)
    return _trial(name or f"phi_a_{math.degrees(spec.phi_a):.0f}deg", c[:, 0], c)


def _run(plant: Plant, spec: SyntheticTrial, log: "_BagLog | None" = None,
         before_tick: Callable[[], None] | None = None) -> np.ndarray:
    """(k, 7) the recorded rows (t, angle, q, eta, n_a, phi_a, phi_d) of ``spec`` run on
    ``plant`` from its state: the firmware's schedule, braking, then HV off for the coast;
    ``before_tick`` is called before every tick; lost samples are missing."""
    plant.open_loop(spec.phi_a, spec.phi_d, priming=spec.priming)
    n_drive = int(round(spec.drive / TICK))
    n_brake = int(round(spec.brake[0] / TICK)) if spec.brake else 0
    n = n_drive + n_brake + int(round(spec.coast / TICK))
    rows = []
    for i in range(n):
        if i == n_drive and n_brake:
            plant.open_loop(spec.brake[1], spec.brake[2], priming=0,
                            priming_phi_a=spec.brake[1])
        if i == n_drive + n_brake:
            plant.wheel.cut_hv()
        if before_tick is not None:
            before_tick()
        row = _take(plant, log)
        if row is not None:
            rows.append(row)
    return np.asarray(rows, dtype=float).reshape(-1, 7)


def _trial(name: str, t: np.ndarray, c: np.ndarray, session_start: float | None = None
           ) -> Trial:
    """A trial of the rows ``c`` (:func:`_run`) on the clock ``t`` [s]."""
    return Trial(name, t, c[:, 1], c[:, 2].astype(np.int8), c[:, 3].astype(np.int64),
                 c[:, 4].astype(np.int64), c[:, 5], c[:, 6], None, "plant simulator",
                 session_start)


@dataclass(frozen=True)
class SessionChanges:
    """What changes over a recorded session: friction rising linearly with session time,
    tau_f (1 + ``friction_rate`` t) (``friction_rate`` [1/s]), and one pad's gain
    multiplied by ``step_factor`` from trial ``step_trial`` on (``step_pad`` 0..15, trials
    counted from 0; None for no step)."""

    friction_rate: float = 0.0
    step_pad: int | None = None
    step_trial: int = 0
    step_factor: float = 1.0


#: The paper's five trials at phi_a 1, 3, 5, 7, 9 deg, in the order 5, 1, 9, 3, 7 deg: a
#: session whose drifts do not follow the trials' speeds.
SESSION_SET = tuple(PAPER_SET[k] for k in (2, 0, 4, 1, 3))


def record_session(specs=SESSION_SET, gap: float = 20.0, params: WheelParams | None = None,
                   config: PlantConfig | None = None, changes: SessionChanges = SessionChanges(),
                   recorder: Any = None, ns: str = "/wheel", progress: str | None = None
                   ) -> list[Trial]:
    """Trials of ``specs`` run back to back on one plant, as a researcher records a session:
    after each trial's coast the wheel is held at rest with HV off for ``gap`` [s], then
    started at the next trial's initial speed.  The plant is never reset, so a retained
    charge carries from one trial to the next and recovers in the gaps; ``changes`` drift
    the friction and step a pad's gain.  Each trial's clock starts at 0 and its
    ``session_start`` [s] is the plant's time at its first sample.  With a ``recorder``
    (:class:`~hasel_wheel_mpc.recorder.Recorder`), every sample of the session (gaps
    included) is written under ``ns`` as the driver would record it: telemetry, and a
    command each time the schedule latches another one (HV reads 0 while nothing is
    latched).  ``progress``, when given, labels a bar of the trials on stderr (on a terminal)."""
    plant = Plant(params, config or PlantConfig(switching="tick"))
    wheel = plant.wheel
    tau0 = float(wheel.pv[L.P_FRICTION])
    log = None if recorder is None else _BagLog(recorder, ns)

    def drift() -> None:                        # the friction at this tick's session time
        wheel.pv[L.P_FRICTION] = tau0 * (1.0 + changes.friction_rate * plant.t)

    out, each = [], specs
    if progress:
        each = progress_bar(specs, progress, len(specs), unit="trial", scale=False)
    for k, spec in enumerate(each):
        if changes.step_pad is not None and k == changes.step_trial:
            wheel.pv[L.P_GAINS + changes.step_pad] *= changes.step_factor
        wheel.s[L.S_XI2] = spec.initial_speed
        wheel.s[L.S_ETA] = math.floor(wheel.s[L.S_XI1] / SECTOR)   # the pad in contact
        c = _run(plant, spec, log, drift)
        out.append(_trial(f"session{k + 1}_phi_a_{math.degrees(spec.phi_a):.0f}deg",
                          c[:, 0] - c[0, 0], c, float(c[0, 0])))
        if k + 1 < len(specs):
            wheel.s[L.S_XI2] = 0.0                       # held at rest through the gap
            for _ in range(int(round(gap / TICK))):
                _take(plant, log)
    return out


def session_trials(effects: Mapping[str, Any], changes: SessionChanges = SessionChanges(),
                   seed: int = 3, via: str = "csv", directory: Path | None = None
                   ) -> list[Trial]:
    """A :func:`record_session` of :data:`SESSION_SET` on a plant with :data:`ENCODER` and
    ``effects``, read back as a user's files would be: ``via`` "csv" (one file per trial
    with its session_t column, listed in reverse order) or "bag" (one bag of the whole
    session, gaps included), written under ``directory``."""
    from hasel_wheel_ident.data import load_trials, write_csv
    cfg = PlantConfig(seed=seed, switching="tick",
                      effects=effects_from_mapping({**ENCODER, **effects}))
    directory = Path(directory)
    if via == "csv":
        trials = record_session(config=cfg, changes=changes)
        paths = []
        for tr in trials:
            paths.append(directory / f"{tr.name}.csv")
            write_csv(tr, paths[-1])
        return load_trials(paths[::-1])
    if via != "bag":
        raise ValueError(f"via = {via!r}: expected 'csv' or 'bag'")
    from hasel_wheel_mpc.recorder import Recorder                  # the bag writer: only here
    rec = Recorder(directory / "bag")
    try:
        record_session(config=cfg, changes=changes, recorder=rec)
    finally:
        rec.close()
    return load_trials([directory / "bag"])


def _take(plant: Plant, log: "_BagLog | None") -> tuple | None:
    """One tick of ``plant``: the recorded row (t, angle, q, eta, n_a, phi_a, phi_d), or None
    for a lost sample; written to ``log`` too when given."""
    sample = plant.step()
    if sample is None:
        return None
    s = plant.wheel.s
    armed = s[L.S_ARMED] != 0.0
    n_a = int(s[L.S_ETA]) % 16 if armed else -1
    pa, pd = (s[L.S_PHI_A], s[L.S_PHI_D]) if armed else (math.nan, math.nan)
    if log is not None:
        log.write(sample, n_a, pa, pd)
    return sample.t, sample.angle, sample.q, sample.eta, n_a, pa, pd


class _BagLog:
    """A plant's samples written to a recorder as the driver records them: a command each
    time the schedule latches another one (numbered from 1), the telemetry naming it, and HV
    reading 0 while nothing is latched or on."""

    def __init__(self, recorder: Any, ns: str) -> None:
        self.recorder, self.ns = recorder, ns
        self.last: tuple[int, float, float] | None = None
        self.seq = 0

    def write(self, sample: Any, n_a: int, pa: float, pd: float) -> None:
        from hasel_wheel_common.samples import Command
        if n_a >= 0 and self.last != (n_a, pa, pd):
            self.seq += 1
            self.recorder.command(self.ns, Command(n_a, float(pa), float(pd), self.seq), sample.t)
        self.last = (n_a, pa, pd) if n_a >= 0 else None
        live = n_a >= 0 or sample.q
        self.recorder.telemetry(self.ns, sample._replace(
            last_command_sequence=self.seq if n_a >= 0 else 0,
            hv_monitor=sample.hv_monitor if live else 0.0))


def record_set(specs=PAPER_SET, params: WheelParams | None = None,
               config: PlantConfig | None = None, progress: str | None = None) -> list[Trial]:
    """Several trials of the same wheel: trial i draws its noise from seed ``config.seed + i``,
    while the wheel's actuator gains (if spread) are drawn once, from ``config.seed``.
    ``progress``, when given, labels a bar of the trials on stderr (on a terminal)."""
    specs = list(specs)
    if not specs:
        return []
    configs = run_configs(config or PlantConfig(switching="tick"), len(specs), same_wheel=True)
    runs = zip(specs, configs)
    if progress:
        runs = progress_bar(runs, progress, len(specs), unit="trial", scale=False)
    return [record(spec, params, cfg) for spec, cfg in runs]


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
