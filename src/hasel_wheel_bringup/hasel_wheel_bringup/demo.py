"""The main job: the closed speed loop on a Fig. 11-like profile, the plant with effects on.

Runs the loop (observer -> estimator -> MPC -> plant, lockstep at 300 Hz) once as configured
and records it to a bag; then, for comparison, without the estimator, with the paper's
estimator (57)-(58), and with the observer replaced by a finite difference.  Prints the
metrics per reference next to the paper's and writes PNG plots like Fig. 11(a-c).
"""
from __future__ import annotations

import math
import textwrap
from pathlib import Path
from typing import NamedTuple

import numpy as np

from hasel_wheel_sim.plant import run_configs

from hasel_wheel_sim import paper
from hasel_wheel_mpc.closed_loop import (FIG11_DURATION, FIG11_PROFILE, LoopLog, WheelLoop, controller_config,
                          run_controller, run_wheels, segment_metrics, start_time)

#: (label, keyword arguments of run_closed_loop) of the comparison runs.
VARIANTS = (
    ("with estimator (tracking)", {}),
    ("without estimator", {"estimator_gain": None}),
    ("paper estimator (57)-(58)", {"estimator_gain": 0.3, "estimator_mode": "paper"}),
    ("finite-difference speed", {"speed_source": "finite_difference"}),
)


class VariantResult(NamedTuple):
    label: str
    log: LoopLog
    metrics: list


def scaled_profile(scale: float):
    """FIG11_PROFILE with every hold stretched by ``scale`` [1]; returns (profile, duration)."""
    return tuple((t * scale, r) for t, r in FIG11_PROFILE), FIG11_DURATION * scale


def run_variants(plant_config, scale: float = 1.0, variants=VARIANTS, recorder=None,
                 wheels: int = 1, overrides: dict | None = None, same_wheel: bool = False,
                 w0: float = 0.0, progress: bool = False):
    """Run each variant on the scaled profile, the wheel starting at ``w0`` [rad/s] (0: from
    rest); the first is recorded (if ``recorder``).

    With ``wheels`` > 1 the first variant runs that many wheels in lockstep, wheel i on the
    plant with seed ``plant_config.seed + i``, each recorded under ``/wheel<i>``; the
    results (one per variant) are wheel 0's, and the other wheels' results follow them as
    ``"<label>, /wheel<i>"``.  With ``same_wheel`` they are runs of one wheel instead: its
    actuator gains drawn once, from ``plant_config.seed`` (see
    :func:`~hasel_wheel_sim.plant.run_configs`); the comparison runs are on wheel 0's plant
    either way.  ``overrides`` ({'mpc.brake_phi_a': -0.384, ...}, see
    ``ControllerConfig.with_overrides``) change every variant's controller.  ``progress``:
    a bar of each run's simulated seconds on stderr (on a terminal).
    """
    profile, duration = scaled_profile(scale)
    plants = run_configs(plant_config, wheels, same_wheel=same_wheel)
    out, extra = [], []
    for i, (label, kw) in enumerate(variants):
        cfg = controller_config(**kw)
        if overrides:
            cfg = cfg.with_overrides(overrides)
        bar = f"demo {i + 1}/{len(variants)}: {label}" if progress else None
        if i == 0:
            loops = [WheelLoop(cfg, profile, pc, w0=w0, recorder=recorder, ns=f"/wheel{k}")
                     for k, pc in enumerate(plants)]
            logs = run_wheels(loops, duration, bar)
            log = logs[0]
            extra = [VariantResult(f"{label}, /wheel{k}", lg, segment_metrics(lg, profile, duration))
                     for k, lg in enumerate(logs[1:], start=1)]
        else:
            log = run_controller(cfg, profile, duration, plants[0], w0=w0, progress=bar)
        out.append(VariantResult(label, log, segment_metrics(log, profile, duration)))
    return out + extra


def _f(v, spec):
    return "   -  " if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, spec)


def metrics_table(results: list[VariantResult], effects: list[str] | None = None) -> str:
    """Text table: per reference, each variant's steady error, NRMSE, rise/fall, and the paper.
    ``effects``: the names of the plant's enabled effects, for the heading."""
    on = ", ".join(effects) if effects else "none"
    lines = textwrap.wrap(f"Closed loop on the plant with these effects on: {on}.", 90) + [
        "Steady window = last 10 s of each hold; rise/fall = from the step until the new "
        "reference", "is first reached.", ""]
    for res in results:
        lines.append(f"{res.label}:")
        first = res.metrics[0].reference
        if res.log.true_speed[0] < first:
            lines.append(f"  start: {first:.1f} rad/s first reached after "
                         f"{_f(start_time(res.log, first), '.2f')} s")
        lines.append("  ref [rad/s] | steady err [%] | NRMSE | rise/fall [s] | paper: err [%], NRMSE"
                     " (with / without estimator)")
        prev = None
        for m in res.metrics:
            pw = paper.FIG11_WITH_ESTIMATOR.get(m.reference)
            po = paper.FIG11_WITHOUT_ESTIMATOR.get(m.reference)
            if prev is not None and m.reference < prev:
                p = f"fall time ~{paper.FIG11_FALL_TIME} s (Fig. 11(c))"
            elif pw and (prev is None or m.reference > prev):
                p = f"{_f(pw[0], '5.2f')}, {pw[1]:.3f} / {_f(po[0], '5.2f')}, {po[1]:.3f}"
            else:
                p = ""
            prev = m.reference
            lines.append(f"     {m.reference:4.1f}     |     {m.steady_error:5.2f}      | "
                         f"{m.nrmse:.3f} |    {_f(m.transition, '5.2f')}      | {p}")
        dec = [d for _, d in res.log.decisions]
        lat = np.array([d.compute_time for d in dec if not d.braking])
        lines.append(f"  decisions {len(dec)}, braking {sum(d.braking for d in dec)}, deadline misses "
                     f"{sum(d.deadline_missed for d in dec)}, latency p50 "
                     f"{np.percentile(lat, 50) * 1e3:.2f} ms p99 {np.percentile(lat, 99) * 1e3:.2f} ms, "
                     f"candidates {int(np.median([d.candidates for d in dec if not d.braking]))}")
        lines.append("")
    return "\n".join(lines)


def plot(results: list[VariantResult], out: Path) -> list[Path]:
    """PNG plots like Fig. 11: (a) without, (b) with the estimator, (c) the 2.6 -> 2.0 step."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    by = {r.label: r for r in results}
    paths = []
    panels = [("fig11a_without_estimator.png", "without estimator", None),
              ("fig11b_with_estimator.png", "with estimator (tracking)", None),
              ("fig11c_braking_step.png", "with estimator (tracking)", (0.85, 1.0))]
    for name, label, frac in panels:
        if label not in by:
            continue
        a = by[label].log.arrays()
        t = a["t"]
        m = np.ones_like(t, dtype=bool) if frac is None else (
            (t >= frac[0] * t[-1]) & (t <= frac[1] * t[-1]))
        fig, ax = plt.subplots(figsize=(9, 3.6))
        ax.plot(t[m], a["true_speed"][m], lw=0.6, label="true speed (plant)")
        ax.plot(t[m], a["est_speed"][m], lw=0.4, alpha=0.6, label="speed seen by the MPC")
        ax.plot(t[m], a["reference"][m], "k--", lw=1.0, label="reference")
        ax.set_xlabel("time [s]")
        ax.set_ylabel("wheel speed [rad/s]")
        ax.set_title(f"closed loop, {label}")
        ax.legend(loc="lower right", fontsize=8)
        fig.tight_layout()
        path = out / name
        fig.savefig(path, dpi=110)
        plt.close(fig)
        paths.append(path)
    return paths
