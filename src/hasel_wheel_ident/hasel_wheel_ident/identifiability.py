"""Which combinations of the paper's parameters a data set determines.

The sensitivity of the multiple-shooting residual to each of the paper's parameters
(sigma1..sigma6, tau_f), in relative units (d sigma_i / |sigma_i|) and with the window starts
projected out, is a matrix J (n, 7).  Its singular values say how well each direction of
parameter space is determined; a singular value near zero is a direction the data cannot see
at all.  Two such directions are structural (see :mod:`.fit`): scaling sigma2, sigma3 and
sigma6 together, and moving sigma1 with sigma4 and sigma6 so that the force bump keeps its
shape.  Data that does not excite the bump's far side (phi_d at 22 deg only) weakens more.
"""
from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np

from hasel_wheel_sim.model import param_vector
from hasel_wheel_sim.params import WheelParams

from hasel_wheel_ident.fit import Problem

PAPER_NAMES = ("sigma1", "sigma2", "sigma3", "sigma4", "sigma5", "sigma6", "tau_f")


@dataclass
class Identifiability:
    names: tuple[str, ...]
    singular_values: np.ndarray     # (7,) descending, relative to the largest
    directions: np.ndarray          # (7, 7) rows: right singular vectors (relative units)
    jacobian_norm: float

    def undetermined(self, tol: float = 1e-5) -> list[dict[str, float]]:
        """Directions whose relative singular value is below tol, as {name: weight}."""
        out = []
        for s, v in zip(self.singular_values, self.directions):
            if s < tol:
                v = v / v[np.argmax(np.abs(v))]
                out.append({n: float(round(x, 4)) for n, x in zip(self.names, v) if abs(x) > 1e-3})
        return out

    def text(self, tol: float = 1e-5) -> list[str]:
        lines = []
        for s, v in zip(self.singular_values, self.directions):
            v = v / v[np.argmax(np.abs(v))]
            combo = " ".join(f"{x:+.3g} {n}" for n, x in zip(self.names, v) if abs(x) > 1e-3)
            verdict = "NOT determined" if s < tol else ("weakly determined" if s < 1e-2
                                                        else "determined")
            lines.append(f"{s:.2e}  {verdict}: {combo}  (relative changes)")
        return lines


def identifiability(problem: Problem, params: WheelParams, x0: np.ndarray | None = None,
                    step: float = 1e-5) -> Identifiability:
    """SVD of the projected sensitivity to the paper's parameters at ``params``.

    Structural: it asks what the model's output can show, so the output error is the plain
    difference from the readings, not the distance from the encoder's count intervals (which
    is flat inside them)."""
    problem = copy.copy(problem)
    problem.quantum = None
    x0 = problem.initial_starts() if x0 is None else x0
    pv = param_vector(params)
    gains = problem.gains(pv)
    x0, r, d1, d2 = problem.starts_for(pv, problem.eta, gains, x0)
    J = np.empty((problem.n, len(PAPER_NAMES)))
    for j, name in enumerate(PAPER_NAMES):
        v = getattr(params, name)
        h = step * abs(v)
        p2 = params.with_values(**{name: v + h})
        J[:, j] = (problem._shoot(param_vector(p2), problem.eta, gains, x0) - r) / step
    J = problem._project(J, d1, d2)
    u, s, vt = np.linalg.svd(J, full_matrices=False)
    return Identifiability(PAPER_NAMES, s / s[0], vt, float(s[0]))


def bump_null_direction(p: WheelParams) -> np.ndarray:
    """The analytic direction (relative units, order of PAPER_NAMES) that leaves the force law
    unchanged: d sigma1 = 1, d sigma4 = sigma5^2 / 2, d ln sigma6 = sigma4."""
    v = np.zeros(len(PAPER_NAMES))
    v[0] = 1.0 / abs(p.sigma1)
    v[3] = (p.sigma5 ** 2 / 2.0) / abs(p.sigma4)
    v[5] = p.sigma4
    return v / np.linalg.norm(v)


def ratio_null_direction() -> np.ndarray:
    """sigma2, sigma3, sigma6 scaled together (relative units)."""
    v = np.zeros(len(PAPER_NAMES))
    v[[1, 2, 5]] = 1.0
    return v / math.sqrt(3.0)
