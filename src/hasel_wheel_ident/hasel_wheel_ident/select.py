"""The whole identification, :func:`identify`: the nominal fit, the search for missing
effects with held-out validation by trial (:mod:`.search`), and the residual analysis of
what remains (:mod:`.unexplained`).

The parts: :mod:`.evaluation` (a model fitted on all trials and cross-validated),
:mod:`.acceptance` (the held-out bars, the choice between refits, near misses),
:mod:`.refit_plan` (which candidates a round refits), :mod:`.refusals` (values that cannot
be the effect they name), :mod:`.identification` (the result record), :mod:`.reasons` (the
codes each verdict carries).  The rules and their evidence are in docs/identification.md.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

from hasel_wheel_sim.params import WheelParams

from hasel_wheel_ident.candidates import LIBRARY, Candidate
from hasel_wheel_ident.data import Trial
from hasel_wheel_ident.evaluation import evaluate, folds_of
from hasel_wheel_ident.fit import Problem, coastdown_friction
from hasel_wheel_ident.friction_trend import along_the_trend, coast_frictions, friction_trend
from hasel_wheel_ident.identification import Identification
from hasel_wheel_ident.prediction import prediction_residual
from hasel_wheel_ident.reasons import InputRefused, Reason
from hasel_wheel_ident.residual import analyse
from hasel_wheel_ident.search import Search, Settings
from hasel_wheel_ident.session import as_session
from hasel_wheel_ident.steps import gain_step
from hasel_wheel_ident.threads import with_one_blas_thread
from hasel_wheel_ident.unexplained import describe_unexplained


@with_one_blas_thread
def identify(trials: list[Trial], base: WheelParams | None = None,
             library: tuple[Candidate, ...] = LIBRARY, window: float = 1.0, k_folds: int = 5,
             min_gain: float = 0.10, max_effects: int = 2, max_refits: int = 2,
             threads: int = 2, analyse_residuals: bool = True,
             progress: Callable[[str], None] | None = None,
             short_fits: bool = True, progress_bars: str | None = None) -> Identification:
    """Identify the model of ``trials`` (at least 2; ``k_folds`` >= 2 folds by trial), taken
    as one session (:func:`~.session.as_session`: in session order when they carry session
    times, effects with memory carried from one to the next):
    windows of ``window`` [s], effects from ``library`` that cut the held-out simulation
    error by ``min_gain`` [1] or more, up to ``max_effects``.  ``short_fits``: screen the
    candidates of a bent fit by short fits from the reference force law too
    (:func:`~.screen.bent`).  ``progress`` (e.g.
    ``print``) gets one line per step with the elapsed wall time; ``progress_bars``, when
    given, labels bars on stderr (on a terminal) of the candidates screened and of each
    model's folds.  Raises
    :class:`~.reasons.InputRefused` (code ``TOO_FEW_TRIALS`` or ``TOO_FEW_FOLDS``).
    Tested in ``test_ident_effects.py``."""
    _check_inputs(trials, k_folds)
    say = _stopwatch(progress)
    base = base or WheelParams()
    session = as_session(trials)
    if session.warning:
        say(f"warning: {session.warning}")
    coasts = coast_frictions(session.trials, base)
    trend = friction_trend(coasts)
    if trend is not None:
        say(trend.text())
    ident = _nominal(along_the_trend(session.trials, trend) if trend and trend.significant
                     else session.trials, base, window, k_folds, min_gain, threads, say,
                     progress_bars)
    ident.session, ident.coast_friction, ident.friction_trend = session, coasts, trend
    settings = Settings(min_gain, max_effects, max_refits, threads, short_fits, progress_bars)
    search = Search(ident, library, settings, say)
    search.run()
    if ident.session is not None and ident.session.timed:
        ident.gain_step = gain_step(ident.consistency.get("gain_spread"))
        if ident.gain_step is not None:
            say(ident.gain_step.text())
    if analyse_residuals:
        _analyse(ident, say)
        describe_unexplained(ident, search.chosen, ident.final, search.refusals, min_gain,
                             say, threads)
    return ident


def _check_inputs(trials: list[Trial], k_folds: int) -> None:
    """Refuse fewer than 2 trials or 2 folds: held-out validation by trial needs them."""
    if len(trials) < 2 or k_folds < 2:
        raise InputRefused(Reason.TOO_FEW_TRIALS if len(trials) < 2 else Reason.TOO_FEW_FOLDS,
                           f"held-out validation by trial needs at least 2 trials and "
                           f"k_folds >= 2; got {len(trials)} trial(s) and k_folds = {k_folds}")


def _stopwatch(progress: Callable[[str], None] | None) -> Callable[[str], None]:
    """A ``say(text)`` that passes ``text`` to ``progress`` with the seconds since now."""
    t_start = time.perf_counter()

    def say(text: str) -> None:
        if progress is not None:
            progress(f"[{time.perf_counter() - t_start:6.1f} s] {text}")

    return say


def _nominal(trials: list[Trial], base: WheelParams, window: float, k_folds: int,
             min_gain: float, threads: int, say: Callable[[str], None],
             progress_bars: str | None = None) -> Identification:
    """The record with the nominal model fitted and cross-validated (code ``NOMINAL``),
    tau_f from the coast-downs when the trials have them."""
    friction = coastdown_friction(trials, base)
    start = {"tau_f": friction.tau_f} if friction else {}
    folds = folds_of(len(trials), k_folds)
    say(f"tau_f from coast-downs: {friction.tau_f:.6f} N*m" if friction else
        "no coast-down: tau_f is fitted with the force law")
    nominal = evaluate(trials, base, (), window, start, folds, threads,
                       progress=f"{progress_bars}: nominal model" if progress_bars else None)
    say(f"nominal model: window RMSE {1e3 * nominal.fit.rmse:.3f} mrad, held-out "
        f"{1e3 * nominal.heldout_rmse:.3f} mrad ({nominal.fit.nfev} evaluations"
        + ("" if nominal.fit.converged else ", stopped at the limit: not converged") + ")")
    nominal.accepted, nominal.reason, nominal.codes = True, "nominal model", [Reason.NOMINAL]
    return Identification(friction, nominal, nominal, folds=folds, trials=list(trials),
                          base=base, window=window, min_gain=min_gain)


def _analyse(ident: Identification, say: Callable[[str], None]) -> None:
    """The residual analyses of the nominal and the final model, side by side (numpy and
    the compiled simulator release the GIL), then their one-step prediction residuals."""
    say("residual analysis")
    trials, base, window = ident.trials, ident.base, ident.window
    nominal, final = ident.nominal, ident.final
    ident.problem_before = Problem(trials, base, (), window)
    ident.problem_after = ident.problem(ident.chosen)
    params, ext, _ = ident.model()
    with ThreadPoolExecutor(max_workers=2) as pool:
        before = pool.submit(analyse, ident.problem_before, nominal.fit)
        after = pool.submit(analyse, ident.problem_after, final.fit)
        ident.diagnostics_before, ident.diagnostics_after = before.result(), after.result()
    for tr in trials:
        ident.prediction_before[tr.name] = prediction_residual(tr, nominal.fit.params)
        ident.prediction_after[tr.name] = prediction_residual(tr, params, ext)
