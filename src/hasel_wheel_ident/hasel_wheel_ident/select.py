"""The whole identification: nominal fit, residual analysis, and the search for the missing
effect with held-out validation by trial.

Search (forward selection).  Starting from the nominal model:

1. **screen** every candidate not yet in the model: add it and refit by one Gauss-Newton
   step, a score test (:mod:`.screen`); when the current fit looks bent (it stopped
   unconverged, or a nominal parameter ended on a bound: :func:`~.screen.bent`) and either
   the trials have no coast-down or a parameter is on its bound, also by a short fit from
   the reference force law.  A candidate goes on when it is significant
   (p < ``SCREEN_P``) and either is predicted to cut the window RMSE by at least half of
   ``min_gain`` or belongs to a *dominant* group of at most ``max_refits``: each member at
   least twice as significant (in -log10 p) as every candidate outside (:func:`dominant`).
   With no dominant group, the ``max_refits`` most significant go on.  A structure one
   effect causes is explained far better by that effect than by the others; a structure
   from outside the library is caught a little by many and dominated by none.  Screening
   only chooses what to refit: the refit's held-out errors below decide, so a structure
   from outside the library is reported instead of forced onto a wrong explanation.  (The
   window RMSE under-predicts effects that build up over a trial: charge retention at
   0.1/s was screened at -4.6 % and -48 in log10 p, beside a rise lag at -29, so it sat on
   the edge of both rules; refitted, it cuts the held-out simulation error about 2x.  The
   score ranks the two the other way round too: a 40 ms rise lag on six 48 s trials was
   screened at -42 beside charge retention at -83; refitted, the rise lag cut the held-out
   simulation error by 52 %, retention by 18 %);
2. **refit** those to convergence, most promising first, up to ``max_refits``, and
   **cross-validate** each (k-fold by trial, each fold refitted; the held-out trials are
   scored with the fold's parameters).  A candidate that leads the screening alone stops
   the refits once it is accepted; rivals (a tied pair, or the most significant when none
   leads) are all refitted, and the accepted one with the lower held-out window error
   joins.  Accepted only when all hold:

   * the **held-out simulation error** (free run of each left-out trial, the paper's
     Table III metric, :mod:`.metrics`) falls by at least ``min_gain`` (default 10 %).
     Cross-validation is the penalty for complexity: parameters that only fit noise do not
     help on trials they never saw;
   * the held-out window error falls too (the windows' angle RMSE, > 0 %);
   * **significance**: its parameters differ from "no effect" by more than chance, a Wald
     test  (x - x0)' C^-1 (x - x0) against chi^2 with p < 1e-6;
   * **plausibility**: the fitted values look like the physics the candidate names
     (``Candidate.implausible``).  Fifteen free gains can imitate any torque fixed to the
     wheel angle: an off-centre mass outside the library was taken for a gain spread of
     std 0.21 whose variance lay almost all in one harmonic per turn.  Fabrication spread
     makes independent gains, so such a pattern is refused
     (:func:`~.candidates.spread_pattern`) and the structure is reported as unexplained.
     The test needs only the fit on all trials, so an implausible refit is refused before
     its folds are fitted (the off-centre mass outside the library: 119.9 s instead of 153.2 s, bench_ident.py);
   * **the same in every trial**: refitted on each trial alone (with force law and friction), the
     effect's size must not trend with the trials' speed (:mod:`.consistency`): an
     off-centre mass standing in for an angle sensor's reading error grows as about
     speed^2, a reading error standing in for an off-centre mass falls as speed^-3.
     Runs of one closed loop share their mean speed: then the spans of each drive are
     refitted in place of the trials (:func:`~.consistency.speed_units`).
     Refitted on the first and the second half of each drive as well, an effect that
     changes within the trials is refitted once more beside a force loss that grows with
     the accumulated HV time (a measuring device, :data:`~.consistency.HV_LOSS`): a rise
     lag standing in for charge retention is slower in the second halves and no longer
     holds beside the device, so it is refused; a right drag that takes up part of a
     missing retention grows there too, but holds, and is kept with a caution
     (:func:`~.consistency.drift_stand_in`).  A rise lag is refitted there whether it
     drifts or not (:data:`~.consistency.LOSS_LOOKALIKES`): one that does not drift is
     refused when it no longer holds while the device is significant beside it, and
     carries a caution when it holds while the device is significant
     (:func:`~.consistency.loss_caution`).  When the model has a retention already, or
     the effect is retention, no such refit runs and a drift is only a caution.  An
     effect whose size grows with the trials' speed (short of a refusal) is refitted
     beside a force that builds up after each switch-on (the device
     :data:`~.consistency.ON_LAG`): retention standing in for a rise lag no longer holds
     there and is refused (:func:`~.consistency.lag_stand_in`).  After the search, an
     unexplained drift is measured beside the final model by each device that can go
     there (``Signature.devices``), and by both together (:func:`_devices_together`,
     :func:`~.consistency.together_lead`): a description, never a name.
     Checked on the fit on all trials of every refit, so a stand-in is refused before its
     folds, and is not "backed" (no second start, no pair).

   A refit whose simulation error on the very trials it was fitted to does not fall below
   the current model's is refused before its folds too: it cannot cut that error on trials
   it never saw.  (Ad-hoc runs on the benchmarks' 5 x 60 s data, every refit of
   every effect alone: the fall of the error on the fitted trials and on the held-out ones
   differed by 0-3.3 points, e.g. 46.0 and 49.3 % for viscous drag, 16.6 and 18.7 % for
   charge retention refitted on rise-lag data; the gain spread refitted on the platform
   pull outside the library raised it, by 12 % fitted and 18 % held out.)

A refit refused although it cuts the window RMSE on all trials by at least half of
``min_gain`` (and its values are plausible) is fitted once more, from the reference force law
with the current model's other values, and the better fit of the windows is kept and judged.
The windows then say the effect is there while the free run does not, which happens when the
refit stayed in the bent force law of a current model that had absorbed the effect.  Seen
with a weak off-centre mass (0.002 N*m at -2 rad, 3 x 34 s, plant seed 7; ad-hoc runs): the
nominal fit's force law had width 0.24 (the truth 0.10); the COM refit from there cut the
window RMSE by 41 % and the held-out simulation error not at all (-1.7 %), so nothing was
named; from the reference force law it converged to 0.00201 N*m at -2.02 rad and cut that
error by 35 % (the true model: 37 %).  Tested in test_ident_effects.py.

When no refit of a round is accepted but two were refused although each cut the window RMSE
on all trials by at least half of ``min_gain`` with plausible values, the two are refitted
together, from the better window fit with the other's own values, and judged as one step
(each must pass the Wald test; :func:`supported_pair`).  Two effects at once can each fit
the windows better alone while neither makes the free run better, because each leaves the
force law bent by the other.  Seen with viscous drag and a gain spread (plant seed 4, 3 x 34
s): nothing was named; together they cut the held-out simulation error 2.3x (0.0643 ->
0.0279 rad/s; bench_ident_effects.py), with c 1.012e-3 (the truth 1e-3) and a gain std of 0.105 (the plant drew
0.110); tested.

When no refit of a round is accepted and just one is backed by the windows in that way (or
none is, but one cut the window RMSE as much and was refused for its values,
:func:`stood_in`), the next ``max_refits`` significant candidates that were not refitted get
refits of their own
(:func:`further_refits`): a second effect can hold the leader's free run down, and it then
scores below the leader, where the :func:`dominant` rule leaves it out.  And when one refit
is accepted but a refused one fits the held-out windows as well (a tie, which :func:`pick`
will not break by guessing), the two are refitted together and judged as one step too
(:func:`tied_pair`).  Seen with a 50 ms rise lag and viscous drag of 1e-3 N*m*s/rad (plant
seed 11, 3 x 34 s): the drag led alone and was refused (held-out simulation error -8.6 %),
and nothing was named; now the rise lag is refitted as well and passes alone (-26 %), the
drag ties it on the held-out windows, and together they cut the error 2.8x (0.0738 ->
0.0266 rad/s; the true model 2.8x), c 0.97e-3 and tau 49.6 ms; tested.

The best accepted candidate joins the model only if its gain is its own: the current model
is refitted from where the augmented fit ended (30 evaluations, no folds), and when that
refit simulates the trials better than the current fit did, the effect must still cut the
error by half of ``min_gain`` against it (:func:`optimum_not_effect`).  If not, the effect is refused,
the current model is replaced by that better optimum of itself (cross-validated again), and
the search screens once more against it.  The same happens when no refit is picked
(none accepted, or a tie :func:`pick` will not break) but the refused one that the windows
back best (:func:`backed`) ended where the current model alone simulates the trials better
by half of ``min_gain`` (:func:`poorer_optimum`): a bent force law it left behind.  Either
restart happens once per run.  The best accepted candidate joins the model and the search
repeats, up to ``max_effects``.
Whatever structure remains in the residual afterwards is reported as unexplained, with its
signature (:mod:`.residual`).
"""
from __future__ import annotations

import dataclasses
import math
import time
from typing import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from hasel_wheel_sim.model import Extensions
from hasel_wheel_sim.params import WheelParams

from hasel_wheel_ident.candidates import BY_ID, LIBRARY, Candidate
from hasel_wheel_ident.consistency import (DEVICE_TREND_AXIS, DEVICE_WORDS, HV_LOSS, ON_LAG, Consistency,
                          can_measure_beside, can_measure_lag, devices_verdict,
                          drift_stand_in, lag_stand_in, lead_device, refit_beside,
                          stand_in_reason, trial_consistency)
from hasel_wheel_ident.data import Trial
from hasel_wheel_ident.fit import (FitResult, FrictionEstimate, Problem, coastdown_friction, effect_wald_p,
                  force_coordinates, wald_p)
from hasel_wheel_ident import actuator
from hasel_wheel_ident import periodic
from hasel_wheel_ident.metrics import TrialMetrics, drift_text, fitted_metrics, pooled_rmse, trial_metrics
from hasel_wheel_ident.prediction import PredictionResidual, prediction_residual
from hasel_wheel_ident.residual import (TREND_SIGNIFICANCE, Diagnostics, Signature, Trend, along_p, analyse,
                       autocorrelation_signature, drift_along)
from hasel_wheel_ident.screen import SCREEN_P, Screening, bent, restart_from, screen
from hasel_wheel_ident.threads import with_one_blas_thread




#: An added effect must differ from "no effect" with a Wald p under this [1] (the texts
#: of the reasons and the report say "1e-6").
WALD_P = 1e-6


@dataclass
class Evaluation:
    """One model (nominal + ``effects``) fitted on all trials and cross-validated."""

    effects: tuple[str, ...]
    fit: FitResult
    heldout_rmse: float                     # pooled over folds [rad]
    heldout_per_trial: dict[str, float]     # [rad]
    wald_p: float = math.nan                # of the last added effect
    accepted: bool = False
    plausible: bool = True                  # its values look like the physics it names
    reason: str = ""
    sim_fitted: dict[str, TrialMetrics] = field(default_factory=dict)   # free run, all-trial fit
    sim_heldout: dict[str, TrialMetrics] = field(default_factory=dict)  # free run, fold fits
    fold_values: dict[str, dict[str, float]] = field(default_factory=dict)  # trial -> its fold fit

    @property
    def sim_heldout_rmse(self) -> float:
        """Held-out simulation error [rad/s] pooled over trials (Table III's metric)."""
        return pooled_rmse(self.sim_heldout or self.sim_fitted)


@dataclass
class Identification:
    """Everything the search found, in the order it found it."""

    friction: FrictionEstimate | None
    nominal: Evaluation
    final: Evaluation
    rounds: list[list[Evaluation]] = field(default_factory=list)
    screenings: list[list[Screening]] = field(default_factory=list)
    diagnostics_before: Diagnostics | None = None
    diagnostics_after: Diagnostics | None = None
    problem_before: Problem | None = None
    problem_after: Problem | None = None
    folds: list[list[int]] = field(default_factory=list)
    prediction_before: dict[str, PredictionResidual] = field(default_factory=dict)
    prediction_after: dict[str, PredictionResidual] = field(default_factory=dict)
    trials: list[Trial] = field(default_factory=list)
    base: WheelParams = field(default_factory=WheelParams)
    window: float = 1.0
    #: the chosen effects refitted trial by trial and on the halves of each drive, as checked
    #: when each was added (:mod:`.consistency`); keyed by effect id
    consistency: dict[str, Consistency] = field(default_factory=dict)
    #: periodic signatures of the residual that their refit did not confirm
    #: (:func:`~.periodic.confirmed`): listed apart, not as unexplained structure
    unconfirmed: list[Signature] = field(default_factory=list)
    #: the refit (one of ``rounds``' evaluations, or a restart's) that stopped at its limit
    #: and ran on into ``final``, whose values are therefore not its own; None when the
    #: final model did not run on
    ran_on_from: Evaluation | None = None
    #: the free-run bar [1] the search judged with (``identify``'s ``min_gain``)
    min_gain: float = 0.10

    @property
    def chosen(self) -> tuple[str, ...]:
        return self.final.effects

    def problem(self, effects: tuple[str, ...]) -> Problem:
        """The fit problem of the model nominal + ``effects`` on all trials."""
        return Problem(self.trials, self.base, tuple(BY_ID[i] for i in effects), self.window)

    def model(self) -> tuple[WheelParams, Extensions, list[str]]:
        """The identified model as the plant and the MPC take it: (wheel parameters,
        extensions, the chosen effects that have no field there and are left out)."""
        prob = self.problem(self.chosen)
        params = prob.wheel_params(prob.full_theta(self.final.fit.theta))
        fields: dict = {}
        left_out = []
        i = prob.n_nominal
        values = prob.full_theta(self.final.fit.theta)
        for c in prob.candidates:
            x = values[i:i + c.size]
            i += c.size
            if c.extension is None:
                left_out.append(c.id)
            else:
                fields.update(c.extension(x))
        return params, Extensions(**fields), left_out


def folds_of(n_trials: int, k: int) -> list[list[int]]:
    """Trial indices held out in each fold: leave-one-out up to k trials, else k groups."""
    k = min(k, n_trials)
    return [list(range(i, n_trials, k)) for i in range(k)]


def _subset_starts(problem: Problem, z: np.ndarray, keep: list[int]) -> np.ndarray:
    """(w', 2) the fitted window starts of the trials ``keep`` (windows never cross trials)."""
    x0 = problem.window_starts(z)
    return np.concatenate([x0[problem.trial_windows[i]] for i in keep])


def evaluate(trials: list[Trial], base: WheelParams, effects: tuple[Candidate, ...],
             window: float, start: dict[str, float], folds: list[list[int]],
             threads: int = 2, cv_below: float | None = None,
             sim_below: float | None = None,
             refuse: Callable[[FitResult], str | None] | None = None,
             x0: np.ndarray | None = None, max_nfev: int = 100) -> Evaluation:
    """Fit on all trials from ``start``, then per fold on the rest (warm-started from the
    full fit), and score the held-out trials with their window starts re-solved.

    The folds are skipped (held-out error nan) when the fit on all trials already shows
    that the model cannot pass the held-out test:

    * ``cv_below`` [rad]: its window RMSE is not below this (it does not even fit the data
      it saw better);
    * ``sim_below`` [rad/s]: its pooled simulation error on the trials it was fitted to
      (free run, :mod:`.metrics`) is not below this.  An effect that makes the free run
      worse on its own training trials does not make it better on trials it never saw; the
      two differ by a few per cent either way (bench figures in :func:`identify`);
    * ``refuse`` returns a reason (values that do not look like the physics the effect
      names): no held-out score could make it acceptable.

    ``threads``: how many threads the fit on all trials splits its windows over, and how
    many folds run side by side (a fold left to run alone at the end gets them all).
    ``x0`` (w, 2) and ``max_nfev``: the fit on all trials' window starts and evaluation
    limit (:meth:`~.fit.Problem.fit`)."""
    # the fit on all trials runs alone, so its windows share the threads; the folds then
    # run side by side, one thread each
    problem = Problem(trials, base, effects, window, threads=threads)
    full = problem.fit(start=start, x0=x0, max_nfev=max_nfev)
    ev = Evaluation(tuple(c.id for c in effects), full, full.rmse, dict(full.per_trial_rmse))
    ev.sim_fitted = fitted_metrics(problem, full, trials)
    if len(trials) < 2 or (cv_below is not None and full.rmse > cv_below) or \
            (sim_below is not None and pooled_rmse(ev.sim_fitted) >= sim_below) or \
            (refuse is not None and refuse(full) is not None):
        if len(trials) >= 2:
            ev.heldout_rmse = math.nan
        return ev
    workers = max(threads, 1)
    alone = len(folds) - 1 if len(folds) % workers == 1 and len(folds) > 1 else -1

    def one_fold(i_held: tuple[int, list[int]]) -> tuple[list[int], Problem, np.ndarray,
                                                         np.ndarray, np.ndarray,
                                                         dict[str, float]]:
        i_fold, held = i_held
        train = [i for i in range(len(trials)) if i not in held]
        # the same numbers with any thread count (Problem); the last fold, alone once the
        # others are done, uses every thread
        pf = Problem([trials[i] for i in train], base, effects, window,
                     threads=workers if i_fold == alone else 1)
        f = pf.fit(start=full.values, x0=_subset_starts(problem, full.z, train), max_nfev=30)
        pt = Problem([trials[i] for i in held], base, effects, window)
        theta = np.array([f.values[nm] for nm in pt.names])
        x, r, _, _ = pt.solve_starts(pt.full_theta(theta), _subset_starts(problem, full.z, held))
        return held, pt, theta, x, r, f.values

    sq = n = 0.0
    with ThreadPoolExecutor(max_workers=workers) as pool:
        for held, pt, theta, x, r, values in pool.map(one_fold, enumerate(folds)):
            for j, (i, s) in enumerate(zip(held, pt.trial_slices)):
                tr = trials[i]
                rr = r[s][pt.ok[s]]
                ev.heldout_per_trial[tr.name] = float(np.sqrt(np.mean(rr ** 2)))
                sq += float(rr @ rr)
                n += rr.size
                ev.sim_heldout[tr.name] = trial_metrics(pt, theta, tr,
                                                        x[pt.trial_windows[j][0]])
                ev.fold_values[tr.name] = dict(values)
    ev.heldout_rmse = math.sqrt(sq / n)
    return ev


def dominant(scores: list[Screening], group: int = 2, factor: float = 2.0) -> set[str]:
    """The candidates in the smallest group (up to ``group``) whose every member is at least
    ``factor`` times as significant (in -log10 p) as every candidate outside it.

    A structure one effect causes is explained far better by that effect than by the others,
    which only catch its projection on their own shapes.  Two effects of nearly the same
    shape on the data at hand (a rise lag and charge retention both weaken the force over
    time) can tie above the rest; both are then tried.  A structure from outside the library
    is caught a little by many and dominated by none."""
    ranked = sorted(scores, key=lambda s: s.log10_p)
    for k in range(1, min(group, len(ranked)) + 1):
        inside, outside = ranked[:k], ranked[k:]
        if not outside or max(s.log10_p for s in inside) <= factor * outside[0].log10_p:
            return {s.candidate for s in inside}
    return set()


def pick(evs: list[Evaluation]) -> Evaluation | None:
    """The refit that joins the model: the accepted one with the lowest held-out window
    error, unless a refused rival fits the held-out windows at least as well (and is not
    refused as implausible).  Then the data do not tell the two apart, and naming either
    would be a guess: none joins, the winner's verdict and reason say so, and the structure
    stays in the residual for the analysis to describe.

    Seen with charge retention at 0.05/s on three 34 s trials, while the fits still stopped
    at ftol 1e-10: retention fitted the held-out windows better (0.283 against 0.285 mrad)
    but was refused (Wald p 6e-4), while a rise lag passed on the simulation error (-18 %
    against -11 %).  (Since ftol 1e-6 both pass there and retention is named.)"""
    good = [e for e in evs if e.accepted]
    if not good:
        return None
    best = min(good, key=lambda e: e.heldout_rmse)
    tie = tied(evs, best)
    both = [e for e in good if tie is not None
            and set(best.effects) | set(tie.effects) <= set(e.effects)]
    if both:
        # the two were tried together (tied_pair) and passed: the pair is named
        pair = min(both, key=lambda e: e.heldout_rmse)
        best.reason += f"; named together with {tie.effects[-1]} ({'+'.join(pair.effects)})"
        return pair
    if tie is not None:
        best.accepted = False
        best.reason += (f"; not named: {'+'.join(tie.effects)} (refused) fits the held-out "
                        f"windows as well ({1e3 * tie.heldout_rmse:.3f} against "
                        f"{1e3 * best.heldout_rmse:.3f} mrad), so the data do not tell the two "
                        f"apart")
        return None
    return best


def near_misses(ident: Identification) -> list[Evaluation]:
    """The refits turned away at the free-run bar, best first: in the search's last round,
    which added nothing, the refused refits with plausible values, a Wald p under 1e-6, a
    lower held-out window RMSE than the final model's, a lower free-run error than the
    final model's own on the trials both were fitted to (so that the gain is not only a
    better optimum of a model that stopped or ran on), and a held-out simulation error
    below the final model's by less than ``ident.min_gain`` [1] but by at least half of it.
    [] when the last round added an effect.

    The bar keeps look-alikes out, so these are not named; but a reader should see them.
    Seen with a 40 ms rise lag in three closed-loop runs of one wheel (the demo's profile at
    half length, plant seed 3; ad hoc): its refit reached 38.8 ms with a Wald p of 0 and cut
    the held-out simulation error by 9.2 %, and the report said only that nothing was
    supported.  (Half the bar: with effects outside the library, an angle eccentricity
    passed all the rest with cuts of 0.8 and 1.8 % on data of a gain spread and of charge
    retention; 3 x 34 s, plant seed 11; ad hoc.)"""
    cur, min_gain = ident.final, ident.min_gain
    if not ident.rounds or any(e.effects == cur.effects for e in ident.rounds[-1]):
        return []
    out = [e for e in ident.rounds[-1]
           if not e.accepted and e.plausible and e.wald_p < WALD_P
           and math.isfinite(e.heldout_rmse) and e.heldout_rmse < cur.heldout_rmse
           and pooled_rmse(e.sim_fitted) < pooled_rmse(cur.sim_fitted)
           and cur.sim_heldout_rmse * (1.0 - min_gain) < e.sim_heldout_rmse
           <= cur.sim_heldout_rmse * (1.0 - 0.5 * min_gain)]
    return sorted(out, key=lambda e: e.sim_heldout_rmse)


def tied(evs: list[Evaluation], best: Evaluation) -> Evaluation | None:
    """The refused, plausible refit among ``evs`` that fits the held-out windows best, if
    at least as well as the accepted ``best`` (see :func:`pick`), else None.  A refit of
    effects that ``best`` holds all of (one of a pair) is no rival to it."""
    tie = [e for e in evs if not e.accepted and e.plausible
           and e.heldout_rmse <= best.heldout_rmse
           and not set(e.effects) <= set(best.effects)]
    return min(tie, key=lambda e: e.heldout_rmse) if tie else None


def tied_pair(evs: list[Evaluation], current: Evaluation
              ) -> tuple[Evaluation, Evaluation] | tuple[()]:
    """The best accepted refit of one effect and a refused one that fits the held-out windows
    as well (:func:`tied`), the better window fit first; () when there is no such tie.

    Naming either would be a guess (:func:`pick`), but both effects may be there: each alone
    then leaves the other's part of the data to a bent force law.  Seen with a 50 ms rise lag
    and viscous drag of 1e-3 N*m*s/rad together on 3 x 34 s (plant seed 11; ad hoc): the rise
    lag alone cut the held-out simulation error by 26 %, the drag alone by 8.6 % but fitted
    the held-out windows better (0.309 against 0.345 mrad)."""
    one = [e for e in evs if len(e.effects) == len(current.effects) + 1]
    good = [e for e in one if e.accepted]
    if not good:
        return ()
    best = min(good, key=lambda e: e.heldout_rmse)
    tie = tied(one, best)
    if tie is None:
        return ()
    return (best, tie) if best.fit.rmse <= tie.fit.rmse else (tie, best)


def optimum_not_effect(current: Evaluation, best: Evaluation, check: Evaluation,
                       min_gain: float = 0.10) -> str | None:
    """Why ``best`` (the current model plus one effect) owes its gain to a better optimum of
    the current model rather than to the effect, or None when it does not.

    ``check`` is the current model refitted from where ``best``'s fit ended (the effect's
    parameters dropped).  When that refit simulates the trials it was fitted to better than
    ``current`` did (pooled free-run error, :mod:`.metrics`), ``current`` sat in a poorer
    optimum; the effect must then still cut the error by half of ``min_gain`` against the
    refit.  (Half: the effect has already cut the held-out error by ``min_gain`` against
    ``current``; this is only to catch a gain that is not the effect's at all.  With the
    full ``min_gain`` a real 20 ms rise lag on 5 x 60 s, whose true model is 1.16x below the
    nominal one, was refused twice in a run of 151 s: seen once, while making this change.)
    Seen with a gain spread of std 0.15 on 3 x 34 s: the gain-spread fit ended with its force
    law bent (width 0.18, the truth 0.10); a 15 ms rise lag then cut the held-out
    simulation error by 30 % and was accepted, by letting the force law return.  The gain
    spread alone, refitted from there, simulated the trials as well (0.0280 against
    0.0288 rad/s).  These figures are from the revision that added this check, when fits
    stopped at ftol 1e-10; since ftol 1e-6 the benchmark prints 0.0285 against 0.0295, and
    the 20 ms rise lag's true model 1.14x."""
    without, with_it = pooled_rmse(check.sim_fitted), pooled_rmse(best.sim_fitted)
    if without >= pooled_rmse(current.sim_fitted) or with_it <= (1.0 - 0.5 * min_gain) * without:
        return None
    return (f"the model without it, refitted from where this fit ended, simulates the trials "
            f"it was fitted to as well ({without:.4f} against {with_it:.4f} rad/s; need "
            f"{50 * min_gain:.0f} % lower with it): the gain came from a better optimum of "
            f"the current model, not from {'+'.join(best.effects[len(current.effects):])}")


def poorer_optimum(current: Evaluation, refused: Evaluation, check: Evaluation,
                   min_gain: float = 0.10) -> str | None:
    """Why ``current`` sits in a poorer optimum of itself, as a ``refused`` refit (the current
    model plus one effect, which the windows back) showed; None when it does not.

    ``check`` is the current model refitted from where ``refused``'s fit ended (the effect's
    parameters dropped).  It shows a poorer optimum when it simulates the trials it was
    fitted to (pooled free-run error, :mod:`.metrics`) better than ``current`` by at least
    half of ``min_gain``.  Seen with a torque periodic in the pivot angle (4e-3 N*m) on
    3 x 34 s, plant seed 11, with 10 ms of serial latency each way, 0.2 % glitches and 0.2 %
    lost samples (ad hoc): the platform's fit ended with its force law bent (peak 398, width
    0.034; the truth 20 and 0.10), held-out error 0.1150 rad/s against 0.2339 nominal; a
    viscous drag refitted from the reference force law cut the window RMSE from 0.436 to
    0.291 mrad, its coefficient insignificant (Wald p 0.19), and it was refused, so nothing
    more happened."""
    without, before = pooled_rmse(check.sim_fitted), pooled_rmse(current.sim_fitted)
    if not without <= (1.0 - 0.5 * min_gain) * before:
        return None
    return (f"refitted from where this fit ended, without {refused.effects[-1]}, the current "
            f"model simulates the trials it was fitted to better ({without:.4f} against "
            f"{before:.4f} rad/s; need {50 * min_gain:.0f} % lower): it sat in a poorer "
            f"optimum of itself")


def refit_order(scores: list[Screening], rmse: float, min_gain: float = 0.10,
                max_refits: int = 2) -> tuple[list[Screening], bool]:
    """Which screened candidates to refit, most promising (lowest predicted window RMSE)
    first, and whether they are rivals (all refitted, the held-out errors choose) rather than
    one leader (the refits stop at the first accepted).  ``rmse`` [rad] is the current
    model's window RMSE.

    A candidate goes on when it is significant (p < SCREEN_P) and either is predicted to cut
    the window RMSE by half of ``min_gain`` or is in the lead: the :func:`dominant` group,
    or, when there is none, the ``max_refits`` most significant.  One candidate far ahead of
    the rest leads alone; two that tie, or the most significant when none leads, are rivals.
    """
    lead = dominant(scores, max_refits)
    rivals = len(lead) != 1
    lead = lead or {s.candidate for s in sorted(scores, key=lambda s: s.log10_p)[:max_refits]}
    promising = sorted((s for s in scores if s.p_value < SCREEN_P and
                        (s.predicted_rmse <= (1.0 - 0.5 * min_gain) * rmse
                         or s.candidate in lead)),
                       key=lambda s: s.predicted_rmse)[:max_refits]
    return promising, rivals


def implausibility(fit: FitResult, added: tuple[Candidate, ...]) -> str | None:
    """Why the fitted values of ``added`` do not look like the physics they name, or None."""
    for c in added:
        why = c.implausible([fit.values[p.name] for p in c.params]) if c.implausible else None
        if why is not None:
            return why
    return None


def supported_pair(evs: list[Evaluation], current: Evaluation,
                   min_gain: float) -> tuple[Evaluation, Evaluation] | tuple[()]:
    """Two refused refits of this round that are worth fitting together: plausible, and each
    cutting the window RMSE on all trials by at least half of ``min_gain`` (the windows say
    the effect is there), the better window fit first; () unless there are two and no refit
    of the round was accepted.

    Two effects at once can each fit the windows better alone while neither makes the free
    run better: the force law the other effect has bent stays.  Seen with viscous drag
    (1e-3 N*m*s/rad) and a gain spread (std 0.1) together, 3 x 34 s, plant seed 4 (ad hoc):
    the gain spread alone cut the window RMSE by 14 % and the held-out simulation error by
    -5.1 %, the drag alone 13 % and raised the simulation error on its own trials; nothing
    was named.  With plant seed 7 the drag was accepted first and the spread after it."""
    if any(e.accepted for e in evs):
        return ()
    both = sorted((e for e in evs if backed(e, current, min_gain)), key=lambda e: e.fit.rmse)
    return (both[0], both[1]) if len(both) >= 2 else ()


def cuts_windows(ev: Evaluation, current: Evaluation, min_gain: float) -> bool:
    """Whether ``ev`` (the current model plus one effect) cut the window RMSE on all trials
    by at least half of ``min_gain`` against ``current``, whatever its verdict."""
    return (len(ev.effects) == len(current.effects) + 1
            and ev.fit.rmse <= (1.0 - 0.5 * min_gain) * current.fit.rmse)


def backed(ev: Evaluation, current: Evaluation, min_gain: float) -> bool:
    """Whether the windows back ``ev`` (the current model plus one effect) whatever its
    verdict: plausible values, and the window RMSE on all trials cut by at least half of
    ``min_gain`` (:func:`cuts_windows`)."""
    return ev.plausible and cuts_windows(ev, current, min_gain)


def stood_in(ev: Evaluation, current: Evaluation, min_gain: float) -> bool:
    """Whether ``ev`` (the current model plus one effect) cut the window RMSE as
    :func:`backed` asks but was refused for its values (implausible, or a stand-in for
    another effect): the windows say an effect is there, not this one."""
    return not ev.plausible and cuts_windows(ev, current, min_gain)


def further_refits(scores: list[Screening], done: list[Screening], evs: list[Evaluation],
                   current: Evaluation, min_gain: float, max_refits: int) -> list[Screening]:
    """The candidates to refit after ``done`` when none of their refits ``evs`` was accepted
    and exactly one is :func:`backed` by the windows, or none is but one :func:`stood_in`
    for another effect: the next ``max_refits`` significant ones (p < SCREEN_P), most
    significant first; [] otherwise (two backed refits are tried together by
    :func:`supported_pair` instead).

    A second effect can hold down the leader's free run, so that the leader is refused while
    the windows say it is there; the second effect then scores below the leader, and the
    :func:`dominant` rule had left it out.  Seen with a 50 ms rise lag and viscous drag of
    1e-3 N*m*s/rad together on 3 x 34 s (plant seed 11; ad hoc): the drag led (log10 p -55
    against -22) and was refitted alone; it cut the window RMSE by 14 % and the held-out
    simulation error by 8.6 %, under the 10 % bar, and nothing was named although the true
    model cuts that error 2.8x.

    A refit refused as a stand-in leaves its effect's place empty the same way.  Seen with
    an off-centre mass in three closed-loop runs of 115 s (the demo's profile at half length,
    plant seed 3; ad hoc): the eccentricity (chi^2 325) and the gain spread (131) were refitted
    and refused, the one as a stand-in span by span, the other for its once-per-turn pattern,
    and the off-centre mass (126) was never refitted."""
    n_backed = sum(backed(e, current, min_gain) for e in evs)
    if any(e.accepted for e in evs) or n_backed > 1 or (
            n_backed == 0 and not any(stood_in(e, current, min_gain) for e in evs)):
        return []
    tried = {s.candidate for s in done}
    rest = sorted((s for s in scores if s.candidate not in tried and s.p_value < SCREEN_P),
                  key=lambda s: s.log10_p)
    return rest[:max_refits]


def judge(ev: Evaluation, added: tuple[Candidate, ...], current: Evaluation, min_gain: float,
          odd: str | None) -> None:
    """Set ``ev``'s Wald p, plausibility, verdict and reason: the current model plus ``added``
    (one effect, or two tried together) against ``current`` (the rules in the module
    docstring); ``odd`` is why its values are implausible, or None.  The Wald p is the
    largest of the added effects': each must differ from "no effect"."""
    ev.wald_p = max(effect_wald_p(ev.fit, c) for c in added)
    gain = 1.0 - ev.heldout_rmse / current.heldout_rmse
    sim_gain = 1.0 - ev.sim_heldout_rmse / current.sim_heldout_rmse
    ev.plausible = odd is None
    ev.accepted = bool(gain > 0.0 and sim_gain >= min_gain and ev.wald_p < WALD_P
                       and odd is None)
    if math.isnan(ev.heldout_rmse):           # not cross-validated (never accepted)
        fitted = pooled_rmse(ev.sim_fitted)
        before = pooled_rmse(current.sim_fitted)
        gate = (f"the simulation error on the trials it was fitted to did not fall "
                f"({fitted:.4f} rad/s against {before:.4f})" if fitted >= before else
                "it does not fit the windows better" if ev.fit.rmse > current.fit.rmse else None)
        why = "; ".join(w for w in (gate, odd) if w) or "not cross-validated"
        ev.reason = (f"window RMSE {1e3 * ev.fit.rmse:.3f} mrad vs "
                     f"{1e3 * current.fit.rmse:.3f} on all trials; simulation error "
                     f"{fitted:.4f} vs {before:.4f} rad/s on all trials; Wald p = "
                     f"{ev.wald_p:.1e}; refused, not cross-validated: {why}")
    else:
        ev.reason = (f"held-out simulation error {ev.sim_heldout_rmse:.4f} rad/s vs "
                     f"{current.sim_heldout_rmse:.4f} ({100 * sim_gain:+.1f} %, need "
                     f"{100 * min_gain:.0f} %); held-out window RMSE "
                     f"{1e3 * ev.heldout_rmse:.3f} mrad vs "
                     f"{1e3 * current.heldout_rmse:.3f} ({100 * gain:+.1f} %, need > 0);"
                     f" Wald p = {ev.wald_p:.1e} (need < 1e-6)"
                     + (f"; refused: {odd}" if odd else ""))


@with_one_blas_thread
def identify(trials: list[Trial], base: WheelParams | None = None,
             library: tuple[Candidate, ...] = LIBRARY, window: float = 1.0, k_folds: int = 5,
             min_gain: float = 0.10, max_effects: int = 2, max_refits: int = 2,
             threads: int = 2, analyse_residuals: bool = True,
             progress: Callable[[str], None] | None = None) -> Identification:
    """Run the whole identification on ``trials`` (see the module docstring).

    ``progress`` (e.g. ``print``) gets one line per step with the elapsed wall time."""
    t_start = time.perf_counter()

    def say(text: str) -> None:
        if progress is not None:
            progress(f"[{time.perf_counter() - t_start:6.1f} s] {text}")

    if len(trials) < 2 or k_folds < 2:
        raise ValueError(f"held-out validation by trial needs at least 2 trials and k_folds >= 2;"
                         f" got {len(trials)} trial(s) and k_folds = {k_folds}")
    base = base or WheelParams()
    friction = coastdown_friction(trials, base)
    start = {"tau_f": friction.tau_f} if friction else {}
    folds = folds_of(len(trials), k_folds)
    say(f"tau_f from coast-downs: {friction.tau_f:.6f} N*m" if friction else
        "no coast-down: tau_f is fitted with the force law")
    current = evaluate(trials, base, (), window, start, folds, threads)
    say(f"nominal model: window RMSE {1e3 * current.fit.rmse:.3f} mrad, held-out "
        f"{1e3 * current.heldout_rmse:.3f} mrad ({current.fit.nfev} evaluations"
        + ("" if current.fit.converged else ", stopped at the limit: not converged") + ")")
    current.accepted, current.reason = True, "nominal model"
    nominal = current
    chosen: tuple[Candidate, ...] = ()
    ident = Identification(friction, nominal, current, folds=folds, trials=list(trials),
                           base=base, window=window, min_gain=min_gain)
    reference = dict(start, **{k: v for k, v in force_coordinates(base).items()})
    if friction is None:
        reference.pop("tau_f", None)
    restarted = False
    refused: dict[bytes, str | None] = {}
    stand_ins: dict[str, tuple[Candidate, str]] = {}    # id -> (candidate, why a stand-in)
    # (the fit's packed vector, effect id) -> why refused beside a measuring device (a
    # stand-in for a change within the trials, or for a loss at each switch-on)
    within: dict[tuple[bytes, str], str] = {}
    # (the fit's packed vector, effect id) -> the effect refitted trial by trial
    checked: dict[tuple[bytes, str], Consistency] = {}

    def refusal(f: FitResult, effects: tuple[Candidate, ...],
                added: tuple[Candidate, ...]) -> str | None:
        """Why the values of ``added`` in the fit ``f`` cannot be the effect they name:
        implausible values, a size that trends with the trials' speed, a size that
        changes within the trials (or a rise lag) and does not hold beside a measured
        change, or a size that grows with the speed and does not hold beside a switch-on
        lag (once per fit; :mod:`.consistency`)."""
        key = f.z.tobytes() + ("+".join(c.id for c in effects) + "|"
                               + "+".join(c.id for c in added)).encode()
        if key not in refused:
            why = implausibility(f, added)
            if why is None:
                for c in added:
                    con = trial_consistency(trials, base, effects, f, c, window, threads)
                    checked[(f.z.tobytes(), c.id)] = con
                    why = stand_in_reason(c, con)
                    if why is not None:
                        stand_ins[c.id] = (c, why)
                        break
                    # refused beside a measuring device: a change within the trials, then
                    # a size that grows with the speed
                    for check, kept in ((drift_stand_in, "beside"), (lag_stand_in, "beside_lag")):
                        why = check(trials, base, effects, f, c, con, min_gain, window, threads)
                        if why is not None:
                            b = getattr(con, kept)
                            within[(f.z.tobytes(), c.id)] = (f"{c.id} took up part of it and "
                                                             f"was refused, "
                                                             f"{b.text(c.id, need=True)}")
                            break
                    if why is not None:
                        break
            refused[key] = why
        return refused[key]

    for round_no in range(max_effects + 1):
        todo = [c for c in library if c not in chosen]
        if not todo or len(chosen) >= max_effects or (round_no == max_effects and not restarted):
            break
        problem = Problem(trials, base, chosen, window)
        ref = dict(reference, tau_f=current.fit.values.get("tau_f", base.tau_f))

        # a bent fit's candidates are also fitted briefly from the reference force law, where
        # nothing anchors the fit: no coast-down pins tau_f (closed-loop runs, where the pushes
        # answer the disturbance), or a parameter ran onto its bound.  Open-loop trials with
        # coast-downs whose fit only stopped unconverged keep the steps, the scan and the
        # second start, which name their effects (bench_ident_effects.py gave the same choices
        # with the short fits; one screening of 5 x 60 s trials took 12 s with them, ad hoc)
        # (unless the steps find nothing to refit from the nominal model: then the short fits
        # are tried too, which costs one screening only where nothing would be named
        # otherwise; in every round it had doubled the time of an effect outside the library)
        crooked = bent(problem, current.fit)
        anchored = friction is not None and not problem.at_bounds(current.fit)
        noise = problem.noise(problem.residual(current.fit.z), len(current.fit.names))

        def screen_all(short: bool) -> list[Screening]:
            """Every candidate of ``todo`` screened, with the short fits from the reference
            force law if ``short``."""
            restart = None if not short else restart_from(
                problem, current.fit, dict(reference, tau_f=friction.tau_f if friction else
                                           base.tau_f, brake_gain=base.brake_gain))

            def score(c: Candidate) -> Screening:
                return screen(trials, base, chosen, current.fit, problem, c, window, ref,
                              restart, noise)

            # the costliest screens first, so that the threads finish together (a place
            # costs a window solve, ~12 simulations, and a Jacobian, one per parameter; a
            # scan up to one solve per grid value and place)
            order = sorted(todo, key=lambda c: -((2 + 2 * len(c.screen_at)) * (17 + c.size)
                                                 + 24 * len(c.scan)))
            with ThreadPoolExecutor(max_workers=max(threads, 1)) as pool:
                done = dict(zip((c.id for c in order), pool.map(score, order)))
            return [done[c.id] for c in todo]

        short = crooked is not None and not anchored
        scores = screen_all(short)
        promising, rivals = refit_order(scores, current.fit.rmse, min_gain, max_refits)
        if crooked is not None and not short and not promising and not chosen:
            say(f"screened: nothing to refit, and the current fit looks bent ({crooked})")
            short = True
            scores = screen_all(short)
            promising, rivals = refit_order(scores, current.fit.rmse, min_gain, max_refits)
        if not short:
            crooked = None
        ident.screenings.append(scores)
        if crooked is not None:
            say(f"the current fit looks bent ({crooked}): each candidate is also screened by a"
                f" short fit from the reference force law")
        say("screened: " + ", ".join(f"{s.candidate} chi2 {s.statistic:.0f}" for s in scores))
        evs: list[Evaluation] = []

        def refit(sc: Screening) -> Evaluation:
            c = BY_ID[sc.candidate]

            def odd_values(f: FitResult, c: Candidate = c) -> str | None:
                return refusal(f, chosen + (c,), (c,))

            gates = dict(cv_below=current.fit.rmse, sim_below=pooled_rmse(current.sim_fitted),
                         refuse=odd_values)
            ev = evaluate(trials, base, chosen + (c,), window, sc.start, folds, threads,
                          **gates)
            if ev.fit.rmse > current.fit.rmse:
                # the nested model cannot fit worse: the linearised step sent the fit astray;
                # start again from the current model with the candidate at its own start
                say(f"  {c.id}: refit from the current model (the screened start fitted worse)")
                ev = evaluate(trials, base, chosen + (c,), window, dict(current.fit.values),
                              folds, threads, **gates)
            judge(ev, (c,), current, min_gain, odd_values(ev.fit))
            if not ev.accepted and (backed(ev, current, min_gain) or (
                    stood_in(ev, current, min_gain) and not current.fit.converged)):
                # the windows say the effect is there, the free run does not: the refit may
                # have stayed in the current model's bent force law.  Once more, from the
                # reference force law (the current model's other values, the candidate's
                # screened start); the better fit of the windows on all trials is kept.
                # The same for a refit refused for its values while the current fit stopped
                # at its limit: values fitted in a bent force law need not be the effect's
                alt = evaluate(trials, base, chosen + (c,), window,
                               {**current.fit.values, **ref,
                                **{p.name: sc.start[p.name] for p in c.params}},
                               folds, threads, **gates)
                say(f"  {c.id}: refused from its screened start although it cuts the window "
                    f"RMSE to {1e3 * ev.fit.rmse:.3f} mrad; from the reference force law "
                    f"{1e3 * alt.fit.rmse:.3f} mrad")
                if alt.fit.rmse < ev.fit.rmse:
                    judge(alt, (c,), current, min_gain, odd_values(alt.fit))
                    if alt.plausible:
                        # the values the first fit was refused for were the bent law's
                        stand_ins.pop(c.id, None)
                    alt.reason += (f"; refitted from the reference force law (from its "
                                   f"screened start: window RMSE {1e3 * ev.fit.rmse:.3f} mrad, "
                                   f"refused)")
                    ev = alt
            say(f"+ {c.id}: {'accepted' if ev.accepted else 'refused'}: {ev.reason}")
            return ev

        for sc in promising:
            evs.append(refit(sc))
            if evs[-1].accepted and not rivals:
                break       # the next round screens the rest again, against this model
        cut = [e.effects[-1] for e in evs if cuts_windows(e, current, min_gain)]
        for sc in further_refits(scores, promising, evs, current, min_gain, max_refits):
            # a refused refit that the windows back may be held down by a second effect:
            # the next significant candidates get their own refits (and the pair below)
            say(f"  {sc.candidate}: refitted as well, since {' and '.join(cut)} cut the "
                f"window RMSE but {'was' if len(cut) == 1 else 'were'} refused")
            evs.append(refit(sc))
            if evs[-1].accepted or sum(backed(e, current, min_gain) for e in evs) >= 2:
                break       # accepted, or two backed refits for supported_pair
        pair = (supported_pair(evs, current, min_gain) or tied_pair(evs, current)) \
            if len(chosen) + 2 <= max_effects else ()
        if pair:
            # each alone fits the windows better but not the free run, or one is accepted and
            # the other fits the held-out windows as well: try the two together, from the
            # better window fit with the other's own values
            first, other = pair
            why_pair = (f"each alone cut the window RMSE (to {1e3 * first.fit.rmse:.3f} and "
                        f"{1e3 * other.fit.rmse:.3f} mrad) but was refused"
                        if not (first.accepted or other.accepted) else
                        f"{'+'.join(e.effects[-1] for e in pair if e.accepted)} alone was "
                        f"accepted, and {'+'.join(e.effects[-1] for e in pair if not e.accepted)}"
                        f" alone (refused) fits the held-out windows as well")
            added = tuple(BY_ID[e.effects[-1]] for e in pair)
            ev = evaluate(trials, base, chosen + added, window,
                          {**first.fit.values,
                           **{p.name: other.fit.values[p.name] for p in added[1].params}},
                          folds, threads, cv_below=current.fit.rmse,
                          sim_below=pooled_rmse(current.sim_fitted),
                          refuse=lambda f: refusal(f, chosen + added, added))
            judge(ev, added, current, min_gain, refusal(ev.fit, chosen + added, added))
            ev.reason += f"; tried together: {why_pair}"
            evs.append(ev)
            say(f"+ {'+'.join(e.id for e in added)}: "
                f"{'accepted' if ev.accepted else 'refused'}: {ev.reason}")
        ident.rounds.append(evs)
        best = pick(evs)

        def from_where(ev: Evaluation) -> Evaluation:
            """The current model refitted from where ``ev``'s fit ended (its added effects'
            parameters dropped; 30 evaluations, no folds)."""
            return evaluate(trials, base, chosen, window,
                            {k: v for k, v in ev.fit.values.items()
                             if k not in {p.name for i in ev.effects[len(chosen):]
                                          for p in BY_ID[i].params}},
                            folds, threads, refuse=lambda f: "a check, not cross-validated",
                            x0=ev.fit.x0, max_nfev=30)

        if best is None:
            # nothing accepted; but a refused refit that the windows back may have reached a
            # better optimum of the current model itself, with an effect that is not there
            # (:func:`poorer_optimum`): the search restarts from it
            lead = min((e for e in evs if backed(e, current, min_gain)),
                       key=lambda e: e.fit.rmse, default=None)
            if lead is None or restarted:
                break
            check = from_where(lead)
            why = poorer_optimum(current, lead, check, min_gain)
            if why is None:
                break
            lead.reason += "; " + why
            say(f"  {'+'.join(lead.effects[len(chosen):])}: {why}")
        else:
            # was the gain the effect's, or a better optimum of the current model that the
            # effect's fit happened to reach?  Refit the current model from where it ended
            check = from_where(best)
            why = optimum_not_effect(current, best, check, min_gain)
            if why is not None:
                best.accepted = False
                best.reason += "; refused: " + why
                say(f"  {'+'.join(best.effects[len(chosen):])}: {why}")
        if why is not None:
            if restarted:
                break
            restarted = True
            current = evaluate(trials, base, chosen, window, dict(check.fit.values), folds,
                               threads, x0=check.fit.x0)
            current.accepted = True
            current.reason = ("+".join(c.id for c in chosen) or "nominal model") + \
                " (refitted from a better optimum)"
            if not chosen:
                nominal = ident.nominal = current
            say(f"current model refitted: window RMSE {1e3 * current.fit.rmse:.3f} mrad, "
                f"held-out {1e3 * current.heldout_rmse:.3f} mrad")
            continue
        chosen = tuple(BY_ID[i] for i in best.effects)
        current = best
        # each chosen effect as it was checked trial by trial when it was added
        ident.consistency.update({i: checked[(best.fit.z.tobytes(), i)] for i in best.effects
                                  if (best.fit.z.tobytes(), i) in checked})
    if chosen and not current.fit.converged:
        # the chosen model's fit stopped at its limit, so its values and intervals are where
        # it stopped, not a minimum: it runs on from there for one more limit, and the fit
        # that went on is kept when it fits the windows no worse.  Its held-out figures stay
        # those of the folds fitted from where it stopped (each fold is fitted afresh on the
        # other trials: 30 evaluations from the full fit's values), which saves refitting
        # them
        more = evaluate(trials, base, chosen, window, dict(current.fit.values), folds, threads,
                        refuse=lambda f: "run on: the folds are the stopped fit's",
                        x0=current.fit.x0)
        say(f"the chosen model's fit stopped at its limit; run on from there: "
            f"{'converged' if more.fit.converged else 'stopped again'} after "
            f"{more.fit.nfev} more evaluations, window RMSE {1e3 * more.fit.rmse:.3f} mrad")
        if more.fit.rmse <= current.fit.rmse:
            # the same model nearer its minimum: the checks it passed are the stopped fit's
            # (the consistency refits are not run again); its Wald p is its own, and its
            # evaluations count both runs
            more.fit = dataclasses.replace(more.fit, nfev=current.fit.nfev + more.fit.nfev)
            more.accepted, more.plausible = True, current.plausible
            more.heldout_rmse, more.heldout_per_trial = (current.heldout_rmse,
                                                         current.heldout_per_trial)
            more.sim_heldout, more.fold_values = current.sim_heldout, current.fold_values
            more.wald_p = max(effect_wald_p(more.fit, c) for c in chosen)
            more.reason = (f"{current.reason}; its fit ran on from where it stopped at its "
                           f"limit ({more.fit.nfev} evaluations in all; held-out figures from "
                           f"the folds fitted from where it stopped)")
            ident.ran_on_from, current = current, more
    ident.final = current
    if analyse_residuals:
        say("residual analysis")
        ident.problem_before = Problem(trials, base, (), window)
        ident.problem_after = Problem(trials, base, chosen, window)
        params, ext, _ = ident.model()
        # the two analyses spend their time in numpy and the compiled simulator (no GIL): side
        # by side they share the cores.  The prediction residuals run in the Python observer
        # (GIL) and come after them: beside the analyses, each of the analyses' compiled
        # calls waited for the observer's thread to hand back the GIL, and the three took
        # 9.4 s on 5 x 60 s where the analyses and then the predictions take 2.2 + 3.8 s
        # (ad hoc)
        with ThreadPoolExecutor(max_workers=2) as pool:
            before = pool.submit(analyse, ident.problem_before, nominal.fit)
            after = pool.submit(analyse, ident.problem_after, current.fit)
            ident.diagnostics_before, ident.diagnostics_after = before.result(), after.result()
        for tr in trials:
            ident.prediction_before[tr.name] = prediction_residual(tr, nominal.fit.params)
            ident.prediction_after[tr.name] = prediction_residual(tr, params, ext)
        _describe_unexplained(ident, chosen, current, stand_ins, within, min_gain, say,
                              threads)
    return ident


def _describe_unexplained(ident: Identification, chosen: tuple[Candidate, ...],
                          current: Evaluation, stand_ins: dict[str, tuple[Candidate, str]],
                          within: dict[tuple[bytes, str], str], min_gain: float,
                          say: Callable[[str], None], threads: int) -> None:
    """Size and describe what the final model (``chosen``, fitted as ``current``) leaves
    unexplained, in ``ident.diagnostics_after.signatures`` (changed in place; the periodic
    signatures a refit does not confirm go to ``ident.unconfirmed``).  ``stand_ins`` (id ->
    (candidate, why)) are the library effects refused as stand-ins for a trend with the
    trials' speed, ``within`` ((fit bytes, id) -> note) those refused beside a measuring
    device: both say what a signature is not.  A drift is measured beside the model by each
    measuring device that can go there, alone and (both) together, and says which takes up
    the most (:func:`~.consistency.devices_verdict`).  ``min_gain`` (a fraction) is the
    search's; ``say`` reports progress."""
    trials, base, window = ident.trials, ident.base, ident.window
    # what is left unexplained and periodic in an angle: sized by a refit (the residual
    # alone shows only what the fit did not already absorb), the strongest first
    diag = ident.diagnostics_after
    sigs = diag.signatures
    # an unexplained drift is measured beside the model by each measuring device that can
    # go there: how much of it a loss with HV time, or a force that builds up after each
    # switch-on, takes up (a description, not a name).  The periodic torques and the force
    # factors below are sized beside the device that takes up the most of it (the HV-time
    # loss, :data:`~.consistency.HV_LOSS`, when none does): they would otherwise take up part
    # of the drift
    measuring: tuple[tuple[Candidate, ...], FitResult] = (chosen, current.fit)
    if any(drift_signature(s) for s in sigs):
        e_model = pooled_rmse(current.sim_fitted)
        devices = [d for d, can in ((HV_LOSS, can_measure_beside(chosen)),
                                    (ON_LAG, can_measure_lag(chosen))) if can]
        alone: dict[str, FitResult] = {}            # device id -> its refit beside the model
        for device in devices:
            noun, words = DEVICE_WORDS[device.id]
            say(f"refitting with {noun} beside the unexplained drift (a measuring device)")
            problem, device_fit = refit_beside(trials, base, chosen, current.fit, device,
                                               window, threads)
            value = device_fit.values[device.params[0].name]
            p = wald_p(device_fit, device)
            e = pooled_rmse(fitted_metrics(problem, device_fit, trials))
            if not (math.isfinite(value) and math.isfinite(e)):
                continue                # a refit that failed measures nothing
            alone[device.id] = device_fit
            if device is HV_LOSS:
                measuring = (chosen + (HV_LOSS,), device_fit)
            for sig in sigs:
                if drift_signature(sig):
                    sig.devices[device.id] = {"value": value, "unit": device.params[0].unit,
                                              "wald_p": p, "sim_rmse_rad_s": e,
                                              "sim_rmse_model_rad_s": e_model}
                    sig.text += (f"; with {noun} beside the model ({words(value)}, a "
                                 f"measuring device, never named; Wald p {p:.1e}), the free "
                                 f"run on all trials is {e:.4f} rad/s against {e_model:.4f}")
        # and refitted together: the one that stays significant beside the other is the
        # loss that is there, whichever runs the trials better alone (together_lead)
        together = _devices_together(trials, base, chosen, alone, window, threads, say)
        if together is not None:
            for sig in sigs:
                if drift_signature(sig):
                    for device in devices:
                        if device.id in sig.devices:
                            sig.devices[device.id]["wald_p_together"] = wald_p(together,
                                                                               device)
        trend = diag.trend
        for sig in list(sigs):
            if len(sig.devices) > 1:
                sig.text += "; " + devices_verdict(sig.devices, min_gain)
                axis = device_axis(sig, trend, min_gain)
                if axis is not None:
                    drift_along(sig, trend, axis, "the device for it takes up the most")
                    # the drift now describes that axis: a binned signature along it goes
                    sigs[:] = [s for s in sigs if s is sig or s.axis != axis]
        # the periodic torques and the force factors are sized beside the device that takes
        # up the most of the drift, the HV-time loss when none does: beside the wrong device,
        # a rise lag's drift left structure that one force factor per actuator took up
        # (bench_ident_effects.py --outside-only, 3 x 34 s, seed 13)
        lead = next((lead_device(s.devices, min_gain) for s in sigs if drift_signature(s)),
                    None)
        if lead == ON_LAG.id and ON_LAG.id in alone:
            measuring = (chosen + (ON_LAG,), alone[ON_LAG.id])
    todo = [i for i, sig in enumerate(sigs) if periodic.frequency(sig, base)][:MEASURED_SIGNATURES]
    beside = measuring
    torque_beside = False          # the strongest periodic torque is beside the factors
    for i in todo:
        say(f"sizing the unexplained signature: {sigs[i].text}")
        sigs[i], refit, term = periodic.measure(sigs[i], trials, base, *measuring,
                                                window, threads)
        if i == todo[0] and refit is not None:
            beside = (measuring[0] + (term,), refit)
            torque_beside = True
    # structure along the actuator index, beside the strongest periodic torque: the
    # residual's bins are too coarse for it (:mod:`.actuator`)
    say("testing one force factor per actuator")
    by_actuator = actuator.measure(trials, base, beside[0], beside[1], window, threads)
    if by_actuator is not None:
        sig, factors_fit = by_actuator
        # the strongest periodic torque was refitted beside the factors: it may only be
        # their shadow (their first harmonic), so it is sized again from that fit
        if torque_beside:
            sigs[todo[0]] = periodic.sized(sigs[todo[0]], factors_fit,
                                           periodic.frequency(sigs[todo[0]], base), base)
        # it replaces the binned actuator axis, and a residual "correlated while no axis
        # shows structure" no longer applies
        sigs[:] = [s for s in sigs if s.axis not in ("actuator", "autocorrelation")] + [sig]
    if len(measuring[0]) > len(chosen):
        # sized beside a measuring device: say so
        device = measuring[0][-1]
        noun, words = DEVICE_WORDS[device.id]
        value = measuring[1].values[device.params[0].name]
        for sig in sigs:
            if sig.torque_ci95 is not None or sig.factors is not None:
                sig.text += (f"; sized with {noun} beside it ({words(value)}), a measuring "
                             f"device for the unexplained drift")
    # a periodic signature that its refit does not confirm (:func:`periodic.confirmed`) is
    # set apart, not reported as unexplained; if nothing is left, the residual may still
    # be correlated
    ident.unconfirmed = [s for s in sigs if not periodic.confirmed(s)]
    sigs[:] = [s for s in sigs if periodic.confirmed(s)]
    if not sigs:
        correlated = autocorrelation_signature(diag, base.inertia)
        sigs += [correlated] if correlated is not None else []
    for sig in sigs:
        if sig.axis == "autocorrelation" or drift_signature(sig):
            # no axis shows it, or only as a drift: the free run shows it trial by trial
            sig.text += ("; the free run's steady-state speed error (simulated minus "
                         "measured) trial by trial: " + drift_text(trials, current.sim_fitted))
    # a library effect of the same shape that was refused as a stand-in tells how the
    # structure goes with speed, which the signature alone does not
    for sig in sigs:
        for c, why in stand_ins.values():
            # the library's periodic effects are once per turn (lap) of their axis
            if (c.axis == sig.axis and c not in chosen and sig.period is not None
                    and abs(sig.period / (2 * math.pi) - 1.0) < 0.02):
                sig.text += f"; refitted to it, {why}"
        if drift_signature(sig):
            # what the drift is not: the library's effects that took it up in part, as
            # refused beside a measuring device in the refits the search kept (one note per
            # effect)
            noted = set()
            for ev in (e for r in ident.rounds for e in r if not e.accepted):
                for cid in ev.effects:
                    why = within.get((ev.fit.z.tobytes(), cid))
                    if why is not None and cid not in ident.chosen and cid not in noted:
                        noted.add(cid)
                        sig.text += f"; {why}"


#: Evaluation limit of each refit of both devices together (:func:`_devices_together`): each
#: starts from one device's refit, run to convergence, and adds one parameter.  With the
#: refits' own limit (150) the retention look-alike test on 5 x 60 s took 117 s.
TOGETHER_NFEV = 30


def _devices_together(trials: list[Trial], base: WheelParams, chosen: tuple[Candidate, ...],
                      alone: dict[str, FitResult], window: float, threads: int,
                      say: Callable[[str], None]) -> FitResult | None:
    """The final model (``chosen``) with both measuring devices beside it, or None unless
    each was refitted alone (``alone``: device id -> that refit).  It is fitted from each
    device's refit with the other added at its start value, and the better fit of the
    windows is kept, so neither device comes in second to a loss the other already took
    up; None when neither fit is finite."""
    if set(alone) != {HV_LOSS.id, ON_LAG.id}:
        return None
    say("refitting with both measuring devices beside the unexplained drift")
    fits = [refit_beside(trials, base, chosen + (first,), alone[first.id], second, window,
                         threads, TOGETHER_NFEV)[1]
            for first, second in ((HV_LOSS, ON_LAG), (ON_LAG, HV_LOSS))]
    fits = [f for f in fits if math.isfinite(f.rmse)]
    return min(fits, key=lambda f: f.rmse) if fits else None


def device_axis(sig: Signature, trend: Trend | None, min_gain: float) -> str | None:
    """The axis to report the drift ``sig`` (the signature of ``trend``) along in place of
    the one the regression read, or None to keep it.  The regression cannot tell axes that
    rose together; the measuring device that takes up the most of the drift
    (:func:`~.consistency.lead_device`, with the search's ``min_gain``) can.  Its axis
    (:data:`~.consistency.DEVICE_TREND_AXIS`) is taken when it differs from ``sig``'s and
    the trend along it is significant too (:func:`~.residual.along_p` under
    :data:`~.residual.TREND_SIGNIFICANCE`)."""
    axis = DEVICE_TREND_AXIS.get(lead_device(sig.devices, min_gain))
    if (axis is None or trend is None or axis == sig.axis
            or along_p(trend, axis) >= TREND_SIGNIFICANCE):
        return None
    return axis


def drift_signature(sig: Signature) -> bool:
    """Whether ``sig`` is a drift during the drives along one of the trend axes (time, HV
    time, speed; :func:`~.residual.drive_trend`)."""
    return sig.drift


#: Unexplained periodic signatures sized by a refit (:mod:`.periodic`), strongest first.
MEASURED_SIGNATURES = 3
