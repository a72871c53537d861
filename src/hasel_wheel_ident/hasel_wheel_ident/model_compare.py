"""Closing the identification loop: the same plant under controllers with different models.

:func:`compare_controllers` runs :func:`~hasel_wheel_mpc.closed_loop.run_closed_loop` once per
controller model (e.g. the paper's nominal model and an identified, augmented one from
:func:`hasel_wheel_sim.model_file.load_model`) against one plant, with the same seed, and
returns the tracking error of each run.  The plant is identical in every run: its random
draws depend only on its seed and the number of ticks (see :mod:`hasel_wheel_sim.plant`).
The MPC's deadline is judged on a constant clock by default, so the result does not depend
on how fast the machine is and two calls give identical numbers.

Errors are measured on the plant's *true* speed xi2 [rad/s] against the reference, on every
host sample except the first ``settle`` seconds after each reference step (and after the start).
"""
from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np

from hasel_wheel_sim.model import Extensions
from hasel_wheel_sim.params import WheelParams
from hasel_wheel_sim.plant import PlantConfig

from hasel_wheel_mpc.closed_loop import FIG11_DURATION, FIG11_PROFILE, LoopLog, run_closed_loop, segment_metrics

#: Default settling time excluded after each reference step [s].
SETTLE = 2.0


def _frozen_clock() -> float:
    return 0.0


def tracking_metrics(log: LoopLog, profile=FIG11_PROFILE, duration: float = FIG11_DURATION,
                     settle: float = SETTLE, window: float = 10.0) -> dict[str, Any]:
    """Tracking error of one closed-loop run (true speed against the reference).

    ``profile`` ((start [s], reference [rad/s]), ...) and ``duration`` [s] as given to the run.
    Samples within ``settle`` [s] of a segment's start are left out of the first three entries:

    * ``rmse`` [rad/s]: sqrt(mean((xi2 - ref)^2)) over the kept samples of the whole run;
    * ``nrmse`` [1]: sqrt(mean(((xi2 - ref) / ref)^2)), so every segment counts relative to
      its own reference;
    * ``segment_mean_error`` [rad/s], one per segment: mean(xi2 - ref) over its kept samples
      (signed; NaN if the segment is not longer than ``settle``);
    * ``segment_steady_error`` [%], one per segment: |mean(xi2) - ref| / ref over the segment's
      last ``window`` [s] (:func:`~hasel_wheel_mpc.closed_loop.segment_metrics`);
    * ``segments``: the :class:`~hasel_wheel_mpc.closed_loop.SegmentMetrics` themselves;
    * ``decisions``, ``braking``, ``deadline_misses`` [count] of the MPC.
    """
    a = log.arrays()
    t, v, ref = a["t"], a["true_speed"], a["reference"]
    starts = np.array([p[0] for p in profile], dtype=float)
    seg = np.searchsorted(starts, t, side="right") - 1       # segment index of each sample (n,)
    keep = (seg >= 0) & (t - starts[np.maximum(seg, 0)] >= settle)
    err = v[keep] - ref[keep]
    per_segment = []
    for k in range(len(profile)):
        m = keep & (seg == k)
        per_segment.append(float(np.mean(v[m] - ref[m])) if m.any() else math.nan)
    decisions = [d for _, d in log.decisions]
    seg_metrics = segment_metrics(log, profile, duration, window)
    return {
        "rmse": float(np.sqrt(np.mean(err ** 2))) if err.size else math.nan,
        "nrmse": float(np.sqrt(np.mean((err / ref[keep]) ** 2))) if err.size else math.nan,
        "segment_mean_error": per_segment,
        "segment_steady_error": [m.steady_error for m in seg_metrics],
        "segments": seg_metrics,
        "decisions": len(decisions),
        "braking": sum(d.braking for d in decisions),
        "deadline_misses": sum(d.deadline_missed for d in decisions),
    }


def compare_controllers(plant_params: WheelParams | None, plant_config: PlantConfig,
                        models: Mapping[str, tuple[WheelParams, Extensions | None]],
                        profile=FIG11_PROFILE, duration: float = FIG11_DURATION,
                        seed: int | None = None, settle: float = SETTLE,
                        wall_clock: bool = False, **loop_kwargs: Any) -> dict[str, dict[str, Any]]:
    """Run one plant under one controller per model; return ``{name: tracking_metrics(...)}``.

    ``plant_params`` (None = the paper's) and ``plant_config`` (its effects are the plant's
    extensions) define the plant; ``seed`` [int] replaces ``plant_config.seed`` if given.
    ``models`` maps a name to the (parameters, extensions) the observer and the MPC use.
    ``profile`` ((start [s], reference [rad/s]), ...), ``duration`` [s] and ``settle`` [s]: see
    :func:`tracking_metrics`.  ``wall_clock`` False judges the MPC's deadline on a constant
    clock (compute time counted as 0, so no wall-clock-dependent fallback), which makes the
    result deterministic; True uses wall time as the demo does.  ``loop_kwargs`` go to
    :func:`~hasel_wheel_mpc.closed_loop.run_closed_loop` (e.g. ``observer_config``,
    ``estimator_gain``, ``mpc_config``), the same for every model.
    """
    if seed is not None:
        plant_config = PlantConfig(seed, plant_config.switching, plant_config.effects)
    clock = None if wall_clock else _frozen_clock
    out: dict[str, dict[str, Any]] = {}
    for name, (params, ext) in models.items():
        log = run_closed_loop(profile, duration, plant_config=plant_config, params=plant_params,
                              controller_params=params, controller_extensions=ext, clock=clock,
                              **loop_kwargs)
        out[name] = tracking_metrics(log, profile, duration, settle)
    return out
