"""Where a trial is driven, and how its drive is cut for the refits one by one: its mean
speed while driven (:func:`driven_speed`), spans of it when the trials share their speed
(:func:`speed_spans`, :func:`speed_units`), and its two halves in HV time
(:func:`drive_halves`).  A sample is driven when an actuator is scheduled or on.  Tested in
``test_ident_consistency.py``
(``test_spans_are_cut_between_pushes_only_when_the_trials_share_their_speed``,
``test_a_trial_that_stalls_for_good_is_halved_as_the_fit_sees_it``)."""
from __future__ import annotations

import math

import numpy as np

from hasel_wheel_ident.data import Trial, hv_time

#: Trials whose mean speeds while driven span less than this ratio cannot show a trend with
#: speed: runs of one closed loop through one reference profile all have the same mean.  Then
#: each trial's drive is cut into :data:`SPANS` spans (:func:`speed_spans`), and the spans are
#: refitted one by one in place of the trials, provided their speeds span this ratio.
MIN_SPEED_RATIO = 1.2
SPANS = 6
#: ... but no more spans than leave this many turns of the wheel to each on average, so that
#: a once-per-turn effect is seen over a few turns in every span.
MIN_SPAN_TURNS = 3.0
#: The fewest samples of a span (a :class:`~.data.Trial` needs 30).
MIN_SPAN_SAMPLES = 30
#: The first and second half of a trial's drive are told apart only if the mean accumulated
#: HV time of the driven actuator differs between them by this factor or more.
MIN_HV_RATIO = 1.5

#: ((early span, late span) [s], (mean HV time in each) [s]) of a trial's drive
Halves = tuple[tuple[tuple[float, float], tuple[float, float]], tuple[float, float]]


def driven(tr: Trial) -> np.ndarray:
    """(n,) bool: the samples with an actuator scheduled or on."""
    return tr.q.astype(bool) | (tr.n_a >= 0)


def driven_speed(tr: Trial) -> float:
    """The trial's mean speed [rad/s] while driven: the angle it turns from its first to its
    last sample with an actuator scheduled or on, over that time (the whole trial if none)."""
    on = driven(tr)
    span = tr.t[on] if on.any() else tr.t
    ang = tr.angle[on] if on.any() else tr.angle
    return float((ang[-1] - ang[0]) / max(span[-1] - span[0], 1e-9))


def speed_spans(tr: Trial, n: int = SPANS) -> list[Trial]:
    """The trial's drive (first to last sample with an actuator scheduled or on) cut into
    ``n`` spans of about equal duration, or fewer so that they average
    :data:`MIN_SPAN_TURNS` turns each, each a trial of its own named after its times [s];
    each cut is moved on to the next sample with no actuator on, so no push is cut, and a
    tail under :data:`MIN_SPAN_SAMPLES` joins the span before.  [] when the trial has no
    drive, or one shorter than that."""
    on = np.flatnonzero(driven(tr))
    if on.size == 0:
        return []
    first, end = int(on[0]), int(on[-1]) + 1
    if end - first < MIN_SPAN_SAMPLES:
        return []
    turns = abs(float(tr.angle[end - 1] - tr.angle[first])) / (2 * math.pi)
    cuts = _span_cuts(tr, first, end, max(min(n, int(turns / MIN_SPAN_TURNS)), 1))
    return [tr.slice(a, b, f"{tr.name} {tr.t[a] - tr.t[0]:.0f}-{tr.t[b - 1] - tr.t[0]:.0f} s")
            for a, b in zip(cuts, cuts[1:])]


def _span_cuts(tr: Trial, first: int, end: int, n: int) -> list[int]:
    """The sample indices from ``first`` to ``end`` that cut the drive into ``n`` spans
    (:func:`speed_spans`)."""
    cuts = [first]
    for t_cut in np.linspace(tr.t[first], tr.t[end - 1], n + 1)[1:-1]:
        i = max(int(np.searchsorted(tr.t, t_cut)), cuts[-1] + MIN_SPAN_SAMPLES)
        while i < end and tr.q[i]:
            i += 1
        if i < end:
            cuts.append(i)
    while len(cuts) > 1 and end - cuts[-1] < MIN_SPAN_SAMPLES:
        cuts.pop()                                      # a short tail joins the span before
    cuts.append(end)
    return cuts


def speed_units(trials: list[Trial]) -> list[tuple[int, Trial]]:
    """(trial index, span) of every trial's :func:`speed_spans` when the trials' speeds while
    driven span less than :data:`MIN_SPEED_RATIO` and the spans' speeds span at least that;
    [] otherwise (the trials themselves are the units)."""
    speeds = [driven_speed(tr) for tr in trials]
    if min(speeds) <= 0.0 or max(speeds) >= MIN_SPEED_RATIO * min(speeds):
        return []           # a trial at rest or rolling back: the trials themselves
    spans = [(j, piece) for j, tr in enumerate(trials) for piece in speed_spans(tr)]
    v = [driven_speed(piece) for _, piece in spans]
    if len(spans) < 3 or min(v) <= 0.0 or max(v) < MIN_SPEED_RATIO * min(v):
        return []
    return spans


def drive_halves(tr: Trial) -> Halves | None:
    """((early span, late span) [s], (mean HV time in each) [s]) of the trial: its drive
    (from the first to the last sample with an actuator scheduled or on) cut at the middle.
    The coast is in neither: it would carry much of the information on a torque (a drag, an
    off-centre mass) in one half only.  The HV time is the driven actuator's accumulated
    on-time (:func:`~.data.hv_time`) averaged over the samples where it is on.  None without
    a drive, or when the halves' HV times differ by less than :data:`MIN_HV_RATIO`."""
    on = tr.q.astype(bool)
    if not on.any():
        return None
    t_on = tr.t[driven(tr)]
    mid = 0.5 * (t_on[0] + t_on[-1])
    h = hv_time(tr)
    early, late = on & (tr.t < mid), on & (tr.t >= mid)
    if not early.any() or not late.any():
        return None
    h0, h1 = float(h[early].mean()), float(h[late].mean())
    if h0 <= 0.0 or h1 < MIN_HV_RATIO * h0:
        return None
    end = float(np.nextafter(t_on[-1], math.inf))         # keep's end is exclusive
    return ((-math.inf, mid), (mid, end)), (h0, h1)
