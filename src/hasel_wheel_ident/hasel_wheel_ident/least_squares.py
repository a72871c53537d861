"""The least-squares run of a multiple-shooting fit (:func:`solve`) and its result
(:func:`result`).  The window starts are solved for inside every evaluation (variable
projection), warm-started from those of the best evaluation so far, so a trial step far off
(which the trust region then rejects) cannot spoil later evaluations.  It runs to
convergence (:data:`FTOL`).  Tested in ``test_ident_fit.py``."""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from scipy import optimize, stats

from hasel_wheel_sim.params import ParameterError

from hasel_wheel_ident.fit_result import FitResult
from hasel_wheel_ident.uncertainty import covariance

if TYPE_CHECKING:
    from hasel_wheel_ident.fit import Problem

#: A step that lowers the cost by less than this fraction of it ends the fit (scipy's
#: ``ftol``).  The cost divided by the noise variance is about the number of samples outside
#: their encoder interval, ~11,000 on 5 x 60 s at 300 Hz (13 % of them), so 1e-6 of it is
#: ~0.01 of one unit of chi^2: far inside any interval (95 % spans 3.84 units).  It is also
#: about the precision of the cost itself: the window starts are solved to ~1e-7 rad, and
#: solving them with 60 Gauss-Newton iterations instead of 12 moves the cost by a few 1e-6
#: of itself, so a tighter tolerance only chases that noise.
FTOL = 1e-6


class _Evaluations:
    """The problem's residual at the last theta asked for (``x0``, ``r``, ``d1``, ``d2`` as
    :meth:`~.fit.Problem.solve_starts` returns them), and the window starts of the best
    evaluation so far (``best_x0``), from which the next is solved."""

    def __init__(self, problem: Problem, x0: np.ndarray) -> None:
        self.problem = problem
        self.key: bytes | None = None
        self.x0 = self.best_x0 = x0
        self.best = math.inf

    def at(self, theta: np.ndarray) -> _Evaluations:
        """Solved at ``theta`` (once per theta)."""
        key = theta.tobytes()
        if self.key != key:
            prob = self.problem
            try:
                x, r, d1, d2 = prob.solve_starts(prob.full_theta(theta), self.best_x0)
            except ParameterError:
                # a trial step outside the physical parameter ranges (a force law with
                # sigma6 beyond its bound): an error far above any fit, so the trust
                # region rejects the step and shrinks
                x, r = self.best_x0, np.where(prob.ok, 1.0, 0.0)
                d1 = d2 = np.zeros(prob.n)
            self.key, self.x0, self.r, self.d1, self.d2 = key, x, r, d1, d2
            cost = float(r @ r)
            if cost < self.best:
                self.best = cost
                self.best_x0 = x
        return self

    def residual(self, theta: np.ndarray) -> np.ndarray:
        """(n,) the residual [rad] at ``theta``, a copy."""
        return self.at(theta).r.copy()

    def jacobian(self, theta: np.ndarray) -> np.ndarray:
        """(n, g) the projected Jacobian at ``theta`` (:meth:`~.fit.Problem.jacobian`)."""
        st = self.at(theta)
        return self.problem.jacobian(theta, st.x0, st.r, st.d1, st.d2)


def solve(problem: Problem, start: dict[str, float] | None, x0: np.ndarray | None,
          max_nfev: int) -> FitResult:
    """``problem`` fitted from ``start`` (start values by name over the specs') and the
    window starts ``x0`` (w, 2) (:meth:`~.fit.Problem.initial_starts` when None), for up to
    ``max_nfev`` evaluations."""
    params = problem.params
    th = params.start(start or {})
    lo, hi = params.bounds()
    ev = _Evaluations(problem, problem.initial_starts() if x0 is None else x0.copy())
    if th.size:
        sol = optimize.least_squares(ev.residual, th, jac=ev.jacobian, bounds=(lo, hi),
                                     x_scale=params.scale(), method="trf", ftol=FTOL,
                                     xtol=1e-10, gtol=1e-10, max_nfev=max_nfev)
        theta, nfev, ok, msg = sol.x, sol.nfev, sol.status > 0, sol.message
        J = ev.jacobian(theta)
    else:
        theta, nfev, ok, msg, J = th, 1, True, "nothing to fit", np.zeros((problem.n, 0))
    st = ev.at(theta)
    return result(problem, theta, st.x0, st.r, J, nfev, ok, msg)


def result(problem: Problem, theta: np.ndarray, x0: np.ndarray, r: np.ndarray,
           J: np.ndarray, nfev: int, converged: bool, message: str) -> FitResult:
    """The :class:`~.fit_result.FitResult` of ``problem`` at ``theta`` (g,) with the window
    starts ``x0`` (w, 2), residual ``r`` (n,) [rad] and projected Jacobian ``J`` (n, g)."""
    g = theta.size
    used = problem.ok
    n_used = int(used.sum())
    s2, inflation = problem.noise(r, g)
    cov = covariance(J, problem.params.scale(), s2 * inflation) if g else np.zeros((0, 0))
    names = problem.names
    sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
    q = stats.norm.ppf(0.975)
    per_trial = {tr.name: float(np.sqrt(np.mean(r[s][used[s]] ** 2)))
                 for tr, s in zip(problem.trials, problem.trial_slices)}
    return FitResult(
        names=names, units=[problem.specs[i].unit for i in problem.free], theta=theta.copy(),
        z=np.concatenate([theta, x0.ravel()]), cov=cov,
        rmse=float(np.sqrt(np.sum(r ** 2) / n_used)), per_trial_rmse=per_trial,
        nfev=int(nfev), converged=bool(converged), message=str(message),
        inflation=float(inflation), candidates=tuple(c.id for c in problem.candidates),
        params=problem.wheel_params(problem.full_theta(theta)),
        values={n: float(v) for n, v in zip(names, theta)},
        ci95={n: (float(v - q * s), float(v + q * s)) for n, v, s in zip(names, theta, sd)})
