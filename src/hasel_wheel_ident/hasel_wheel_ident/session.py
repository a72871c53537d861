"""Trials as one session: the order they ran in, the gaps between them, and the switching
history each one starts from.

A wheel does not reset between trials: charge retained in its pads recovers only partly
in the gap before the next trial.  :func:`as_session` sorts trials by their session time
(``Trial.session_start``, from a bag's clock or a CSV's ``session_t`` column) and gives
each one the switch-ons of the trials before it (``Trial.prior``, in the trial's own
clock), so that an effect with memory starts each trial where the last one left it, by its
own recovery law (:func:`prior_charge`).  :func:`split_stream` cuts one recording of a
whole session into its trials at the rests between them.

Tested in ``test_ident_session.py``.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from hasel_wheel_sim.model import N_ACTUATORS

from hasel_wheel_ident.data import REST_BAND, Trial

#: A rest with HV off at least this long [s] separates two trials of one recording.
MIN_GAP = 5.0


@dataclass(frozen=True)
class SessionEntry:
    """One trial's place in its session: ``start`` [s] of session time at its first sample
    and the ``gap`` [s] since the previous trial's last sample (None for the first, or when
    the session time is unknown)."""

    name: str
    start: float | None
    gap: float | None
    duration: float


@dataclass(frozen=True)
class Session:
    """Trials in session order, with their entries; ``timed`` False when the trials cannot
    be placed in one session (no session time for some or all, or overlapping ones): then
    the order is the order given and ``warning`` says why (None for a single trial)."""

    trials: list[Trial]
    entries: list[SessionEntry]
    timed: bool
    warning: str | None


def as_session(trials: list[Trial]) -> Session:
    """``trials`` in session order, each with the switch-ons of the trials before it as its
    ``prior`` (in its own clock), session times counted from the first trial's start [s].

    Without a session time for every trial, or when trials overlap in session time (several
    wheels recorded side by side), the order given is kept, every trial starts from rest (no
    prior switching) and ``warning`` says why.
    """
    untimed = [tr.name for tr in trials if tr.session_start is None]
    if len(trials) < 2:
        why = None
    elif len(untimed) == len(trials):
        why = "no session time in these recordings"
    elif untimed:
        why = f"no session time for {untimed}"
    else:
        why = _overlap(trials)
    if why is not None or len(untimed) == len(trials):
        entries = [SessionEntry(tr.name, None, None, tr.duration) for tr in trials]
        warning = None if why is None else (
            f"{why}: the trials are taken in the order given, each starting with rested "
            f"actuators (a session_t column, or trials from one bag, carry effects from one "
            f"trial to the next)")
        return Session([replace(tr, prior=np.zeros((0, 3))) for tr in trials], entries, False,
                       warning)
    order = sorted(trials, key=lambda tr: tr.session_start)
    t0 = order[0].session_start
    out: list[Trial] = []
    entries: list[SessionEntry] = []
    history = np.zeros((0, 3))            # switch-ons so far, in session time
    prev_end: float | None = None
    for tr in order:
        start = float(tr.session_start - t0)
        shift = np.array([float(tr.t[0]) - start] * 2 + [0.0])   # session time -> own clock
        out.append(replace(tr, session_start=start, prior=history + shift))
        history = np.concatenate([history, tr.switch_ons() - shift])
        entries.append(SessionEntry(tr.name, start, None if prev_end is None else start - prev_end,
                                    tr.duration))
        prev_end = start + tr.duration
    return Session(out, entries, True, None)


def _overlap(trials: list[Trial]) -> str | None:
    """Words for the first two trials that overlap in session time, or None."""
    order = sorted(trials, key=lambda tr: tr.session_start)
    for a, b in zip(order, order[1:]):
        if b.session_start < a.session_start + a.duration - 1e-6:
            return f"{a.name} and {b.name} overlap in session time"
    return None


def prior_charge(tr: Trial, recovery: float) -> np.ndarray:
    """(16,) the retained charge Q_i [s] of each pad at the trial's first sample, from its
    ``prior`` switch-ons with dQ_i/dt = q_i - Q_i / recovery (``recovery`` [s]), exact: a
    switch-on of d seconds ending s seconds before leaves recovery (1 - e^(-d/recovery))
    e^(-s/recovery).  Zeros without prior switching."""
    out = np.zeros(N_ACTUATORS)
    if tr.prior.shape[0] == 0 or not recovery > 0.0:
        return out
    on, off, pad = tr.prior[:, 0], tr.prior[:, 1], tr.prior[:, 2].astype(np.int64)
    t0 = float(tr.t[0])
    left = recovery * -np.expm1(-(off - on) / recovery) * np.exp(-(t0 - off) / recovery)
    np.add.at(out, pad, left)
    return out


def split_stream(tr: Trial, min_gap: float = MIN_GAP) -> list[Trial]:
    """One recording of a session cut into its trials at the rests between them.

    A rest is a stretch of at least ``min_gap`` [s] with nothing scheduled, no actuator on
    and the wheel within :data:`~.data.REST_BAND` of where it stopped, or a gap of at least
    ``min_gap`` between two samples.  Each trial runs from the end of one rest to the start
    of the next (the first sample at rest is kept, as a coast-down's end); its
    ``session_start`` is ``tr.session_start`` (0 when None) plus its offset into the
    recording.  A recording without such a rest is returned whole, as one trial; pieces of
    fewer than 30 samples are dropped."""
    cuts = _rests(tr, min_gap)
    if not cuts:
        return [tr]
    base = 0.0 if tr.session_start is None else tr.session_start
    pieces = []
    a = 0
    for r0, r1 in cuts + [(tr.t.shape[0], tr.t.shape[0])]:
        if r0 - a >= 30:
            pieces.append((a, r0))
        a = r1
    out = []
    for k, (a, b) in enumerate(pieces, start=1):
        piece = tr.slice(a, b, f"{tr.name}_trial{k}" if len(pieces) > 1 else tr.name)
        out.append(replace(piece, session_start=base + float(tr.t[a] - tr.t[0]),
                           prior=np.zeros((0, 3))))
    return out


def _rests(tr: Trial, min_gap: float) -> list[tuple[int, int]]:
    """[(first sample at rest + 1, first sample after the rest)] of :func:`split_stream`."""
    idle = (tr.n_a < 0) & (tr.q == 0)
    out: list[tuple[int, int]] = []
    n = tr.t.shape[0]
    k = 0
    while k < n:
        if not idle[k]:
            k += 1
            continue
        j = k
        while j + 1 < n and idle[j + 1] and abs(tr.angle[j + 1] - tr.angle[k]) <= REST_BAND:
            j += 1
        if j > k and tr.t[j] - tr.t[k] >= min_gap:
            out.append((k + 1, j + 1))
        elif k + 1 < n and tr.t[k + 1] - tr.t[k] >= min_gap:
            out.append((k + 1, k + 1))
        k = j + 1
    return out
