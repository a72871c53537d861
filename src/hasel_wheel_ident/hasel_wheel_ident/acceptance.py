"""The rules that accept or refuse a refit: :func:`judge` (the held-out bars), :func:`pick`
(which accepted refit joins), the two optimum checks, and :func:`near_misses`."""
from __future__ import annotations

import math

from hasel_wheel_ident.candidates import Candidate
from hasel_wheel_ident.evaluation import Evaluation
from hasel_wheel_ident.fit import FitResult, effect_wald_p
from hasel_wheel_ident.identification import Identification
from hasel_wheel_ident.metrics import pooled_rmse
from hasel_wheel_ident.reasons import Finding, Reason

#: An added effect must differ from "no effect" with a Wald p under this [1] (the texts
#: of the reasons and the report say "1e-6").
WALD_P = 1e-6


def implausibility(fit: FitResult, added: tuple[Candidate, ...]) -> Finding | None:
    """Why the fitted values of ``added`` do not look like the physics they name
    (``Candidate.implausible``; code ``IMPLAUSIBLE``), or None."""
    for c in added:
        why = c.implausible([fit.values[p.name] for p in c.params]) if c.implausible else None
        if why is not None:
            return Finding(Reason.IMPLAUSIBLE, why, {"effect": c.id})
    return None


def judge(ev: Evaluation, added: tuple[Candidate, ...], current: Evaluation, min_gain: float,
          odd: Finding | None) -> None:
    """Set ``ev``'s Wald p, plausibility, verdict, reason and codes: the current model plus
    ``added`` against ``current``.  Accepted when the held-out window RMSE falls (> 0), the
    held-out simulation error falls by ``min_gain`` [1] or more, every added effect's Wald p
    is under :data:`WALD_P`, and ``odd`` (why its values are implausible) is None.  Tested
    in ``test_ident_effects.py`` and ``test_ident_candidates.py``."""
    ev.wald_p = max(effect_wald_p(ev.fit, c) for c in added)
    gain = 1.0 - ev.heldout_rmse / current.heldout_rmse
    sim_gain = 1.0 - ev.sim_heldout_rmse / current.sim_heldout_rmse
    ev.plausible = odd is None
    ev.accepted = bool(gain > 0.0 and sim_gain >= min_gain and ev.wald_p < WALD_P
                       and odd is None)
    if math.isnan(ev.heldout_rmse):           # not cross-validated (never accepted)
        _judge_uncrossed(ev, current, odd)
        return
    ev.codes = [Reason.ACCEPTED] if ev.accepted else [
        code for code, failed in ((Reason.HELDOUT_WINDOWS_NOT_BETTER, not gain > 0.0),
                                  (Reason.SIM_GAIN_BELOW_BAR, not sim_gain >= min_gain),
                                  (Reason.NOT_SIGNIFICANT, not ev.wald_p < WALD_P))
        if failed] + ([odd.code] if odd else [])
    ev.reason = (f"held-out simulation error {ev.sim_heldout_rmse:.4f} rad/s vs "
                 f"{current.sim_heldout_rmse:.4f} ({100 * sim_gain:+.1f} %, need "
                 f"{100 * min_gain:.0f} %); held-out window RMSE "
                 f"{1e3 * ev.heldout_rmse:.3f} mrad vs "
                 f"{1e3 * current.heldout_rmse:.3f} ({100 * gain:+.1f} %, need > 0);"
                 f" Wald p = {ev.wald_p:.1e} (need < 1e-6)"
                 + (f"; refused: {odd.text}" if odd else ""))


def _judge_uncrossed(ev: Evaluation, current: Evaluation, odd: Finding | None) -> None:
    """The reason and codes of a refit whose folds were not fitted (:func:`judge`)."""
    fitted = pooled_rmse(ev.sim_fitted)
    before = pooled_rmse(current.sim_fitted)
    gate, code = ((f"the simulation error on the trials it was fitted to did not fall "
                   f"({fitted:.4f} rad/s against {before:.4f})", Reason.SIM_FITTED_NOT_LOWER)
                  if fitted >= before else
                  ("it does not fit the windows better", Reason.WINDOWS_NOT_BETTER)
                  if ev.fit.rmse > current.fit.rmse else (None, None))
    why = "; ".join(w for w in (gate, odd.text if odd else None) if w) or "not cross-validated"
    ev.codes = [Reason.NOT_CROSS_VALIDATED] + [c for c in (code, odd.code if odd else None)
                                               if c is not None]
    ev.reason = (f"window RMSE {1e3 * ev.fit.rmse:.3f} mrad vs "
                 f"{1e3 * current.fit.rmse:.3f} on all trials; simulation error "
                 f"{fitted:.4f} vs {before:.4f} rad/s on all trials; Wald p = "
                 f"{ev.wald_p:.1e}; refused, not cross-validated: {why}")


def tied(evs: list[Evaluation], best: Evaluation) -> Evaluation | None:
    """The refused, plausible refit among ``evs`` that fits the held-out windows best, if
    at least as well as the accepted ``best`` (see :func:`pick`), else None.  A refit of
    effects that ``best`` holds all of (one of a pair) is no rival to it."""
    tie = [e for e in evs if not e.accepted and e.plausible
           and e.heldout_rmse <= best.heldout_rmse
           and not set(e.effects) <= set(best.effects)]
    return min(tie, key=lambda e: e.heldout_rmse) if tie else None


def pick(evs: list[Evaluation]) -> Evaluation | None:
    """The refit that joins the model: the accepted one with the lowest held-out window
    RMSE, unless a refused plausible rival fits the held-out windows at least as well
    (:func:`tied`): then none joins and the winner is refused with code ``TIE``; a pair of
    the two that passed joins instead (code ``NAMED_TOGETHER``).  Tested in
    ``test_ident_candidates.py::test_rivals_the_data_cannot_tell_apart_are_not_named``."""
    good = [e for e in evs if e.accepted]
    if not good:
        return None
    best = min(good, key=lambda e: e.heldout_rmse)
    tie = tied(evs, best)
    both = [e for e in good if tie is not None
            and set(best.effects) | set(tie.effects) <= set(e.effects)]
    if both:
        pair = min(both, key=lambda e: e.heldout_rmse)
        best.reason += f"; named together with {tie.effects[-1]} ({'+'.join(pair.effects)})"
        best.codes.append(Reason.NAMED_TOGETHER)
        return pair
    if tie is not None:
        best.accepted = False
        best.reason += (f"; not named: {'+'.join(tie.effects)} (refused) fits the held-out "
                        f"windows as well ({1e3 * tie.heldout_rmse:.3f} against "
                        f"{1e3 * best.heldout_rmse:.3f} mrad), so the data do not tell the two "
                        f"apart")
        best.codes.append(Reason.TIE)
        return None
    return best


def optimum_not_effect(current: Evaluation, best: Evaluation, check: Evaluation,
                       min_gain: float = 0.10) -> Finding | None:
    """Code ``BETTER_OPTIMUM`` when ``best`` (the current model plus effects) owes its gain
    to a better optimum of the current model, else None.  ``check`` is the current model
    refitted from where ``best``'s fit ended.  When ``check``'s pooled free-run error on
    its own trials [rad/s] is below ``current``'s, ``best`` must still be half of
    ``min_gain`` [1] below ``check``.  Values: ``without``, ``with`` [rad/s], ``effects``.
    Tested in ``test_ident_candidates.py::test_a_gain_that_a_restart_...``."""
    without, with_it = pooled_rmse(check.sim_fitted), pooled_rmse(best.sim_fitted)
    if without >= pooled_rmse(current.sim_fitted) or with_it <= (1.0 - 0.5 * min_gain) * without:
        return None
    added = best.effects[len(current.effects):]
    return Finding(Reason.BETTER_OPTIMUM,
                   f"the model without it, refitted from where this fit ended, simulates the "
                   f"trials it was fitted to as well ({without:.4f} against {with_it:.4f} "
                   f"rad/s; need {50 * min_gain:.0f} % lower with it): the gain came from a "
                   f"better optimum of the current model, not from {'+'.join(added)}",
                   {"without": without, "with": with_it, "effects": added})


def poorer_optimum(current: Evaluation, refused: Evaluation, check: Evaluation,
                   min_gain: float = 0.10) -> Finding | None:
    """Code ``POORER_OPTIMUM`` when ``check`` (the current model refitted from where the
    ``refused`` refit ended) simulates its trials better than ``current`` by half of
    ``min_gain`` [1] or more (pooled free-run error [rad/s]), else None.  Values:
    ``without``, ``before`` [rad/s], ``effect``.  Tested in
    ``test_ident_candidates.py::test_a_refused_refit_that_shows_a_better_optimum_...``."""
    without, before = pooled_rmse(check.sim_fitted), pooled_rmse(current.sim_fitted)
    if not without <= (1.0 - 0.5 * min_gain) * before:
        return None
    return Finding(Reason.POORER_OPTIMUM,
                   f"refitted from where this fit ended, without {refused.effects[-1]}, the "
                   f"current model simulates the trials it was fitted to better ({without:.4f} "
                   f"against {before:.4f} rad/s; need {50 * min_gain:.0f} % lower): it sat in "
                   f"a poorer optimum of itself",
                   {"without": without, "before": before, "effect": refused.effects[-1]})


def near_misses(ident: Identification) -> list[Evaluation]:
    """The refits turned away at the free-run bar alone, best first: in the last round (which
    added nothing), refused refits with plausible values, Wald p under :data:`WALD_P`, a
    held-out window RMSE and a fitted free-run error below the final model's, and a held-out
    simulation error below the final model's by at least half of ``ident.min_gain`` [1] but
    less than all of it.  [] when the last round added an effect.  Tested in
    ``test_ident_candidates.py::test_near_misses_are_the_refits_only_the_free_run_bar_...``."""
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
