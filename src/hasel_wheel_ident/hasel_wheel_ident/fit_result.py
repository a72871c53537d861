"""The outcome of one multiple-shooting fit (:class:`FitResult`), made by
:func:`~.least_squares.result`."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hasel_wheel_sim.params import WheelParams


@dataclass
class FitResult:
    """Outcome of one fit; ``values`` and ``ci95`` are keyed by parameter name."""

    names: list[str]
    units: list[str]
    theta: np.ndarray                 # shared parameters (g,)
    z: np.ndarray                     # everything fitted, shared then window starts
    cov: np.ndarray                   # (g, g) covariance of theta (nuisance marginalised)
    rmse: float                       # angle residual RMS [rad] over all used samples
    per_trial_rmse: dict[str, float]
    nfev: int
    converged: bool
    message: str
    inflation: float                  # variance inflation for residual autocorrelation
    candidates: tuple[str, ...] = ()
    params: WheelParams | None = None
    values: dict[str, float] = field(default_factory=dict)
    ci95: dict[str, tuple[float, float]] = field(default_factory=dict)

    @property
    def x0(self) -> np.ndarray:
        """(w, 2) the fitted start of each window: xi1 [rad], xi2 [rad/s]."""
        return self.z[self.theta.size:].reshape(-1, 2)
