"""The library of candidate effects: physical extensions of the hybrid model.

Each candidate is a parameterised extension with a stable identifier (used in report.json
and documented in docs/identification.md, "Candidate effects").  ``apply`` writes its parameters into the model's parameter
vector, so the fit, the free-run simulation, the plant and the MPC's predictor all evaluate
the very same physics (:mod:`hasel_wheel_sim.model`).  Parameters are chosen so that "no
effect" is a parameter value (0, or equal gains) and the fit is smooth around it.

==================  =======================================================================
identifier          physics (axle torque, factor on the actuator force, or the angle reading)
==================  =======================================================================
viscous_drag        -c xi2                                   c [N*m*s/rad]
com_offset          A cos(xi1) + B sin(xi1)                  A, B [N*m]  (once per turn)
platform_periodic   P sin((r/L) xi1) + Q cos((r/L) xi1)      P, Q [N*m]  (once per pivot lap)
rise_lag            force x (1 - exp(-t_on / tau))           tau [s]
charge_retention    force x exp(-rate Q_i), Q_i' = q_i - Q_i/T   rate [1/s], T [s]
gain_spread         actuator i's force x exp(d_i), sum d_i = 0   d_1..d_15 [1]
angle_offset        pads sit delta further along than the encoder's zero   delta [rad]
angle_eccentricity  the sensor reads xi1 + E cos(xi1) + F sin(xi1)        E, F [rad]
==================  =======================================================================

``angle_eccentricity`` is the one effect on the measurement, not on the motion: an encoder
disc or magnet off the axle.  The fit compares the model's *readings* with the recorded
angles, and the free run switches where the reading reaches the switching angles, as the
firmware does.  Its speed error grows with speed (E, F times xi2), where a torque once per
turn (``com_offset``) gives a speed ripple that shrinks with speed; trials at several speeds
tell the two apart.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from collections.abc import Sequence
from typing import Callable

import numpy as np

from hasel_wheel_sim import layout as L
from hasel_wheel_sim.model import N_ACTUATORS, SECTOR


@dataclass(frozen=True)
class ParamSpec:
    """One fitted parameter: name, unit, start value, bounds and a typical magnitude."""

    name: str
    unit: str
    start: float
    lower: float
    upper: float
    scale: float


@dataclass(frozen=True)
class Candidate:
    """A parameterised effect; ``apply(x, pv, extra)`` writes values x (k,) into pv."""

    id: str
    title: str
    params: tuple[ParamSpec, ...]
    apply: Callable[[np.ndarray, np.ndarray, dict], None]
    describe: Callable[[np.ndarray], dict]
    axis: str   # the residual axis on which its signature shows
    #: x (k,) -> the fields of hasel_wheel_sim.model.Extensions it sets (the saved model);
    #: None when the plant and the MPC have no such field
    extension: Callable[[np.ndarray], dict] | None = None
    #: x (k,) -> None when the fitted values look like the physics the candidate names, else
    #: a sentence saying why not (the candidate is then refused, and the structure it took
    #: up is left for the residual analysis to describe)
    implausible: Callable[[np.ndarray], str | None] | None = None
    #: further values of its own parameters to screen it at, besides their start values
    #: (:mod:`.screen`): for an effect far from linear in its parameters, whose one
    #: Gauss-Newton step from a single start under-predicts what a refit finds
    screen_at: tuple[dict[str, float], ...] = ()
    #: a grid of its own parameter values at which the error is evaluated, not predicted
    #: (:mod:`.screen`): for an effect whose Gauss-Newton step is good only close to the
    #: optimum, the grid finds where that is
    scan: tuple[dict[str, float], ...] = ()
    #: its parameters refitted trial by trial to check that the trials agree on it
    #: (:mod:`.consistency`); None for all.  A time constant far longer than a trial (charge
    #: retention's recovery) is held at the fit on all trials instead
    per_trial: tuple[str, ...] | None = None

    @property
    def size(self) -> int:
        return len(self.params)


def _viscous(x, pv, extra):
    pv[L.P_VISCOUS] = x[0]


def _com(x, pv, extra):
    pv[L.P_BIAS_COS] += x[0]
    pv[L.P_BIAS_SIN] += x[1]


def _com_describe(x):
    torque = math.hypot(x[0], x[1])
    # A cos + B sin = -T sin(xi1 + phase)  (the plant's com_offset convention)
    return {"torque_N_m": torque, "phase_rad": math.atan2(-x[0], -x[1])}


def _platform(x, pv, extra):
    pv[L.P_PLATFORM_TORQUE] = math.hypot(x[0], x[1])
    pv[L.P_PLATFORM_PHASE] = math.atan2(x[1], x[0])


def _platform_describe(x):
    return {"torque_N_m": math.hypot(x[0], x[1]), "phase_rad": math.atan2(x[1], x[0])}


def _rise(x, pv, extra):
    pv[L.P_RISE_TIME] = x[0]


def _retention(x, pv, extra):
    pv[L.P_RET_RATE] = x[0]
    pv[L.P_RET_RECOVERY] = x[1]


def _spread(x, pv, extra):
    d = np.concatenate(([-np.sum(x)], x))
    pv[L.P_GAINS:L.P_GAINS + N_ACTUATORS] *= np.exp(d)


def _spread_describe(x):
    g = np.array(_spread_gains(x))
    return {"gains": [float(v) for v in g], "std": float(np.std(g))}


def _spread_gains(x) -> tuple[float, ...]:
    return tuple(float(v) for v in np.exp(np.concatenate(([-np.sum(x)], x))))


def spread_values(gains: Sequence[float] | np.ndarray) -> tuple[float, dict[str, float]]:
    """A wheel's actuator gains (16,) [1] in ``gain_spread``'s terms: (their geometric mean
    [1], which scales the force law's peak, and the candidate's log-gains {"d1".."d15"}
    [1] of the gains over that mean).  The inverse of the candidate's gains."""
    g = np.asarray(gains, dtype=float)
    if g.shape != (N_ACTUATORS,) or not np.all((g > 0.0) & np.isfinite(g)):
        raise ValueError(f"expected {N_ACTUATORS} positive gains, got {gains!r}")
    logs = np.log(g)
    d = logs - np.mean(logs)
    return float(np.exp(np.mean(logs))), {f"d{i}": float(d[i]) for i in range(1, N_ACTUATORS)}


#: Bounds [1] of each log-gain d_i: from a pad at e^-5 = 0.7 % of the geometric mean (one
#: that has broken down and barely pushes) to one at e^3 = 20 times it.  The plant draws
#: gains down to 0.05 (``gain_spread`` std up to 0.5) and takes explicit gains in (0, 10];
#: a gain below 0.7 % of the mean (0.001 among gains of 1) would still stop at the bound.
#: Held by test_gains_far_from_the_mean_are_measured_not_stopped_at_a_bound
#: (test_ident_effects).
SPREAD_LOG_LOWER = -5.0
SPREAD_LOG_UPPER = 3.0

#: Below this p-value a gain pattern is too smooth around the wheel for fabrication spread.
SPREAD_PATTERN_P = 1e-3


def spread_pattern(x) -> tuple[int, float, float]:
    """(k, share, p) of the fitted log-gains: the harmonic k (1..8 per wheel turn) that holds
    the largest share [1] of their variance around the wheel, and the chance p of so large a
    share if the 16 gains were independent, as fabrication spread makes them.

    Under that hypothesis each harmonic k < 8 carries two of the 15 degrees of freedom, so
    its share is Beta(1, 13/2) distributed and exceeds s with probability (1 - s)^(13/2);
    the eighth carries one, Beta(1/2, 7).  p is the union bound over the eight (an upper
    bound, tight where it matters).  A torque fixed to the wheel angle (an off-centre mass,
    anything periodic in the angle) that gains have to imitate puts most of their variance
    into one low harmonic: an off-centre mass, into the first."""
    from scipy import stats
    d = np.concatenate(([-np.sum(x)], np.asarray(x, dtype=float)))
    power = np.abs(np.fft.rfft(d - d.mean())[1:]) ** 2          # k = 1..8
    power[:-1] *= 2.0                                           # k and 16 - k
    total = float(power.sum())
    if total <= 0.0:
        return 1, 0.0, 1.0
    k = int(np.argmax(power))
    share = float(power[k] / total)
    p = 7 * stats.beta.sf(share, 1.0, 6.5) + stats.beta.sf(share, 0.5, 7.0)
    return k + 1, share, float(min(p, 1.0))


def _spread_implausible(x) -> str | None:
    k, share, p = spread_pattern(x)
    if p >= SPREAD_PATTERN_P:
        return None
    return (f"the fitted gains follow a pattern of {k} per wheel turn ({100 * share:.0f} % of "
            f"their variance; p = {p:.1e} for gains that vary independently, as fabrication "
            f"spread makes them): a torque periodic in the wheel angle, not a spread")


def _com_extension(x):
    d = _com_describe(x)
    return {"com_torque": d["torque_N_m"], "com_phase": d["phase_rad"]}


def _platform_extension(x):
    d = _platform_describe(x)
    return {"platform_torque": d["torque_N_m"], "platform_phase": d["phase_rad"]}


def _eccentric(x, pv, extra):
    pv[L.P_READ_COS] += x[0]
    pv[L.P_READ_SIN] += x[1]


def _eccentric_describe(x):
    # E cos + F sin = e sin(xi1 + phase)  (the plant's angle_eccentricity convention)
    return {"amplitude_rad": math.hypot(x[0], x[1]), "phase_rad": math.atan2(x[0], x[1])}


def _eccentric_extension(x):
    d = _eccentric_describe(x)
    return {"angle_eccentricity": d["amplitude_rad"], "angle_eccentricity_phase": d["phase_rad"]}


def _offset(x, pv, extra):
    extra["eta_offset"] = extra.get("eta_offset", 0.0) + x[0] / SECTOR


LIBRARY: tuple[Candidate, ...] = (
    Candidate("viscous_drag", "viscous drag at the axle",
              (ParamSpec("c", "N*m*s/rad", 1e-4, 0.0, 0.1, 1e-3),), _viscous,
              lambda x: {"coefficient_N_m_s_per_rad": float(x[0])}, "speed",
              lambda x: {"viscous": float(x[0])}),
    Candidate("com_offset", "centre of mass off the axle (gravity torque once per turn)",
              (ParamSpec("A", "N*m", 0.0, -0.5, 0.5, 1e-3),
               ParamSpec("B", "N*m", 0.0, -0.5, 0.5, 1e-3)), _com, _com_describe, "wheel_angle",
              _com_extension),
    Candidate("platform_periodic", "torque periodic in the pivot angle (uneven platform)",
              (ParamSpec("P", "N*m", 0.0, -0.5, 0.5, 1e-3),
               ParamSpec("Q", "N*m", 0.0, -0.5, 0.5, 1e-3)), _platform, _platform_describe,
              "pivot_angle", _platform_extension),
    Candidate("rise_lag", "actuator force builds up after switch-on",
              (ParamSpec("tau", "s", 0.005, 1e-5, 0.5, 0.01),), _rise,
              lambda x: {"time_constant_s": float(x[0])}, "on_time",
              lambda x: {"rise_time": float(x[0])},
              screen_at=({"tau": 0.02}, {"tau": 0.06}),
              # 10 ms to 0.32 s in steps of 2: from the nearest point (within a factor of
              # sqrt(2)) the scan's short fit reaches the optimum
              scan=tuple({"tau": 0.01 * 2.0 ** k} for k in range(6))),
    Candidate("charge_retention", "actuators weaken with accumulated HV time",
              (ParamSpec("rate", "1/s", 1e-3, 0.0, 1.0, 1e-2),
               ParamSpec("recovery", "s", 60.0, 1.0, 1e5, 60.0)), _retention,
              lambda x: {"rate_per_s": float(x[0]), "recovery_s": float(x[1])}, "hv_time",
              lambda x: {"retention_rate": float(x[0]), "retention_recovery": float(x[1])},
              per_trial=("rate",)),
    Candidate("gain_spread", "fabrication spread of the 16 actuators' force",
              tuple(ParamSpec(f"d{i}", "1", 0.0, SPREAD_LOG_LOWER, SPREAD_LOG_UPPER, 0.05)
                    for i in range(1, N_ACTUATORS)),
              _spread, _spread_describe, "actuator", lambda x: {"gains": _spread_gains(x)},
              _spread_implausible),
    Candidate("angle_offset", "pads offset from the encoder's zero",
              (ParamSpec("delta", "rad", 0.0, -SECTOR / 2, SECTOR / 2, 0.01),), _offset,
              lambda x: {"offset_rad": float(x[0])}, "contact_angle"),
    # bounds of 0.14 rad keep the amplitude within the model's 0.2 rad
    Candidate("angle_eccentricity", "angle sensor off the axle (reading error once per turn)",
              (ParamSpec("E", "rad", 0.0, -0.14, 0.14, 0.005),
               ParamSpec("F", "rad", 0.0, -0.14, 0.14, 0.005)), _eccentric, _eccentric_describe,
              "wheel_angle", _eccentric_extension),
)

BY_ID = {c.id: c for c in LIBRARY}


def library(ids: list[str] | None = None, exclude: list[str] | None = None) -> tuple[Candidate, ...]:
    """Candidates by identifier (all by default), minus ``exclude``; unknown ids raise."""
    for i in (ids or []) + (exclude or []):
        if i not in BY_ID:
            raise ValueError(f"unknown candidate effect {i!r}; known: {sorted(BY_ID)}")
    chosen = [BY_ID[i] for i in ids] if ids else list(LIBRARY)
    return tuple(c for c in chosen if c.id not in (exclude or []))
