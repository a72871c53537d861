"""Disturbance estimators for the MPC's speed offset d [rad/s], as one small pure core.

``mode="paper"``: eqs. (57)-(58), faithful.

    d(k+1) = d(k) + K e(k),   e(k) = xi2_meas(k) - xi2_prdt(k)

``k`` counts cycles: xi2_meas is the measured mean speed over a cycle and xi2_prdt the mean the
MPC predicted for it (model + d).  It runs only near the reference, |xi2_prdt - xi2_r| <=
``gate`` (the paper: ~0.1 m/s = 0.64 rad/s), so the transient does not wind it up.  With a
constant model error e, d(k) = e (1 - (1 - K)^k) for 0 < K < 2
(``test_disturbance.py::test_constant_offset_closes_geometrically``,
``test_gated_outside_the_band_near_the_reference``).

``mode="tracking"`` (ours, the default): e(k) = xi2_meas(k) - xi2_r, gated on the measured
speed.  (58) only removes the error between model and wheel; the controller's own bias (a
cost that prefers a slightly slow cycle, a coarse search grid) stays.  Integrating the
tracking error removes both.  If the MPC meets its prediction, xi2_meas = xi2_r - d + e, and
the same geometric law d(k) = e (1 - (1 - K)^k) follows
(``test_tracking_mode_closes_a_constant_offset_at_the_same_rate``,
``test_tracking_mode_is_gated_on_the_measured_speed``).

How d enters the prediction (the paper leaves it open): as an additive speed offset.  The
MPC predicts xi2_prdt = xi2_model + d and minimises its cost on it.  The observer's
acceleration disturbance (observer.py) is the other, separate channel.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

#: The default gain K of the tracking estimator [1 per cycle].  The observer's pivot
#: harmonic carries the platform's slow pull, so d only has to hold what remains; a faster
#: d chases cycle-to-cycle scatter.  ``benchmarks/bench_speed_loop.py`` compares K over
#: plant seeds.
TRACKING_GAIN = 0.07
#: The band around the reference the estimator runs in [rad/s] (the paper's ~0.1 m/s).
ESTIMATOR_GATE = 0.64


@dataclass
class IntegralEstimator:
    """(57)-(58) with gating.  gain K [1 per update], gate [rad/s]; 0 < K < 2, else refused
    (``test_disturbance.py::test_unstable_gains_are_refused``)."""

    gain: float = TRACKING_GAIN
    gate: float = ESTIMATOR_GATE
    mode: str = "tracking"   # "tracking" (ours) or "paper" ((57)-(58))
    d: float = 0.0
    updates: int = 0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.gain) and 0.0 < self.gain < 2.0):
            raise ValueError(f"gain K = {self.gain!r}: expected 0 < K < 2 (stable update)")
        if self.mode not in ("paper", "tracking"):
            raise ValueError(f"mode = {self.mode!r}: expected 'paper' or 'tracking'")
        if not (math.isfinite(self.gate) and self.gate > 0.0):
            raise ValueError(f"gate = {self.gate!r} rad/s: expected a positive speed band")

    def step(self, measured: float, model_prediction: float, reference: float) -> float:
        """One update per cycle from the measured and the model's mean speed [rad/s]; returns d.

        The prediction used in (58) is the model's plus the current d (the offset choice).
        """
        predicted = model_prediction + self.d
        if self.mode == "tracking":
            if abs(measured - reference) <= self.gate:
                self.d += self.gain * (measured - reference)
                self.updates += 1
            return self.d
        if abs(predicted - reference) <= self.gate:
            self.d += self.gain * (measured - predicted)
            self.updates += 1
        return self.d
