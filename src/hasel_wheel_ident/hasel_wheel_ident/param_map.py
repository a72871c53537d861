"""The shared parameters of a multiple-shooting fit: each one's spec, which are fixed, and
the map from the free ones (theta, in the order of :attr:`ParameterMap.free`) to all of
them.  Tested in ``test_ident_fit.py``."""
from __future__ import annotations

import numpy as np

from hasel_wheel_ident.candidates import ParamSpec


class ParameterMap:
    """``specs`` every shared parameter (the nominal model's ``n_nominal`` first), ``fixed``
    the values pinned by name; ``free`` the indices into ``specs`` of the others."""

    def __init__(self, specs: tuple[ParamSpec, ...], n_nominal: int,
                 fixed: dict[str, float] | None) -> None:
        self.specs = specs
        self.n_nominal = n_nominal
        self.fixed = dict(fixed or {})
        self.free = [i for i, p in enumerate(self.specs) if p.name not in self.fixed]

    @property
    def names(self) -> list[str]:
        """The free parameters' names."""
        return [self.specs[i].name for i in self.free]

    def full_theta(self, theta_free: np.ndarray) -> np.ndarray:
        """All shared parameters: the fixed values, the free ones ``theta_free``."""
        full = np.array([self.fixed.get(p.name, p.start) for p in self.specs], dtype=float)
        full[self.free] = theta_free
        return full

    def at_bounds(self, values: dict[str, float], rel: float = 1e-6) -> list[str]:
        """The free nominal parameters whose ``values`` ended on a bound of their range
        (within ``rel`` of the range's width)."""
        out = []
        for i in self.free:
            p = self.specs[i]
            if i < self.n_nominal and p.name in values:
                v, tol = values[p.name], rel * (p.upper - p.lower)
                if v <= p.lower + tol or v >= p.upper - tol:
                    out.append(p.name)
        return out

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) of the free parameters, each in its unit."""
        return (np.array([self.specs[i].lower for i in self.free]),
                np.array([self.specs[i].upper for i in self.free]))

    def scale(self) -> np.ndarray:
        """The free parameters' typical magnitudes."""
        return np.array([self.specs[i].scale for i in self.free])

    def start(self, start: dict[str, float]) -> np.ndarray:
        """The free parameters' start: ``start`` by name, else each spec's, moved inside the
        bounds by 1e-9 of the range."""
        th = np.array([start.get(self.specs[i].name, self.specs[i].start) for i in self.free])
        lo, hi = self.bounds()
        return np.clip(th, lo + 1e-9 * (hi - lo), hi - 1e-9 * (hi - lo))
