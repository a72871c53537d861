"""Candidate effects and the search's rules: the plausibility test of a fitted gain spread
against its closed form, the signature-sizing term, and which screened candidates are
refitted."""
import math

import numpy as np
import pytest

from hasel_wheel_ident import candidates as C
from hasel_wheel_ident.reasons import Reason


def _params(log_gains: np.ndarray) -> np.ndarray:
    """The candidate's 15 free parameters d_1..d_15 for 16 log-gains (their mean removed)."""
    d = log_gains - log_gains.mean()
    return d[1:]


def test_a_once_per_turn_gain_pattern_is_named_with_its_harmonic():
    i = np.arange(16)
    k, share, p = C.spread_pattern(_params(0.2 * np.cos(2 * math.pi * i / 16 + 0.3)))
    assert (k, share) == (1, pytest.approx(1.0))
    assert p < 1e-12
    k, share, p = C.spread_pattern(_params(0.1 * np.sin(2 * math.pi * 3 * i / 16)))
    assert (k, share) == (3, pytest.approx(1.0))
    why = C.BY_ID["gain_spread"].implausible(_params(0.2 * np.cos(2 * math.pi * i / 16)))
    assert why is not None              # the pattern above: one harmonic holds it all


def test_a_wheels_gains_in_the_spread_candidates_terms_give_them_back():
    # gains 2^(k/8) over the pads: geometric mean 2^(15/16), and the candidate (whose gains
    # have a geometric mean of 1) times that mean returns them
    gains = 2.0 ** (np.arange(16) / 8.0)
    mean, logs = C.spread_values(gains)
    assert mean == pytest.approx(2.0 ** (15 / 16))
    assert logs["d1"] == pytest.approx(math.log(2) * (1 / 8 - 15 / 16))
    x = [logs[f"d{i}"] for i in range(1, 16)]
    np.testing.assert_allclose(mean * np.array(C.BY_ID["gain_spread"].describe(x)["gains"]),
                               gains, rtol=1e-12)
    with pytest.raises(ValueError, match="expected 16 positive gains"):
        C.spread_values([1.0] * 15 + [0.0])


def test_independent_gains_share_their_variance_as_the_beta_law_says():
    # under independence the first harmonic's share is Beta(1, 13/2): P(share > s) = (1-s)^6.5
    rng = np.random.default_rng(7)
    draws = rng.normal(0.0, 0.08, (20000, 16))
    d = draws - draws.mean(axis=1, keepdims=True)
    power = np.abs(np.fft.rfft(d, axis=1)[:, 1:]) ** 2
    power[:, :-1] *= 2
    share1 = power[:, 0] / power.sum(axis=1)
    for s in (0.2, 0.4, 0.6):
        assert np.mean(share1 > s) == pytest.approx((1 - s) ** 6.5, rel=0.1, abs=2e-4)
    # and the test refuses at most its nominal rate (a union bound: p is conservative)
    p = np.array([C.spread_pattern(_params(g))[2] for g in draws[:5000]])
    assert np.mean(p < C.SPREAD_PATTERN_P) <= C.SPREAD_PATTERN_P * 1.5
    assert C.BY_ID["gain_spread"].implausible(_params(draws[0])) is None


def test_the_signature_term_is_the_torque_it_names():
    from hasel_wheel_ident import periodic
    from hasel_wheel_ident.residual import Signature
    from hasel_wheel_sim.model import external_torque, param_vector
    from hasel_wheel_sim.params import WheelParams
    base = WheelParams()
    # a pivot-lap signature: period 2 pi in psi = (r/L) xi1, so k = r/L per rad of xi1
    sig = Signature("pivot_angle", "rad", 2 * math.pi, 0.1, 0.002, 1e-9, "periodic in ...")
    assert periodic.frequency(sig, base) == pytest.approx(base.r / base.L)
    sig = Signature("wheel_angle", "rad", 2 * math.pi / 3, 0.1, 0.002, 1e-9, "periodic in ...")
    assert periodic.frequency(sig, base) == pytest.approx(3.0)
    assert periodic.frequency(Signature("speed", "rad/s", None, 0.1, 0.002, 1e-9, ""), base) is None
    term = periodic.periodic_torque(2.5)
    pv = param_vector(base)
    term.apply(np.array([0.003, -0.001]), pv, {})
    for xi1 in (0.0, 0.7, 4.0, 123.4):
        assert external_torque(xi1, 1.0, pv) == pytest.approx(
            0.003 * math.sin(2.5 * xi1) - 0.001 * math.cos(2.5 * xi1), abs=1e-15)


def _scores(*rows):
    """Screenings from (candidate, log10 p, predicted window RMSE [rad]) rows."""
    from hasel_wheel_ident.screen import Screening
    return [Screening(c, 1, 0.0, 10.0 ** lp, lp, rmse, {}) for c, lp, rmse in rows]


def test_one_leader_is_refitted_alone_and_rivals_all():
    from hasel_wheel_ident.refit_plan import refit_order
    rmse = 1e-3
    # far ahead of the rest (more than twice as significant): alone, refits stop at it
    order, rivals = refit_order(_scores(("com_offset", -300, 0.5e-3), ("gain_spread", -40, 0.99e-3),
                                        ("viscous_drag", -2, 1e-3)), rmse)
    assert [s.candidate for s in order] == ["com_offset"] and not rivals
    # the 40 ms rise lag beside charge retention (-42 against -83, -26 next): none leads,
    # both go on as rivals, the lower predicted error first
    order, rivals = refit_order(_scores(("rise_lag", -42.2, 0.2957e-3),
                                        ("charge_retention", -83.0, 0.2927e-3),
                                        ("angle_offset", -26.3, 0.2968e-3)), 0.299e-3)
    assert [s.candidate for s in order] == ["charge_retention", "rise_lag"] and rivals
    # a tied pair far ahead of the rest: both, as rivals
    order, rivals = refit_order(_scores(("rise_lag", -60, 0.97e-3), ("charge_retention", -70, 0.98e-3),
                                        ("viscous_drag", -5, 1e-3)), rmse)
    assert {s.candidate for s in order} == {"rise_lag", "charge_retention"} and rivals
    # nothing significant (p >= 1e-6): nothing is refitted, whatever it predicts
    order, _ = refit_order(_scores(("platform_periodic", -5.9, 0.5e-3), ("com_offset", -3, 0.9e-3)),
                           rmse)
    assert order == []


def _ev(effect, window_rmse, accepted, plausible=True):
    from hasel_wheel_ident.evaluation import Evaluation
    return Evaluation((effect,), None, window_rmse, {}, accepted=accepted, plausible=plausible,
                      reason="r")


def test_rivals_the_data_cannot_tell_apart_are_not_named():
    from hasel_wheel_ident.acceptance import pick
    # the accepted rival with the lower held-out window error joins
    a, b = _ev("rise_lag", 0.288e-3, True), _ev("charge_retention", 0.293e-3, True)
    assert pick([b, a]) is a and a.accepted and a.codes == []
    # a refused rival that fits the held-out windows better: neither is named
    a, b = _ev("rise_lag", 0.285e-3, True), _ev("charge_retention", 0.283e-3, False)
    assert pick([b, a]) is None
    assert not a.accepted and a.codes == [Reason.TIE]
    # ... unless it was refused as implausible (a gain pattern that imitates a torque)
    a, b = _ev("com_offset", 0.30e-3, True), _ev("gain_spread", 0.29e-3, False, plausible=False)
    assert pick([b, a]) is a
    # a refused rival that fits worse does not stand in the way
    a, b = _ev("rise_lag", 0.288e-3, True), _ev("charge_retention", 0.293e-3, False)
    assert pick([a, b]) is a
    assert pick([_ev("viscous_drag", 0.3e-3, False)]) is None


def _sim(effects, rmse):
    from hasel_wheel_ident.metrics import TrialMetrics
    from hasel_wheel_ident.evaluation import Evaluation
    # two trials of 100 samples each at the same error: pooled = rmse
    return Evaluation(effects, None, 0.3e-3, {}, sim_fitted={
        n: TrialMetrics(n, rmse, 0.9, 0.05, 0.0, 100) for n in ("a", "b")})


def test_a_gain_that_a_restart_of_the_current_model_also_reaches_is_not_the_effects():
    from hasel_wheel_ident.acceptance import optimum_not_effect
    current = _sim(("gain_spread",), 0.0387)
    best = _sim(("gain_spread", "rise_lag"), 0.0288)
    # the current model refitted from the augmented fit's end: as good -> refused, saying why
    why = optimum_not_effect(current, best, _sim(("gain_spread",), 0.0280))
    assert why.code == Reason.BETTER_OPTIMUM and why.values["effects"] == ("rise_lag",)
    assert (why.values["without"], why.values["with"]) == pytest.approx((0.0280, 0.0288))
    # ... and so while the effect's own gain over the restart is under min_gain / 2 (5 %)
    assert optimum_not_effect(current, best, _sim(("gain_spread",), 0.0302)) is not None
    # the effect cuts the error by more than 5 % against the restart: its gain stands
    assert optimum_not_effect(current, best, _sim(("gain_spread",), 0.0304)) is None
    # the restart found nothing better than the current model: no question arises
    assert optimum_not_effect(current, best, _sim(("gain_spread",), 0.0387)) is None
    # a pair tried together is named whole
    why = optimum_not_effect(_sim((), 0.0387), _sim(("viscous_drag", "rise_lag"), 0.0288),
                             _sim((), 0.0280))
    assert why.code == Reason.BETTER_OPTIMUM
    assert why.values["effects"] == ("viscous_drag", "rise_lag")


def test_a_refused_refit_that_shows_a_better_optimum_of_the_current_model_restarts_it():
    from hasel_wheel_ident.acceptance import poorer_optimum
    current = _sim(("platform_periodic",), 0.1048)
    refused = _sim(("platform_periodic", "gain_spread"), 0.0322)
    # the current model refitted from where the refused refit ended runs the trials better
    # by at least half of min_gain (5 %): it sat in a poorer optimum, and says which refit
    why = poorer_optimum(current, refused, _sim(("platform_periodic",), 0.0303))
    assert why.code == Reason.POORER_OPTIMUM and why.values["effect"] == "gain_spread"
    assert (why.values["without"], why.values["before"]) == pytest.approx((0.0303, 0.1048))
    assert poorer_optimum(current, refused, _sim(("platform_periodic",), 0.0995)) is not None
    # under 5 % better, or worse: no restart
    assert poorer_optimum(current, refused, _sim(("platform_periodic",), 0.0997)) is None
    assert poorer_optimum(current, refused, _sim(("platform_periodic",), 0.2)) is None
    # a refit that did not converge to a number says nothing
    assert poorer_optimum(current, refused, _sim(("platform_periodic",), math.nan)) is None


def _refit(effects, window_rmse, plausible=True):
    import types
    from hasel_wheel_ident.evaluation import Evaluation
    return Evaluation(effects, types.SimpleNamespace(rmse=window_rmse), 0.0, {},
                      plausible=plausible, reason="r")


def test_a_refit_refused_as_a_stand_in_makes_room_for_the_next_candidates():
    from hasel_wheel_ident.refit_plan import further_refits, stood_in
    current = _refit((), 0.770e-3)
    scores = _scores(("angle_eccentricity", -70, 0.4e-3), ("gain_spread", -25, 0.4e-3),
                     ("com_offset", -24, 0.4e-3), ("charge_retention", -3, 0.7e-3))
    done = scores[:2]
    # both refused for their values (a stand-in span by span; gains in a once-per-turn
    # pattern), each having halved the window RMSE: the off-centre mass is refitted next
    evs = [_refit(("angle_eccentricity",), 0.379e-3, plausible=False),
           _refit(("gain_spread",), 0.367e-3, plausible=False)]
    assert all(stood_in(e, current, 0.10) for e in evs)
    assert [s.candidate for s in further_refits(scores, done, evs, current, 0.10, 2)] == [
        "com_offset"]                       # retention is not significant (p >= SCREEN_P)
    # a refused stand-in that did not cut the window RMSE by 5 % says nothing is there
    weak = [_refit(("angle_eccentricity",), 0.74e-3, plausible=False)]
    assert not stood_in(weak[0], current, 0.10)
    assert further_refits(scores, done, weak, current, 0.10, 2) == []
    # refused with plausible values and no window gain either: nothing more
    assert further_refits(scores, done, [_refit(("gain_spread",), 0.76e-3)], current, 0.10,
                          2) == []


def _held_out(effects, window_rmse, sim_rmse, accepted=False, plausible=True, wald_p=0.0,
              fitted=None, values=None):
    import types
    from hasel_wheel_ident.metrics import TrialMetrics
    from hasel_wheel_ident.evaluation import Evaluation

    def two(rmse):      # two trials of 100 samples each at the same error: pooled = rmse
        return {n: TrialMetrics(n, rmse, 0.9, 0.05, 0.0, 100) for n in "ab"}
    # the free run on the trials fitted to: as good as held out unless told
    return Evaluation(effects, types.SimpleNamespace(values=values or {}), window_rmse, {},
                      wald_p=wald_p, accepted=accepted, plausible=plausible, reason="r",
                      sim_heldout=two(sim_rmse), sim_fitted=two(fitted or sim_rmse))


def test_near_misses_are_the_refits_only_the_free_run_bar_turned_away():
    import types
    from hasel_wheel_ident.acceptance import near_misses
    final = _held_out(("com_offset",), 0.300e-3, 0.0400, accepted=True)
    close = _held_out(("com_offset", "rise_lag"), 0.290e-3, 0.0370)       # 7.5 % lower
    closer = _held_out(("com_offset", "viscous_drag"), 0.295e-3, 0.0364)  # 9.0 % lower
    others = [
        _held_out(("com_offset", "gain_spread"), 0.290e-3, 0.0359),        # 10.25 %: the bar
        _held_out(("com_offset", "charge_retention"), 0.290e-3, 0.0370, wald_p=1e-5),
        _held_out(("com_offset", "angle_offset"), 0.290e-3, 0.0370, plausible=False),
        _held_out(("com_offset", "platform_periodic"), 0.301e-3, 0.0370),  # windows worse
        _held_out(("com_offset", "angle_eccentricity"), 0.290e-3, 0.0401),  # free run worse
        _held_out(("com_offset", "angle_eccentricity"), 0.290e-3, 0.0392),  # 2 %: < half
        _held_out(("com_offset", "rise_lag"), math.nan, 0.0370),           # not cross-validated
        # held out 7.5 % lower, but no better than the final model on its own trials: a
        # better optimum of a model that stopped, not the effect's
        _held_out(("com_offset", "gain_spread"), 0.290e-3, 0.0370, fitted=0.0400),
    ]
    ident = types.SimpleNamespace(final=final, rounds=[[final], [close, *others, closer]],
                                  min_gain=0.10)
    assert near_misses(ident) == [closer, close]
    # with a 5 % bar the 7.5 % and 9 % cuts would have passed it: not near misses
    ident.min_gain = 0.05
    assert near_misses(ident) == []
    ident.min_gain = 0.10
    # a last round that added an effect has none (accepted or not, now: a pick may have
    # un-accepted the pair while one alone kept its mark); nor has a search without rounds
    added = _held_out(("com_offset", "rise_lag", "viscous_drag"), 0.2e-3, 0.02)
    ident.rounds[-1].append(added)
    ident.final = added
    assert near_misses(ident) == []
    assert near_misses(types.SimpleNamespace(final=final, rounds=[], min_gain=0.1)) == []


def test_a_near_miss_reads_in_the_report_as_it_was_measured():
    import types
    from hasel_wheel_ident.report_json import near_miss as _near_miss
    from hasel_wheel_ident.report_text import near_miss_text, near_miss_texts
    final = _held_out(("com_offset",), 0.300e-3, 0.0415, accepted=True)
    e = _held_out(("com_offset", "rise_lag"), 0.290e-3, 0.0376,
                  values={"tau": 0.03883, "A": 0.001, "B": 0.002})
    m = _near_miss(e, final, 0.10)
    assert m["ids"] == ["rise_lag"] and m["physical"] == {"rise_lag": {"time_constant_s": 0.03883}}
    assert m["cut"] == pytest.approx(1 - 0.0376 / 0.0415) and m["bar"] == 0.10
    assert m["code"] == Reason.NEAR_MISS
    assert near_miss_text(m) == ("rise_lag (time_constant_s 0.03883): Wald p 0.0e+00, held-out "
                                 "simulation error 0.0415 -> 0.0376 rad/s (9.4 % lower; the "
                                 "bar is 10 %)")
    # the lines the command and the benchmarks print: the same text, from the search itself
    ident = types.SimpleNamespace(final=final, rounds=[[final], [e]], min_gain=0.10)
    assert near_miss_texts(ident) == [near_miss_text(m)]
    ident.min_gain = 0.05                 # a 9.4 % cut passes a 5 % bar: no near miss
    assert near_miss_texts(ident) == []
