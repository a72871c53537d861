"""The compiled window-start solver and Jacobian give the bits of the array versions they
replaced.

:meth:`~hasel_wheel_ident.fit.Problem.starts_for` runs each window's safeguarded
Gauss-Newton in compiled code (:func:`~hasel_wheel_ident.simulate.solve_window_starts`),
and :meth:`~hasel_wheel_ident.fit.Problem.jacobian` shoots its columns and projects the
starts out there too.  Both were first written with numpy arrays over all windows at once;
those versions are kept here, word for word, as the references.  Every choice the
identification makes downstream follows these numbers, so they must not move in the last
bit: they are compared with ``assert_array_equal``, not a tolerance.
"""
import math
import os
import subprocess
import sys

import numpy as np
import pytest

from hasel_wheel_ident import candidates as C
from hasel_wheel_ident import synthetic as S
from hasel_wheel_ident.fit import Problem
from hasel_wheel_ident.simulate import window_dot
from hasel_wheel_sim.effects import effects_from_mapping
from hasel_wheel_sim.model import angle_readings
from hasel_wheel_sim.plant import PlantConfig


def reference_output_error(problem: Problem, x1, pv):
    """The array version of the output error (:func:`~hasel_wheel_ident.simulate.sample_error`)."""
    x1 = angle_readings(x1, pv)
    if problem.quantum is None:
        return np.where(problem.ok, x1 - problem.y, 0.0)
    return np.where(problem.ok, x1 - np.clip(x1, problem.y, problem.y + problem.quantum), 0.0)


def window_sums(problem: Problem, v):
    return np.add.reduceat(v, problem.starts[:-1])


def normal(problem: Problem, d1, d2):
    a11, a12, a22 = (window_sums(problem, d1 * d1), window_sums(problem, d1 * d2),
                     window_sums(problem, d2 * d2))
    det = a11 * a22 - a12 * a12
    return a11, a12, a22, np.where(np.abs(det) > 1e-30, det, np.inf)


def reference_jacobian(problem: Problem, theta, x0, r, d1, d2):
    """The array version of :meth:`Problem.jacobian` (and of its projection)."""
    J = np.empty((problem.n, theta.size))
    for j in range(theta.size):
        tp, h = problem.stepped(theta, j)
        pv, extra = problem.model(problem.full_theta(tp))
        x1, x2 = np.zeros(problem.n), np.zeros(problem.n)
        eta = problem.eta + extra.get("eta_offset", 0.0)
        problem._shoot_windows(eta, problem.gains(pv), np.arange(problem.n_windows), x0, pv,
                               x1, x2)
        J[:, j] = (reference_output_error(problem, x1, pv) - r) / h
    a11, a12, a22, det = normal(problem, d1, d2)
    win = np.repeat(np.arange(problem.n_windows), np.diff(problem.starts))
    out = J.copy()
    for j in range(J.shape[1]):
        g1, g2 = window_sums(problem, d1 * J[:, j]), window_sums(problem, d2 * J[:, j])
        c1 = (a22 * g1 - a12 * g2) / det
        c2 = (a11 * g2 - a12 * g1) / det
        out[:, j] -= c1[win] * d1 + c2[win] * d2
    return out


def reference_starts(problem: Problem, pv, eta, gains, x0, iterations=20, paths=None):
    """The array version of :meth:`Problem.starts_for` (every window at once).  ``paths``
    (a dict), when given, counts the steps refused and the trial speeds clamped at 0."""
    paths = {} if paths is None else paths
    x0 = x0.copy()
    h1, h2 = 1e-6, 1e-6
    lengths = np.diff(problem.starts)
    out = [np.zeros(problem.n) for _ in range(2)]
    scratch = np.zeros(problem.n)
    every = np.arange(problem.n_windows)
    problem._shoot_windows(eta, gains, every, x0, pv, out[0], out[1])
    r = reference_output_error(problem, out[0], pv)
    cost = window_sums(problem, r * r)
    d1, d2 = np.zeros(problem.n), np.zeros(problem.n)
    active = np.ones(problem.n_windows, dtype=bool)
    lam = np.ones(problem.n_windows)
    stale = np.ones(problem.n_windows, dtype=bool)

    def derivatives(windows):
        sel = np.repeat(np.isin(every, windows), lengths)
        for d, e, h in ((d1, (h1, 0.0), h1), (d2, (0.0, h2), h2)):
            problem._shoot_windows(eta, gains, windows, x0 + e, pv, out[1], scratch)
            d[sel] = (reference_output_error(problem, out[1], pv)[sel] - r[sel]) / h
        stale[windows] = False

    for _ in range(iterations):
        windows = np.flatnonzero(active)
        if windows.size == 0:
            break
        derivatives(windows)
        a11, a12, a22, det = normal(problem, d1, d2)
        g1, g2 = window_sums(problem, d1 * r), window_sums(problem, d2 * r)
        step = np.column_stack([-(a22 * g1 - a12 * g2) / det, -(a11 * g2 - a12 * g1) / det])
        step[~active] = 0.0
        trial = x0 + lam[:, None] * step
        paths["clamped"] = paths.get("clamped", 0) + int(np.sum(trial[windows, 1] < 0.0))
        np.maximum(trial[:, 1], 0.0, out=trial[:, 1])
        problem._shoot_windows(eta, gains, windows, trial, pv, out[1], scratch)
        r_try = reference_output_error(problem, out[1], pv)
        cost_try = window_sums(problem, r_try * r_try)
        take = active & (cost_try <= cost)
        paths["refused"] = paths.get("refused", 0) + int(np.sum(active & ~take))
        x0[take] = trial[take]
        cost[take] = cost_try[take]
        sel = np.repeat(take, lengths)
        r[sel] = r_try[sel]
        stale |= take
        small = (np.abs(step[:, 0]) < 1e-7) & (np.abs(step[:, 1]) < 1e-6)
        lam = np.where(take, np.minimum(2.0 * lam, 1.0), 0.25 * lam)
        active &= ~(take & small) & (lam >= 1.0 / 256)
    if stale.any():
        derivatives(np.flatnonzero(stale))
    return x0, r, d1, d2


def assert_same_bits(a, b):
    """a and b hold the same float64 bits (-0.0 is not 0.0 here, nor one NaN another)."""
    a, b = np.ascontiguousarray(a, dtype=float), np.ascontiguousarray(b, dtype=float)
    assert a.shape == b.shape
    np.testing.assert_array_equal(a.view(np.uint64), b.view(np.uint64))


@pytest.fixture(scope="module")
def trials():
    specs = tuple(S.SyntheticTrial(math.radians(a), drive=6.0, coast=2.0) for a in (2.0, 7.0))
    effects = {**S.ENCODER,
               "com_offset": {"enabled": True, "torque": {"value": 0.004, "unit": "N*m"},
                              "phase": {"value": 0.5, "unit": "rad"}}}
    return S.record_set(specs, config=PlantConfig(seed=5, switching="tick",
                                                  effects=effects_from_mapping(effects)))


def _theta(problem: Problem, values: dict[str, float]):
    return np.array([values.get(problem.specs[i].name, problem.specs[i].start)
                     for i in problem.free]) * 1.02


def _inputs(problem: Problem, values: dict[str, float]):
    pv, extra = problem.model(problem.full_theta(_theta(problem, values)))
    return pv, problem.eta + extra.get("eta_offset", 0.0), problem.gains(pv)


CASES = {
    # encoder counts: the error is the distance from the count's interval
    "encoder": (dict(), (), {}),
    # the angles taken as they are (motion capture)
    "angles as read": (dict(quantised=False), (), {}),
    # an eccentric sensor (cos, sin in every sample) and gains that fall with the HV time
    "eccentric sensor, retention": (dict(), ("angle_eccentricity", "charge_retention"),
                                    {"E": 0.01, "F": -0.004, "rate": 0.02, "recovery": 30.0}),
    # samples outside [1.5 s, 6 s) do not count (ok False): windows with none and with some
    "samples left out": (dict(keep=(1.5, 6.0)), (), {}),
}


@pytest.mark.parametrize("case", CASES)
@pytest.mark.parametrize("threads", [1, 2])
def test_compiled_window_starts_are_the_array_versions_bits(trials, case, threads):
    kwargs, ids, values = CASES[case]
    problem = Problem(trials, candidates=C.library(list(ids)) if ids else (), threads=threads,
                      **kwargs)
    pv, eta, gains = _inputs(problem, values)
    x0 = problem.initial_starts()
    x0[::3, 1] += 0.5                    # some windows start far off and need many steps,
    x0[1::3, 1] = 0.02                   # some near rest, where a step can go below 0
    # a start speed of -0.0: where no sample counts (samples left out) the step is -0.0 too,
    # and the clamp must give +0.0 as np.maximum does
    x0[0, 1] = -0.0
    paths: dict[str, int] = {}
    for iterations in (0, 3, 20):
        got = problem.starts_for(pv, eta, gains, x0, iterations)
        want = reference_starts(problem, pv, eta, gains, x0, iterations, paths)
        for a, b in zip(got, want):
            assert_same_bits(a, b)
    # the rule's side paths ran: a step refused (its derivatives kept) and a trial speed
    # clamped at 0 (not where samples are left out: the windows near rest count none there;
    # the -0.0 start takes the clamp's other side)
    assert paths["refused"] > 0
    assert paths["clamped"] > 0 or case == "samples left out"
    # the solve moved the starts and cut the error (the comparison is not of two no-ops)
    r_start = reference_starts(problem, pv, eta, gains, x0, 0)[1]
    assert float(got[1] @ got[1]) < 0.5 * float(r_start @ r_start)
    assert not np.array_equal(got[0], x0)
    # the Jacobian at the solved starts, its columns shot and the starts projected out
    theta = _theta(problem, values)
    jac = problem.jacobian(theta, *got)
    assert_same_bits(jac, reference_jacobian(problem, theta, *got))
    assert np.all(np.abs(jac).max(axis=0) > 0)       # every parameter moves the residual


def test_the_fused_shot_is_the_output_error_of_the_simulation(trials):
    # and the residual of a packed vector is that shot
    problem = Problem(trials, candidates=C.library(["angle_eccentricity"]), threads=2)
    pv, eta, gains = _inputs(problem, {"E": 0.01, "F": 0.003})
    x0 = problem.initial_starts()
    err = problem._shoot(pv, eta, gains, x0)
    x1, x2 = np.zeros(problem.n), np.zeros(problem.n)
    problem._shoot_windows(eta, gains, np.arange(problem.n_windows), x0, pv, x1, x2)
    assert_same_bits(err, reference_output_error(problem, x1, pv))
    assert_same_bits(problem._out1, x1)
    z = np.concatenate([_theta(problem, {"E": 0.01, "F": 0.003}), x0.ravel()])
    assert_same_bits(problem.residual(z), err)


@pytest.mark.parametrize("lengths", [[1], [2, 7, 8, 9], [127, 128, 129], [255, 256, 257, 300],
                                     [1000, 4097, 3]])
def test_window_dot_sums_in_numpys_order(lengths):
    rng = np.random.default_rng(len(lengths))
    starts = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int64)
    # magnitudes over 12 decades, so another order of the sum would round differently
    u = rng.standard_normal(starts[-1]) * 10.0 ** rng.uniform(-8, 4, starts[-1])
    v = rng.standard_normal(starts[-1])
    u[0], v[0] = -0.0, 1.0               # a window of one sample keeps -0.0, as numpy does
    want = np.add.reduceat(u * v, starts[:-1])
    got = np.array([window_dot(u, v, starts[w], starts[w + 1]) for w in range(len(lengths))])
    assert_same_bits(got, want)
    # and the order matters: a running sum from the first product rounds differently
    if max(lengths) > 128:
        running = np.array([np.cumsum(u[a:b] * v[a:b])[-1]
                            for a, b in zip(starts[:-1], starts[1:])])
        assert not np.array_equal(running, want)


def test_the_recursive_sum_loads_from_numbas_cache(tmp_path):
    # numba/numba#6061: a recursive function cached with cache=True crashed when it was
    # loaded from the cache.  One process compiles the sum into a fresh cache, a second loads
    # it from there and must get numpy's bits for a sum long enough to recurse
    pytest.importorskip("numba")
    code = (
        "import numpy as np\n"
        "from hasel_wheel_ident.simulate import _pairwise_dot\n"
        "u = np.random.default_rng(0).standard_normal(5000)\n"
        "s = _pairwise_dot(u, u, 0, u.size)\n"
        "assert s == np.add.reduce(u * u), (s, np.add.reduce(u * u))\n"
        "st = _pairwise_dot.stats\n"
        "print(sum(st.cache_hits.values()), sum(st.cache_misses.values()))\n")
    env = dict(os.environ, HASEL_WHEEL_JIT_CACHE=str(tmp_path))
    runs = [subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                           text=True, timeout=300) for _ in range(2)]
    for run in runs:
        assert run.returncode == 0, run.stderr
    assert runs[0].stdout.split() == ["0", "1"]          # compiled into the fresh cache
    assert runs[1].stdout.split() == ["1", "0"]          # and loaded from it
