"""The size of structure along the actuator index: the acceleration an actuator gives while on,
against the speed the model's own trajectory gains per second on (an integral identity)."""
import math
import types

import numpy as np
import pytest

from hasel_wheel_ident import actuator as A
from hasel_wheel_ident import fit as F
from hasel_wheel_ident import synthetic as S
from hasel_wheel_sim import layout as L
from hasel_wheel_sim.params import WheelParams
from hasel_wheel_sim.plant import PlantConfig

TRUE = WheelParams()
SET = tuple(S.SyntheticTrial(math.radians(a), drive=30.0, coast=9.0) for a in (1.0, 4.0, 7.0))


@pytest.fixture(scope="module")
def at_the_truth():
    """The nominal model at the plant's values on exact nominal trials: (problem, fit)."""
    trials = S.record_set(SET, config=PlantConfig(seed=5, switching="tick"))
    problem = F.Problem(trials, TRUE)
    theta = np.array([F.force_coordinates(TRUE)[n] for n in ("peak", "centre", "width", "b")]
                     + [TRUE.tau_f])
    x0, _, _, _ = problem.solve_starts(problem.full_theta(theta), problem.initial_starts())
    return problem, types.SimpleNamespace(theta=theta, z=np.concatenate([theta, x0.ravel()]))


def test_the_drive_is_the_speed_gained_on_plus_friction(at_the_truth):
    # over an interval with the actuator on, the wheel gains int (a_drive - tau/(J/L)) dt: the
    # nominal model has no torque but the actuator's and Coulomb friction's, constant while
    # the wheel rolls on.  So the time average of the actuator's share is the speed gained
    # per second on, plus friction's deceleration, up to the trapezoid rule's error
    problem, fit = at_the_truth
    x1, x2 = problem.simulate(fit.z)
    pv, _ = problem.model(problem.full_theta(fit.theta))
    window = np.repeat(np.arange(problem.n_windows), np.diff(problem.starts))
    i = np.flatnonzero((problem.q[:-1] > 0) & problem.ok[:-1] & (window[1:] == window[:-1]))
    assert np.all(x2[i] > 0.0)                       # rolling: friction is the constant below
    dt = problem.t[i + 1] - problem.t[i]
    gained = float(np.sum(x2[i + 1] - x2[i]) / np.sum(dt))
    friction = pv[L.P_FRICTION] * pv[L.P_INV_INERTIA]
    drive = A.driving_acceleration(problem, fit)
    assert drive == pytest.approx(gained + friction, rel=0.01)
    # the mean of the on-samples alone is not it: the force rises through each push
    assert drive > 1.03 * float(np.mean([
        A.acceleration(x1[k], x2[k], 1.0, problem.eta[k],
                       A.contact_at_switch_on(problem.eta[k], problem.phi_a[k], pv), 1.0,
                       problem.on_time[k], pv, 1.0) + friction for k in i]))
