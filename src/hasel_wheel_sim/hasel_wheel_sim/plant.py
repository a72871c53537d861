"""The plant simulator: the hybrid model plus the effects a real wheel has.

``Plant.step(command, dt) -> telemetry`` is the whole contract: it takes the command the
host sends now (or None), advances the wheel by one 300 Hz firmware tick and returns what
the host receives now (a :class:`TelemetrySample`, or None when a sample is lost or still
in flight).  The same seed and configuration give bit-identical runs: every random draw
comes from one ``numpy.random.Generator`` in a fixed order.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from hasel_wheel_common import protocol as P
from hasel_wheel_common.samples import ENCODER_COUNT, ENCODER_COUNTS, Command, TelemetrySample

from hasel_wheel_sim import layout as L
from hasel_wheel_sim.effects import EffectsConfig, effects_from_mapping
from hasel_wheel_sim.model import Extensions, angle_reading
from hasel_wheel_sim.model_file import load_model
from hasel_wheel_sim.params import ParameterError, WheelParams, load_wheel_params, load_yaml_file
from hasel_wheel_sim.wheel import TICK, HybridWheel, SwitchMode

COUNT = ENCODER_COUNT  # one encoder count [rad]
HV_SUPPLY_V = 9000.0                    # HV converter output while HV is enabled [V]
ACTUATOR_CURRENT_A = 3e-4               # supply current while an actuator charges [A]
MAX_ON_TIME = 2.0                       # the device's default maximum on-time [s] (rule 5)


@dataclass(frozen=True)
class PlantConfig:
    """Seed, switching mode and effects of a plant (see ``config/plant.yaml``)."""

    seed: int = 0
    switching: SwitchMode = "exact"
    effects: EffectsConfig = field(default_factory=EffectsConfig)


def plant_config_from_mapping(data: Any, where: str = "plant") -> PlantConfig:
    """Parse ``{seed: int, switching: exact|tick, effects: {...}}`` with clear errors."""
    if data is None:
        return PlantConfig()
    if not isinstance(data, Mapping):
        raise ParameterError(f"{where}: expected a mapping, got {type(data).__name__}")
    unknown = sorted(set(data) - {"seed", "switching", "effects"})
    if unknown:
        raise ParameterError(f"{where}: unknown key(s) {unknown}; expected seed, switching, effects")
    seed = data.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ParameterError(f"{where}.seed = {seed!r}: expected a non-negative integer")
    switching = data.get("switching", "exact")
    if switching not in ("exact", "tick"):
        raise ParameterError(f"{where}.switching = {switching!r}: expected 'exact' (switch at the "
                             f"crossing angle) or 'tick' (switch on the first 300 Hz tick after it)")
    return PlantConfig(seed, switching, effects_from_mapping(data.get("effects"), f"{where}.effects"))


def load_plant_config(path: str | Path) -> PlantConfig:
    """Load the ``plant:`` section of a YAML file."""
    data = load_yaml_file(path)
    if not isinstance(data, Mapping) or "plant" not in data:
        raise ParameterError(f"{path}: expected a top-level 'plant:' section")
    return plant_config_from_mapping(data["plant"], f"{path}: plant")


def plant_with_model(config: PlantConfig, ext: Extensions, where: str = "plant") -> PlantConfig:
    """``config`` with its dynamics replaced by ``ext`` (a model file's extensions).

    Seed, switching and the sensor/link effects (encoder, glitches, dropouts, latency) stay;
    a dynamic effect enabled in ``config`` as well raises :class:`ParameterError` (see
    :meth:`EffectsConfig.with_extensions`).
    """
    return replace(config, effects=config.effects.with_extensions(ext, f"{where}.effects"))


def run_configs(config: PlantConfig, runs: int, *, same_wheel: bool) -> list[PlantConfig]:
    """Plants of ``runs`` recordings: run i draws its noise from seed ``config.seed + i``.

    With ``same_wheel`` the runs are of one wheel, as a researcher records one wheel several
    times: its actuator gains (when spread) are drawn once, from ``config.seed``, and held.
    Otherwise each run is a wheel of its own, drawing its gains from its own seed.  (Held
    gains are not drawn, so run 0 of one wheel draws other noise than a plant of
    ``config`` itself, which draws its gains first.)
    """
    if isinstance(runs, bool) or not isinstance(runs, int) or runs < 1:
        raise ParameterError(f"runs = {runs!r}: expected a whole number of recordings, at "
                             f"least 1")
    if same_wheel:
        gains = config.effects.extensions(np.random.default_rng(config.seed)).gains
        config = replace(config, effects=replace(config.effects, gains=tuple(gains)))
    return [replace(config, seed=config.seed + i) for i in range(runs)]


def load_plant_model(wheel_params_file: str | Path, plant_file: str | Path,
                     model_file: str | Path = "") -> tuple[WheelParams, PlantConfig]:
    """The sim node's plant: (parameters, config) from its three file parameters.

    ``model_file`` '' : ``wheel_params_file`` and ``plant_file`` as they are.  Otherwise the
    model file's parameters and extensions are the dynamics (``wheel_params_file`` is not read)
    and ``plant_file`` adds seed, switching and sensor/link effects (:func:`plant_with_model`).
    """
    if not model_file:
        return load_wheel_params(wheel_params_file), load_plant_config(plant_file)
    params, ext = load_model(model_file)
    return params, plant_with_model(load_plant_config(plant_file), ext, f"{plant_file}: plant")


class _Draws:
    """Random numbers drawn from one generator in blocks of fixed size, in a fixed order.

    A block holds, per tick, one standard normal and two uniforms, so the stream depends only
    on the seed and the number of ticks, never on which effects consume the values.
    """

    BLOCK = 4096

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self.k = self.BLOCK

    def next(self) -> tuple[float, float, float]:
        """(standard normal, uniform, uniform) for one tick."""
        if self.k == self.BLOCK:
            self.normal = self.rng.standard_normal(self.BLOCK).tolist()
            self.uniform = self.rng.random((self.BLOCK, 2)).tolist()
            self.k = 0
        k = self.k
        self.k += 1
        u = self.uniform[k]
        return self.normal[k], u[0], u[1]


class PlantEvents:
    """The plant's events at a set time (effects ``pad_death`` and ``obstacle``).

    From ``pad_death.time`` [s] on, pad ``pad_death.pad``'s force gain is multiplied by
    ``pad_death.gain``.  During [``obstacle.time``, + ``obstacle.duration``) [s] the Coulomb
    friction torque at the axle grows by ``obstacle.torque`` [N*m]: it brakes a rolling wheel
    and holds a standing one up to that torque.  Each applies at the start of the first tick
    at or after its time.  Tests: ``test_effects.py::test_a_pad_dies_at_its_time`` and
    ``::test_an_obstacle_stops_the_wheel_for_its_duration``.
    """

    def __init__(self, fx: EffectsConfig, pv: np.ndarray) -> None:
        pad = fx.get("pad_death", "pad")
        if pad != int(pad):
            raise ParameterError(f"plant.effects.pad_death.pad = {pad!r}: expected a whole pad "
                                 f"index 0..15")
        self.pad_death = (int(pad), fx.get("pad_death", "time"),
                          fx.get("pad_death", "gain")) if fx.on("pad_death") else None
        self.obstacle = (fx.get("obstacle", "time"), fx.get("obstacle", "duration"),
                         fx.get("obstacle", "torque")) if fx.on("obstacle") else None
        self._friction = float(pv[L.P_FRICTION])

    def apply(self, t: float, pv: np.ndarray) -> None:
        """Set ``pv`` for the tick starting at ``t`` [s]."""
        if self.pad_death is not None and t >= self.pad_death[1] - 1e-9:
            pad, _, gain = self.pad_death
            pv[L.P_GAINS + pad] *= gain
            self.pad_death = None
        if self.obstacle is not None:
            start, duration, torque = self.obstacle
            on = start - 1e-9 <= t < start + duration - 1e-9
            pv[L.P_FRICTION] = self._friction + (torque if on else 0.0)


class Plant:
    """A simulated wheel behind a simulated Teensy (sampling, encoder, link delays)."""

    def __init__(self, params: WheelParams | None = None, config: PlantConfig | None = None,
                 xi1: float = 0.0, xi2: float = 0.0) -> None:
        self.config = config or PlantConfig()
        self.rng = np.random.default_rng(self.config.seed)
        fx = self.config.effects
        self.extensions = fx.extensions(self.rng)
        self.wheel = HybridWheel(params, self.extensions, self.config.switching, xi1, xi2)
        self.sequence = 0
        self.last_events = np.zeros((0, 4))
        self._draws = _Draws(self.rng)
        self._cmd_delay = fx.get("serial_latency", "command")
        self._tlm_delay = fx.get("serial_latency", "telemetry")
        self._noise = fx.get("encoder", "noise_std")
        self._quantise = fx.on("encoder")
        self._p_glitch = fx.get("encoder_glitches", "probability")
        self._p_drop = fx.get("dropouts", "probability")
        self._events = PlantEvents(fx, self.wheel.pv)
        self._commands: deque[tuple[float, Command]] = deque()
        self._faults = 0
        #: START commands the wheel refused (pad not in contact, or an actuator on) [count].
        self.starts_refused = 0
        self._samples: deque[TelemetrySample | None] = deque()
        #: The encoder's raw reading (0..1023, noise and glitches included) at the last tick,
        #: or at the initial angle before the first; what a device reads (:mod:`.firmware`).
        self.encoder_raw = math.floor(angle_reading(xi1, self.wheel.pv) / COUNT) % ENCODER_COUNTS

    @property
    def t(self) -> float:
        """Simulated time [s]."""
        return self.wheel.t

    def open_loop(self, phi_a: float, phi_d: float, rule: str = "after_active",
                  priming: int = 0, priming_phi_a: float = math.radians(3.0)) -> None:
        """Let the (virtual) firmware run its sequential schedule (see ``HybridWheel.open_loop``)."""
        self.wheel.open_loop(phi_a, phi_d, rule, priming, priming_phi_a)  # type: ignore[arg-type]

    def step(self, command: Command | None = None, dt: float = TICK) -> TelemetrySample | None:
        """Send ``command`` now, advance by dt [s] (one tick), return what arrives now."""
        commands = self._commands
        if command is not None or commands:
            now = self.wheel.s[L.S_T]
            if command is not None:
                commands.append((now + self._cmd_delay, command))
            while commands and commands[0][0] <= now + 1e-12:
                self._apply(commands.popleft()[1])
        self._events.apply(self.wheel.s[L.S_T], self.wheel.pv)
        self.last_events = self.wheel.advance(dt)
        if self.wheel.s[L.S_Q] and self.wheel.s[L.S_ON_TIME] >= MAX_ON_TIME - 1e-9:
            self.wheel.cut_hv()                  # protocol rule 5, as the firmware does
            self._faults |= P.F_MAX_ON
        sample = self._sample()
        if self._tlm_delay == 0.0:
            return sample
        # deliver the sample taken `telemetry latency` ago (rounded up to whole ticks)
        self._samples.append(sample)
        if len(self._samples) <= math.ceil(self._tlm_delay / dt - 1e-9):
            return None
        return self._samples.popleft()

    def _apply(self, c: Command) -> None:
        """A command reaches the wheel: latched as the firmware does (protocol rule 3), or a
        START (``c.now``) switches the pad in contact on at once; a refused START sets the
        rejected-command fault bit in the next sample, as the device's REJECT would."""
        if not c.now:
            self.wheel.command(c.n_a, c.phi_a, c.phi_d, c.sequence)
        elif self.wheel.start_now(c.n_a, c.phi_a, c.phi_d, c.sequence):
            self.starts_refused += 1
            self._faults |= P.F_REJECTED

    def _sample(self) -> TelemetrySample | None:
        """What the firmware measures at this tick (None if the sample gets lost)."""
        s = self.wheel.s
        self.sequence += 1
        z, u_glitch, u_drop = self._draws.next()
        measured = angle_reading(s[L.S_XI1], self.wheel.pv) + z * self._noise
        counts = math.floor(measured / COUNT)
        angle = counts * COUNT if self._quantise else measured
        raw = counts % ENCODER_COUNTS
        if u_glitch < self._p_glitch:
            glitch_count = int(u_glitch / self._p_glitch * ENCODER_COUNTS)  # uniform 0..1023
            angle += (glitch_count - raw) * COUNT
            raw = glitch_count
        self.encoder_raw = int(raw)
        if u_drop < self._p_drop:
            return None
        q = int(s[L.S_Q])
        eta_u = int(s[L.S_ETA])
        t = s[L.S_T]
        faults, self._faults = self._faults, 0
        return TelemetrySample(
            float(t), int(round(t * 1e6)), self.sequence, int(raw), float(angle), q, eta_u % 16,
            eta_u, (1 << (eta_u % 16)) if q else 0, HV_SUPPLY_V,
            ACTUATOR_CURRENT_A if q else 0.0, max(int(s[L.S_CMD_SEQ]), 0), faults)
