"""Which screened candidates a round refits, and which refused refits are tried again:
alone after the leader (:func:`further_refits`) or as a pair (:func:`supported_pair`,
:func:`tied_pair`)."""
from __future__ import annotations

from hasel_wheel_ident.acceptance import tied
from hasel_wheel_ident.evaluation import Evaluation
from hasel_wheel_ident.screen import SCREEN_P, Screening


def dominant(scores: list[Screening], group: int = 2, factor: float = 2.0) -> set[str]:
    """The candidates in the smallest group (up to ``group``) whose every member is at least
    ``factor`` times as significant (in -log10 p) as every candidate outside it; the empty
    set when there is none.  Tested in
    ``test_ident_candidates.py::test_one_leader_is_refitted_alone_and_rivals_all``."""
    ranked = sorted(scores, key=lambda s: s.log10_p)
    for k in range(1, min(group, len(ranked)) + 1):
        inside, outside = ranked[:k], ranked[k:]
        if not outside or max(s.log10_p for s in inside) <= factor * outside[0].log10_p:
            return {s.candidate for s in inside}
    return set()


def refit_order(scores: list[Screening], rmse: float, min_gain: float = 0.10,
                max_refits: int = 2) -> tuple[list[Screening], bool]:
    """(The candidates to refit, lowest predicted window RMSE first; whether they are
    rivals).  ``rmse`` [rad] is the current model's window RMSE.  A candidate goes on when
    p < ``SCREEN_P`` and it is predicted to cut ``rmse`` by half of ``min_gain`` [1] or is
    in the lead (the :func:`dominant` group, else the ``max_refits`` most significant).
    One dominant candidate leads alone; otherwise they are rivals (all refitted).  Tested in
    ``test_ident_candidates.py::test_one_leader_is_refitted_alone_and_rivals_all``."""
    lead = dominant(scores, max_refits)
    rivals = len(lead) != 1
    lead = lead or {s.candidate for s in sorted(scores, key=lambda s: s.log10_p)[:max_refits]}
    promising = sorted((s for s in scores if s.p_value < SCREEN_P and
                        (s.predicted_rmse <= (1.0 - 0.5 * min_gain) * rmse
                         or s.candidate in lead)),
                       key=lambda s: s.predicted_rmse)[:max_refits]
    return promising, rivals


def cuts_windows(ev: Evaluation, current: Evaluation, min_gain: float) -> bool:
    """Whether ``ev`` (the current model plus one effect) cut the window RMSE on all trials
    by at least half of ``min_gain`` [1] against ``current``, whatever its verdict."""
    return (len(ev.effects) == len(current.effects) + 1
            and ev.fit.rmse <= (1.0 - 0.5 * min_gain) * current.fit.rmse)


def backed(ev: Evaluation, current: Evaluation, min_gain: float) -> bool:
    """Whether the windows back ``ev`` whatever its verdict: plausible values and
    :func:`cuts_windows`."""
    return ev.plausible and cuts_windows(ev, current, min_gain)


def stood_in(ev: Evaluation, current: Evaluation, min_gain: float) -> bool:
    """Whether ``ev`` :func:`cuts_windows` but was refused for its values (implausible, or
    a stand-in): the windows say an effect is there, not this one."""
    return not ev.plausible and cuts_windows(ev, current, min_gain)


def supported_pair(evs: list[Evaluation], current: Evaluation,
                   min_gain: float) -> tuple[Evaluation, Evaluation] | tuple[()]:
    """The two :func:`backed` refits of a round with none accepted, the better window fit
    first, to be fitted together; () otherwise.  Tested in
    ``test_ident_effects.py::test_two_effects_that_each_fail_the_free_run_alone_...``."""
    if any(e.accepted for e in evs):
        return ()
    both = sorted((e for e in evs if backed(e, current, min_gain)), key=lambda e: e.fit.rmse)
    return (both[0], both[1]) if len(both) >= 2 else ()


def tied_pair(evs: list[Evaluation], current: Evaluation
              ) -> tuple[Evaluation, Evaluation] | tuple[()]:
    """The best accepted refit of one effect and a refused one that fits the held-out windows
    as well (:func:`~.acceptance.tied`), the better window fit first, to be fitted together;
    () when there is no such tie.  Tested in
    ``test_ident_effects.py::test_a_second_effect_behind_a_refused_leader_...``."""
    one = [e for e in evs if len(e.effects) == len(current.effects) + 1]
    good = [e for e in one if e.accepted]
    if not good:
        return ()
    best = min(good, key=lambda e: e.heldout_rmse)
    tie = tied(one, best)
    if tie is None:
        return ()
    return (best, tie) if best.fit.rmse <= tie.fit.rmse else (tie, best)


def further_refits(scores: list[Screening], done: list[Screening], evs: list[Evaluation],
                   current: Evaluation, min_gain: float, max_refits: int) -> list[Screening]:
    """The next ``max_refits`` significant candidates (p < ``SCREEN_P``, most significant
    first) not in ``done``, when none of ``evs`` was accepted and exactly one is
    :func:`backed`, or none is but one :func:`stood_in`; [] otherwise.  Tested in
    ``test_ident_candidates.py::test_a_refit_refused_as_a_stand_in_makes_room_...``."""
    n_backed = sum(backed(e, current, min_gain) for e in evs)
    if any(e.accepted for e in evs) or n_backed > 1 or (
            n_backed == 0 and not any(stood_in(e, current, min_gain) for e in evs)):
        return []
    tried = {s.candidate for s in done}
    rest = sorted((s for s in scores if s.candidate not in tried and s.p_value < SCREEN_P),
                  key=lambda s: s.log10_p)
    return rest[:max_refits]
