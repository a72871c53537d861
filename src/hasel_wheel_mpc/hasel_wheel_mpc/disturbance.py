"""The paper's disturbance estimator, eqs. (57)-(58), as a small pure core.

    d(k+1) = d(k) + K e(k),   e(k) = xi2_meas(k) - xi2_prdt(k)

It runs only near the reference: when |xi2_prdt - xi2_r| <= ``gate`` (the paper switches it
on within ~0.1 m/s = 0.64 rad/s), so the transient does not wind it up.

How d enters the prediction (the paper leaves it open): as an additive speed offset.  The
MPC predicts xi2_prdt = xi2_model + d and minimises (59) on it.  With that choice a constant
model error e is removed geometrically, d(k) = e (1 - (1 - K)^k), for 0 < K < 2.
"""
from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass
class IntegralEstimator:
    """(57)-(58) with gating.  gain K [1 per update], gate [rad/s]."""

    gain: float = 0.2
    gate: float = 0.64
    d: float = 0.0
    updates: int = 0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.gain) and 0.0 < self.gain < 2.0):
            raise ValueError(f"gain K = {self.gain!r}: expected 0 < K < 2 (stable update)")
        if not (math.isfinite(self.gate) and self.gate > 0.0):
            raise ValueError(f"gate = {self.gate!r} rad/s: expected a positive speed band")

    def step(self, measured: float, model_prediction: float, reference: float) -> float:
        """One update from the measured speed and the model's prediction [rad/s]; returns d.

        The prediction used in (58) is the model's plus the current d (the offset choice).
        """
        predicted = model_prediction + self.d
        if abs(predicted - reference) <= self.gate:
            self.d += self.gain * (measured - predicted)
            self.updates += 1
        return self.d
