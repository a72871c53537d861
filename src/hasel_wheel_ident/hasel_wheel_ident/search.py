"""The forward selection of effects (:class:`Search`): each round screens the candidates
not yet in the model, refits the promising ones and cross-validates them, tries refused
ones again (from the reference force law, after the leader, as a pair), and checks that the
accepted gain is the effect's own.  The rules are in docs/identification.md; each method
names the test that holds it."""
from __future__ import annotations

import dataclasses
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

from hasel_wheel_bag.progress import progress_bar

from hasel_wheel_ident.acceptance import judge, optimum_not_effect, pick, poorer_optimum
from hasel_wheel_ident.candidates import BY_ID, Candidate
from hasel_wheel_ident.evaluation import Evaluation, evaluate
from hasel_wheel_ident.fit import Problem, effect_wald_p, force_coordinates
from hasel_wheel_ident.identification import Identification
from hasel_wheel_ident.metrics import pooled_rmse
from hasel_wheel_ident.reasons import Finding, Reason
from hasel_wheel_ident.refit_plan import (backed, cuts_windows, further_refits, refit_order,
                                          stood_in, supported_pair, tied_pair)
from hasel_wheel_ident.refusals import Refusals
from hasel_wheel_ident.screen import Screening, bent, restart_from, screen

#: Evaluation limit of the current model refitted from where a refit ended
#: (:meth:`Search._from_where`).
CHECK_NFEV = 30


@dataclasses.dataclass
class Settings:
    """The search's bounds: ``min_gain`` [1] the held-out free-run bar, ``max_effects`` the
    most effects named, ``max_refits`` the most refits per round, ``threads`` the workers;
    ``short_fits``: a bent fit's candidates may be screened by short fits from the reference
    force law (:meth:`Search._screen`); ``progress``, when given, labels bars on stderr (on
    a terminal) of the candidates screened and of each refit's folds."""

    min_gain: float = 0.10
    max_effects: int = 2
    max_refits: int = 2
    threads: int = 2
    short_fits: bool = True
    progress: str | None = None


class Search:
    """One forward selection from the nominal evaluation ``ident.nominal`` of
    ``ident.trials`` over ``library``; :meth:`run` leaves the result in ``ident``."""

    def __init__(self, ident: Identification, library: tuple[Candidate, ...],
                 settings: Settings, say: Callable[[str], None]) -> None:
        self.ident, self.library, self.s, self.say = ident, library, settings, say
        self.trials, self.base, self.window = ident.trials, ident.base, ident.window
        self.current = ident.nominal
        self.chosen: tuple[Candidate, ...] = ()
        self.restarted = False
        self.refusals = Refusals(self.trials, self.base, self.window, settings.min_gain,
                                 settings.threads)
        friction = ident.friction
        start = {"tau_f": friction.tau_f} if friction else {}
        self.reference = dict(start, **{k: v for k, v in force_coordinates(self.base).items()})
        if friction is None:
            self.reference.pop("tau_f", None)

    # -- the rounds ---------------------------------------------------------------------

    def run(self) -> None:
        """Rounds until nothing joins, ``max_effects`` are named, or the library is spent;
        then the chosen model's fit runs on if it stopped at its limit (:meth:`run_on`)."""
        for round_no in range(self.s.max_effects + 1):
            todo = [c for c in self.library if c not in self.chosen]
            if not todo or len(self.chosen) >= self.s.max_effects or (
                    round_no == self.s.max_effects and not self.restarted):
                break
            if not self._round(todo):
                break
        if self.chosen and not self.current.fit.converged:
            self.run_on()
        self.ident.final = self.current

    def _round(self, todo: list[Candidate]) -> bool:
        """One round over ``todo``; False when the search ends here."""
        problem = Problem(self.trials, self.base, self.chosen, self.window)
        ref = dict(self.reference, tau_f=self.current.fit.values.get("tau_f", self.base.tau_f))
        scores, promising, rivals = self._screen(problem, todo, ref)
        evs = self._refits(scores, promising, rivals, ref)
        self.ident.rounds.append(evs)
        best = pick(evs)
        outcome = self._poorer_optimum(evs) if best is None else self._own_gain(best)
        if outcome is None:
            return False
        why, check = outcome
        if why is not None:
            if self.restarted:
                return False
            self._restart(check)
            return True
        self.chosen = tuple(BY_ID[i] for i in best.effects)
        self.current = best
        z = best.fit.z.tobytes()
        self.ident.consistency.update({i: self.refusals.checked[(z, i)] for i in best.effects
                                       if (z, i) in self.refusals.checked})
        return True

    # -- screening ----------------------------------------------------------------------

    def _screen(self, problem: Problem, todo: list[Candidate], ref: dict[str, float]
                ) -> tuple[list[Screening], list[Screening], bool]:
        """(Every candidate of ``todo`` screened, those to refit, whether they are rivals).
        A bent current fit (:func:`~.screen.bent`) with nothing anchoring it (no coast-down,
        or a parameter on its bound) is also screened by short fits from the reference force
        law; so is a bent nominal fit whose screening finds nothing to refit.  Tested in
        ``test_ident_effects.py::test_strong_retention_that_bends_the_nominal_fit_...``."""
        fit, friction = self.current.fit, self.ident.friction
        crooked = bent(problem, fit) if self.s.short_fits else None
        anchored = friction is not None and not problem.at_bounds(fit)
        noise = problem.noise(problem.residual(fit.z), len(fit.names))
        short = crooked is not None and not anchored
        scores = self._screen_all(problem, todo, ref, noise, short)
        promising, rivals = refit_order(scores, fit.rmse, self.s.min_gain, self.s.max_refits)
        if crooked is not None and not short and not promising and not self.chosen:
            self.say(f"screened: nothing to refit, and the current fit looks bent ({crooked})")
            short = True
            scores = self._screen_all(problem, todo, ref, noise, short)
            promising, rivals = refit_order(scores, fit.rmse, self.s.min_gain,
                                            self.s.max_refits)
        self.ident.screenings.append(scores)
        if short:
            self.say(f"the current fit looks bent ({crooked}): each candidate is also "
                     f"screened by a short fit from the reference force law")
        self.say("screened: " + ", ".join(f"{s.candidate} chi2 {s.statistic:.0f}"
                                          for s in scores))
        return scores, promising, rivals

    def _screen_all(self, problem: Problem, todo: list[Candidate], ref: dict[str, float],
                    noise: tuple[float, float], short: bool) -> list[Screening]:
        """Every candidate of ``todo`` screened (in ``todo``'s order), with the short fits
        from the reference force law if ``short``; the costliest run first."""
        friction, base, fit = self.ident.friction, self.base, self.current.fit
        restart = None if not short else restart_from(
            problem, fit, dict(self.reference, tau_f=friction.tau_f if friction else
                               base.tau_f, brake_gain=base.brake_gain))

        def score(c: Candidate) -> Screening:
            return screen(self.trials, base, self.chosen, fit, problem, c, self.window, ref,
                          restart, noise)

        order = sorted(todo, key=lambda c: -((2 + 2 * len(c.screen_at)) * (17 + c.size)
                                             + 24 * len(c.scan)))
        with ThreadPoolExecutor(max_workers=max(self.s.threads, 1)) as pool:
            scored = pool.map(score, order)
            if self.s.progress:
                scored = progress_bar(scored, f"{self.s.progress}: screening", len(order),
                                      unit="candidate", scale=False)
            done = dict(zip((c.id for c in order), scored))
        return [done[c.id] for c in todo]

    # -- refits -------------------------------------------------------------------------

    def _refits(self, scores: list[Screening], promising: list[Screening], rivals: bool,
                ref: dict[str, float]) -> list[Evaluation]:
        """The round's refits: the promising ones (a leader stops at its acceptance), the
        :func:`~.refit_plan.further_refits`, and a pair of two when one is due."""
        current, min_gain = self.current, self.s.min_gain
        evs: list[Evaluation] = []
        for sc in promising:
            evs.append(self._refit(sc, ref))
            if evs[-1].accepted and not rivals:
                break
        cut = [e.effects[-1] for e in evs if cuts_windows(e, current, min_gain)]
        for sc in further_refits(scores, promising, evs, current, min_gain, self.s.max_refits):
            self.say(f"  {sc.candidate}: refitted as well, since {' and '.join(cut)} cut the "
                     f"window RMSE but {'was' if len(cut) == 1 else 'were'} refused")
            evs.append(self._refit(sc, ref))
            if evs[-1].accepted or sum(backed(e, current, min_gain) for e in evs) >= 2:
                break
        pair = (supported_pair(evs, current, min_gain) or tied_pair(evs, current)) \
            if len(self.chosen) + 2 <= self.s.max_effects else ()
        if pair:
            evs.append(self._refit_pair(*pair))
        return evs

    def _bar(self, model: str) -> str | None:
        """The label of the bar of ``model``'s folds (None: no bar)."""
        return f"{self.s.progress}: {model}" if self.s.progress else None

    def _gates(self, effects: tuple[Candidate, ...], added: tuple[Candidate, ...]) -> dict:
        """:func:`~.evaluation.evaluate`'s gates for the current model plus ``added``."""
        return dict(cv_below=self.current.fit.rmse,
                    sim_below=pooled_rmse(self.current.sim_fitted),
                    refuse=lambda f: self.refusals(f, effects, added))

    def _refit(self, sc: Screening, ref: dict[str, float]) -> Evaluation:
        """The screened candidate ``sc`` refitted from its screened start (from the current
        model if that fits worse), judged, and refitted from the reference force law when
        the windows back it but it was refused (:meth:`_from_reference`)."""
        c, current = BY_ID[sc.candidate], self.current
        effects = self.chosen + (c,)
        gates = self._gates(effects, (c,))
        ev = evaluate(self.trials, self.base, effects, self.window, sc.start,
                      self.ident.folds, self.s.threads, **gates, progress=self._bar(c.id))
        if ev.fit.rmse > current.fit.rmse:
            self.say(f"  {c.id}: refit from the current model (the screened start fitted worse)")
            ev = evaluate(self.trials, self.base, effects, self.window,
                          dict(current.fit.values), self.ident.folds, self.s.threads, **gates,
                          progress=self._bar(c.id))
        judge(ev, (c,), current, self.s.min_gain, self.refusals(ev.fit, effects, (c,)))
        if not ev.accepted and (backed(ev, current, self.s.min_gain) or (
                stood_in(ev, current, self.s.min_gain) and not current.fit.converged)):
            ev = self._from_reference(ev, sc, ref, gates)
        self.say(f"+ {c.id}: {'accepted' if ev.accepted else 'refused'}: {ev.reason}")
        return ev

    def _from_reference(self, ev: Evaluation, sc: Screening, ref: dict[str, float],
                        gates: dict) -> Evaluation:
        """``ev`` refitted once more from the reference force law (the current model's other
        values, the candidate's screened start); the better window fit is kept and judged
        (code ``REFIT_FROM_REFERENCE``).  Tested in
        ``test_ident_effects.py::test_an_effect_refused_in_a_bent_fit_is_refitted_...``."""
        c, current = BY_ID[sc.candidate], self.current
        effects = self.chosen + (c,)
        alt = evaluate(self.trials, self.base, effects, self.window,
                       {**current.fit.values, **ref,
                        **{p.name: sc.start[p.name] for p in c.params}},
                       self.ident.folds, self.s.threads, **gates, progress=self._bar(c.id))
        self.say(f"  {c.id}: refused from its screened start although it cuts the window "
                 f"RMSE to {1e3 * ev.fit.rmse:.3f} mrad; from the reference force law "
                 f"{1e3 * alt.fit.rmse:.3f} mrad")
        if not alt.fit.rmse < ev.fit.rmse:
            return ev
        judge(alt, (c,), current, self.s.min_gain, self.refusals(alt.fit, effects, (c,)))
        if alt.plausible:
            self.refusals.stand_ins.pop(c.id, None)
        alt.reason += (f"; refitted from the reference force law (from its screened start: "
                       f"window RMSE {1e3 * ev.fit.rmse:.3f} mrad, refused)")
        alt.codes.append(Reason.REFIT_FROM_REFERENCE)
        return alt

    def _refit_pair(self, first: Evaluation, other: Evaluation) -> Evaluation:
        """Two refits of one effect each fitted together, from ``first``'s values with
        ``other``'s own, and judged as one step (code ``TRIED_TOGETHER``).  Tested in
        ``test_ident_effects.py::test_two_effects_that_each_fail_the_free_run_alone_...``."""
        pair = (first, other)
        why_pair = (f"each alone cut the window RMSE (to {1e3 * first.fit.rmse:.3f} and "
                    f"{1e3 * other.fit.rmse:.3f} mrad) but was refused"
                    if not (first.accepted or other.accepted) else
                    f"{'+'.join(e.effects[-1] for e in pair if e.accepted)} alone was "
                    f"accepted, and {'+'.join(e.effects[-1] for e in pair if not e.accepted)}"
                    f" alone (refused) fits the held-out windows as well")
        added = tuple(BY_ID[e.effects[-1]] for e in pair)
        effects = self.chosen + added
        ev = evaluate(self.trials, self.base, effects, self.window,
                      {**first.fit.values,
                       **{p.name: other.fit.values[p.name] for p in added[1].params}},
                      self.ident.folds, self.s.threads, **self._gates(effects, added),
                      progress=self._bar("+".join(c.id for c in added)))
        judge(ev, added, self.current, self.s.min_gain, self.refusals(ev.fit, effects, added))
        ev.reason += f"; tried together: {why_pair}"
        ev.codes.append(Reason.TRIED_TOGETHER)
        self.say(f"+ {'+'.join(e.id for e in added)}: "
                 f"{'accepted' if ev.accepted else 'refused'}: {ev.reason}")
        return ev

    # -- is the gain the effect's? ------------------------------------------------------

    def _from_where(self, ev: Evaluation) -> Evaluation:
        """The current model refitted from where ``ev``'s fit ended (its added effects'
        parameters dropped; :data:`CHECK_NFEV` evaluations, no folds)."""
        own = {p.name for i in ev.effects[len(self.chosen):] for p in BY_ID[i].params}
        return evaluate(self.trials, self.base, self.chosen, self.window,
                        {k: v for k, v in ev.fit.values.items() if k not in own},
                        self.ident.folds, self.s.threads,
                        refuse=lambda f: "a check, not cross-validated",
                        x0=ev.fit.x0, max_nfev=CHECK_NFEV)

    def _poorer_optimum(self, evs: list[Evaluation]
                        ) -> tuple[Finding | None, Evaluation] | None:
        """With nothing picked: (why the current model sits in a poorer optimum, the check)
        from the refused refit the windows back best (:func:`~.acceptance.poorer_optimum`);
        None when there is none, it shows none, or the search restarted already."""
        lead = min((e for e in evs if backed(e, self.current, self.s.min_gain)),
                   key=lambda e: e.fit.rmse, default=None)
        if lead is None or self.restarted:
            return None
        check = self._from_where(lead)
        why = poorer_optimum(self.current, lead, check, self.s.min_gain)
        if why is None:
            return None
        lead.reason += "; " + why.text
        lead.codes.append(why.code)
        self.say(f"  {'+'.join(lead.effects[len(self.chosen):])}: {why}")
        return why, check

    def _own_gain(self, best: Evaluation) -> tuple[Finding | None, Evaluation]:
        """(Why ``best``'s gain is a better optimum of the current model, or None; the
        check): :func:`~.acceptance.optimum_not_effect`, refusing ``best`` if so."""
        check = self._from_where(best)
        why = optimum_not_effect(self.current, best, check, self.s.min_gain)
        if why is not None:
            best.accepted = False
            best.reason += "; refused: " + why.text
            best.codes.append(why.code)
            self.say(f"  {'+'.join(best.effects[len(self.chosen):])}: {why}")
        return why, check

    def _restart(self, check: Evaluation) -> None:
        """Replace the current model by ``check``, its better optimum, cross-validated
        (code ``RESTARTED``); once per search."""
        self.restarted = True
        current = evaluate(self.trials, self.base, self.chosen, self.window,
                           dict(check.fit.values), self.ident.folds, self.s.threads,
                           x0=check.fit.x0, progress=self._bar("current model"))
        current.accepted = True
        current.reason = ("+".join(c.id for c in self.chosen) or "nominal model") + \
            " (refitted from a better optimum)"
        current.codes = [Reason.RESTARTED]
        if not self.chosen:
            self.ident.nominal = current
        self.current = current
        self.say(f"current model refitted: window RMSE {1e3 * current.fit.rmse:.3f} mrad, "
                 f"held-out {1e3 * current.heldout_rmse:.3f} mrad")

    # -- the chosen model's fit ---------------------------------------------------------

    def run_on(self) -> None:
        """The chosen model's fit stopped at its limit: run it on for one more limit, and
        keep it when it fits the windows no worse (code ``RAN_ON``), with the held-out
        figures of the folds fitted from where it stopped."""
        current = self.current
        more = evaluate(self.trials, self.base, self.chosen, self.window,
                        dict(current.fit.values), self.ident.folds, self.s.threads,
                        refuse=lambda f: "run on: the folds are the stopped fit's",
                        x0=current.fit.x0)
        self.say(f"the chosen model's fit stopped at its limit; run on from there: "
                 f"{'converged' if more.fit.converged else 'stopped again'} after "
                 f"{more.fit.nfev} more evaluations, window RMSE {1e3 * more.fit.rmse:.3f} mrad")
        if more.fit.rmse <= current.fit.rmse:
            self._carry_over(current, more)
            self.ident.ran_on_from, self.current = current, more

    def _carry_over(self, stopped: Evaluation, more: Evaluation) -> None:
        """Give the fit that ran on (``more``) the verdict and held-out figures of the
        ``stopped`` one; its Wald p is its own, its evaluations count both runs."""
        more.fit = dataclasses.replace(more.fit, nfev=stopped.fit.nfev + more.fit.nfev)
        more.accepted, more.plausible = True, stopped.plausible
        more.heldout_rmse, more.heldout_per_trial = (stopped.heldout_rmse,
                                                     stopped.heldout_per_trial)
        more.sim_heldout, more.fold_values = stopped.sim_heldout, stopped.fold_values
        more.wald_p = max(effect_wald_p(more.fit, c) for c in self.chosen)
        more.reason = (f"{stopped.reason}; its fit ran on from where it stopped at its "
                       f"limit ({more.fit.nfev} evaluations in all; held-out figures from "
                       f"the folds fitted from where it stopped)")
        more.codes = list(stopped.codes) + [Reason.RAN_ON]

