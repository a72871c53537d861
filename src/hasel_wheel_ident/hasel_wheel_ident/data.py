"""Trials for identification: one recording of one wheel, from a CSV file or a bag.

A :class:`Trial` holds per-sample arrays, SI units, angles in radians:

=========  ==========================================================================
t          sample time [s], strictly increasing
angle      wheel angle xi1 [rad], unwrapped
q          1 while the actuator of interest is on, else 0
eta        actuator of interest 0..15 (driven, or in contact)
n_a        target actuator of the command in effect, -1 when none is scheduled
phi_a      activation angle of the command in effect [rad] (nan when none)
phi_d      deactivation angle of the command in effect [rad] (nan when none)
speed      measured speed [rad/s], optional (motion capture); None when absent
=========  ==========================================================================

and where the trial sits in its session (:mod:`.session`): ``session_start``, the session
time [s] at t[0] (None when unknown), and ``prior``, the switch-ons the wheel went through
before t[0] (in the trial's own clock), from which effects with memory (retained charge)
start.

From these it derives the unwrapped sector of the actuator of interest, the activations
(runs of q = 1, each with its pad and angles) and the coast-down segments (no actuator
scheduled and none on).
"""
from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hasel_wheel_sim.model import N_ACTUATORS, SECTOR

#: CSV columns: required, and optional.
CSV_REQUIRED = ("t", "angle", "q", "eta", "n_a", "phi_a", "phi_d")
CSV_OPTIONAL = ("speed", "session_t")
#: A coast-down segment must last at least this long [s] to be used for friction.
MIN_COAST = 1.0
#: Glitch rejection: a sample further than this from the line through its neighbours [rad].
GLITCH = 0.05


class TrialError(ValueError):
    """A trial's data is unusable; the message names the file, row and column at fault."""


@dataclass
class Activation:
    """One switch-on of one actuator: samples [start, stop) have q = 1."""

    start: int
    stop: int
    eta: int          # unwrapped sector index
    phi_a: float      # [rad]
    phi_d: float      # [rad]


@dataclass
class Trial:
    """One recording (see the module docstring for the arrays)."""

    name: str
    t: np.ndarray
    angle: np.ndarray
    q: np.ndarray
    eta: np.ndarray
    n_a: np.ndarray
    phi_a: np.ndarray
    phi_d: np.ndarray
    speed: np.ndarray | None = None
    source: str = ""
    #: session time [s] at t[0]; None when the recording does not say
    session_start: float | None = None
    #: (k, 3) switch-ons before t[0], in the clock of t: (on [s], off [s], pad 0..15)
    prior: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    #: the trial's friction over the model's tau_f [1]: 1 unless the coast-downs show
    #: friction changing along the session (:func:`~.friction_trend.along_the_trend`)
    friction_scale: float = 1.0
    eta_unwrapped: np.ndarray = field(init=False)
    activations: list[Activation] = field(init=False)
    coasts: list[tuple[int, int]] = field(init=False)

    def __post_init__(self) -> None:
        where = self.source or self.name
        # one memory layout for the compiled simulators (a column of a table is strided)
        self.t = np.ascontiguousarray(self.t, dtype=float)
        n = self.t.shape[0]
        for k in ("angle", "q", "eta", "n_a", "phi_a", "phi_d"):
            if getattr(self, k).shape != (n,):
                raise TrialError(f"{where}: column {k} has shape {getattr(self, k).shape}, "
                                 f"expected ({n},) like t")
        if n < 30:
            raise TrialError(f"{where}: {n} samples; a trial needs at least 30")
        dt = np.diff(self.t)
        if not np.all(dt > 0):
            k = int(np.argmax(dt <= 0)) + 1
            # sample k is CSV row k + 2 (row 1 is the header)
            raise TrialError(f"{where}: row {k + 2}, column t: time {float(self.t[k])!r} s is "
                             f"not after the previous {float(self.t[k - 1])!r} s (t must "
                             f"increase)")
        self.angle = unwrap_angle(self.t, self.angle)
        # the pad's turn is read from the angle: one glitched count must not move it a turn
        self.eta_unwrapped = unwrap_eta(bridged_angle(self.t, self.angle), self.eta,
                                        self.phi_a, self.phi_d, self.q)
        self.activations = find_activations(self)
        self.coasts = find_coasts(self)
        self.prior = np.asarray(self.prior, dtype=float).reshape(-1, 3)

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0])

    @property
    def sample_time(self) -> float:
        """Median sample interval [s]."""
        return float(np.median(np.diff(self.t)))

    def switch_ons(self, end: int | None = None) -> np.ndarray:
        """(k, 3) the switch-ons of samples [0, end) (all when None) in the clock of t:
        (on [s], off [s], pad 0..15).  Sample k's q holds until t[k + 1]; a run of q = 1
        changes pad where eta_unwrapped does (:func:`on_intervals`)."""
        stop = self.t.shape[0] if end is None else end
        return on_intervals(self.t[:stop + 1], self.q[:stop],
                            self.eta_unwrapped[:stop] % N_ACTUATORS)

    def slice(self, a: int, b: int, name: str | None = None) -> "Trial":
        """Samples [a, b) as a trial of its own; the switch-ons before a join its ``prior``."""
        start = None if self.session_start is None else self.session_start + float(
            self.t[a] - self.t[0])
        prior = np.concatenate([self.prior, self.switch_ons(a)]) if a > 0 else self.prior
        return Trial(name or f"{self.name}[{a}:{b}]", self.t[a:b], self.angle[a:b], self.q[a:b],
                     self.eta[a:b], self.n_a[a:b], self.phi_a[a:b], self.phi_d[a:b],
                     None if self.speed is None else self.speed[a:b], self.source, start, prior,
                     self.friction_scale)


def on_intervals(t: np.ndarray, q: np.ndarray, pad: np.ndarray) -> np.ndarray:
    """(k, 3) the runs of q = 1 as (on [s], off [s], pad): ``q``, ``pad`` (n,) per sample,
    ``t`` (n,) or (n + 1,) the sample times (with n + 1, the time at which sample n - 1's q
    ends; with n, the last sample's q ends one median interval after it).  A run ends where
    q falls or the pad changes."""
    n = q.shape[0]
    if n == 0:
        return np.zeros((0, 3))
    tt = t if t.shape[0] > n else np.append(t, t[-1] + (np.median(np.diff(t)) if n > 1 else 0.0))
    on = q.astype(bool)
    edge = np.empty(n, dtype=bool)
    edge[0] = on[0]
    edge[1:] = on[1:] & (~on[:-1] | (pad[1:] != pad[:-1]))
    starts = np.flatnonzero(edge)
    end = np.empty(n, dtype=bool)
    end[-1] = on[-1]
    end[:-1] = on[:-1] & (~on[1:] | (pad[1:] != pad[:-1]))
    stops = np.flatnonzero(end) + 1
    return np.column_stack([tt[starts], tt[stops], pad[starts].astype(float)])


def hv_time(tr: Trial) -> np.ndarray:
    """(n,) accumulated HV on-time [s] of the actuator of interest at each sample: the time
    each actuator has held HV so far, in the session (the trial's ``prior`` switch-ons
    first; from the trial's start when it has none)."""
    pad = tr.eta_unwrapped % N_ACTUATORS
    acc = np.bincount(tr.prior[:, 2].astype(np.int64), weights=tr.prior[:, 1] - tr.prior[:, 0],
                      minlength=N_ACTUATORS).astype(float)
    out = np.zeros(tr.t.shape[0])
    dt = np.diff(tr.t, append=tr.t[-1])
    for k in range(tr.t.shape[0]):
        out[k] = acc[pad[k]]
        if tr.q[k]:
            acc[pad[k]] += dt[k]
    return out


def clean_mask(t: np.ndarray, y: np.ndarray, tol: float = GLITCH,
               modulo: float | None = None) -> np.ndarray:
    """False at isolated glitches: samples off the line through both neighbours by > tol [rad].

    The first and the last sample have one neighbour: each is judged on the line through the
    two samples next to it, extrapolated one step.  A glitched first reading had been kept:
    its speed spike (-36 rad/s) and the start it gave the free run made a trial's simulation
    error 0.94 rad/s for the true model as for the nominal one (3 x 34 s, 0.2 % glitches, a
    sensor eccentricity, plant seed 6968; ``benchmarks/sweep_ident.py``), and nothing could
    be named.  A glitch next to an end flags that end as well, which only leaves out one
    more sample.

    With ``modulo`` (2 pi), angles are compared modulo it: a reading a whole turn off the line
    (an unwrapping slip) is not a glitch, so wrapped readings can be checked too."""
    ok = np.ones(y.shape[0], dtype=bool)
    if y.shape[0] < 3:
        return ok
    w = (t[1:-1] - t[:-2]) / (t[2:] - t[:-2])
    ok[1:-1] = np.abs(_off_line(y[1:-1], y[:-2], y[2:], w, modulo)) <= tol
    if y.shape[0] < MIN_END_CHECK:
        return ok
    for i, j, k in ((0, 1, 2), (-1, -2, -3)):           # the ends, on the next two samples
        w_end = (t[i] - t[j]) / (t[k] - t[j])
        ok[i] = abs(_off_line(y[i], y[j], y[k], w_end, modulo)) <= tol
    return ok


#: The fewest readings whose ends :func:`clean_mask` judges: in fewer, one glitch next to both
#: ends could leave fewer than two clean samples to bridge or unwrap along.
MIN_END_CHECK = 5


def _off_line(y, a, b, w, modulo: float | None):
    """How far ``y`` lies off the line through ``a`` (w = 0) and ``b`` (w = 1) at ``w``
    (arrays or floats, [rad]); modulo ``modulo`` when given."""
    if modulo is None:
        return y - (a + w * (b - a))
    return _wrap(y - a - w * _wrap(b - a, modulo), modulo)


def _wrap(x: np.ndarray, period: float) -> np.ndarray:
    """x reduced to [-period/2, period/2)."""
    return (x + 0.5 * period) % period - 0.5 * period


#: Longest sample gap [s] across which an unwrapped recording's own step is taken as it is.
UNWRAP_GAP = 0.1


def unwrap_angle(t: np.ndarray, angle: np.ndarray, tol: float = GLITCH) -> np.ndarray:
    """The wheel angle (n,) [rad], unwrapped, of readings (n,) [rad] that are wrapped or already
    unwrapped, counting turns over the clean samples only.

    ``np.unwrap`` alone takes every step as the shorter way round.  A glitched reading
    about half a turn from the truth makes the step back to the truth ambiguous, and one
    wrong choice moves every later sample by a whole turn (seen on simulated recordings with
    0.1 % glitches: a trial's free run then went wrong by 2.7 rad/s).  A device that unwraps
    its raw counts itself can make the same slip, which leaves a one-turn step in an
    otherwise unwrapped recording.  Here the glitches are found modulo a turn
    (:func:`clean_mask`), the turns are counted along the clean samples (each step taken
    modulo a turn, as the shorter way round; in a recording that is already unwrapped, a
    step across a gap longer than ``UNWRAP_GAP`` keeps its own size, since the wheel may
    have turned that far), and each rejected sample goes on the turn nearest the clean path.
    """
    a = np.asarray(angle, dtype=float)
    if a.shape[0] < 3:
        return np.unwrap(a)
    two_pi = 2.0 * math.pi
    ok = clean_mask(t, a, tol, modulo=two_pi)
    tc, ac = t[ok], a[ok]
    step = np.diff(ac)
    short = _wrap(step, two_pi)
    already = float(np.ptp(a)) > two_pi + tol          # the readings are not wrapped
    keep = already & (np.diff(tc) > UNWRAP_GAP)
    path = ac[0] + np.concatenate(([0.0], np.cumsum(np.where(keep, step, short))))
    ref = path if ok.all() else np.interp(t, tc, path)
    # whole turns only: a reading keeps its own value up to the turns it was missing
    return a + two_pi * np.round((ref - a) / two_pi)


def bridged_angle(t: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """``angle`` (n,) [rad] with the samples :func:`clean_mask` rejects replaced by linear
    interpolation between their clean neighbours, or at either end by the least-squares line
    through the :data:`END_FIT` clean samples nearest it (the same array when none is
    rejected)."""
    ok = clean_mask(t, angle)
    if ok.all():
        return angle
    tc, ac = t[ok], angle[ok]
    out = np.interp(t, tc, ac)
    if tc.shape[0] >= 2:
        for end, near in ((t < tc[0], slice(0, END_FIT)), (t > tc[-1], slice(-END_FIT, None))):
            if end.any():
                slope, icpt = np.polyfit(tc[near] - tc[near][0], ac[near], 1)
                out[end] = icpt + slope * (t[end] - tc[near][0])
    return out


#: Clean samples a rejected end reading is extrapolated from (:func:`bridged_angle`): a line
#: through the two nearest would carry a count's step (6 mrad in 3.3 ms, 1.8 rad/s).
END_FIT = 8


def unwrap_eta(angle: np.ndarray, eta: np.ndarray, phi_a: np.ndarray, phi_d: np.ndarray,
               q: np.ndarray) -> np.ndarray:
    """Unwrapped sector N = eta + 16 k (n,) nearest to where the contact happens.

    While an actuator is on its contact angle xi1 - N pi/8 lies between phi_a and phi_d
    (within +-pi/8), so N is the multiple that puts the window's middle nearest the angle.
    """
    mid = np.where(np.isfinite(phi_a) & np.isfinite(phi_d), 0.5 * (phi_a + phi_d), 0.0)
    sector = (angle - mid) / SECTOR
    k = np.round((sector - eta) / N_ACTUATORS)
    return (eta + N_ACTUATORS * k).astype(np.int64)


def find_activations(tr: Trial) -> list[Activation]:
    """Runs of q = 1 on one pad, with the pad and the angles of their first sample.

    A run also ends where the pad changes with q = 1 on both sides: the q = 0 samples
    between two pads were lost (a dropped USB frame; at speed with a small phi_a there is
    only one), and both pads were driven.

    A pad can switch on after the host has cleared its schedule (empty angles, n_a = -1):
    the wheel still held the last command it was sent (the command link has a delay).  Its
    angles are then those of the last row that has them.
    """
    q = tr.q.astype(bool)
    eta = tr.eta_unwrapped
    same = np.concatenate(([False], q[1:] & q[:-1] & (eta[1:] == eta[:-1]), [False]))
    starts = np.flatnonzero(q & ~same[:-1])
    stops = np.flatnonzero(q & ~same[1:]) + 1
    given = np.isfinite(tr.phi_a) & np.isfinite(tr.phi_d)
    last = np.maximum.accumulate(np.where(given, np.arange(given.shape[0]), -1))
    out = []
    for a, b in zip(starts, stops):
        if last[a] < 0:
            raise TrialError(f"{tr.source or tr.name}: row {a + 2}: q = 1 but phi_a / phi_d are "
                             f"empty here and in every row before; an active actuator needs the "
                             f"angles it was commanded with")
        pa, pd = float(tr.phi_a[last[a]]), float(tr.phi_d[last[a]])
        out.append(Activation(int(a), int(b), int(tr.eta_unwrapped[a]), pa, pd))
    return out


#: How far a wheel at rest may read from where it stopped [rad]: two counts of the 10-bit
#: encoder (6.1 mrad each) plus noise.
REST_BAND = 0.015


def rest_start(t: np.ndarray, angle: np.ndarray, band: float = REST_BAND) -> int | None:
    """Index into ``angle`` (n,) [rad] of the first sample of the rest that ends the record:
    from there to the end the angle stays within ``band`` [rad].  0 when the whole record is
    at rest; None when it does not end at rest (fewer than two samples in the band).

    The band is judged on the samples within ``band`` of the line through their neighbours
    (:func:`clean_mask` at that tolerance; the last one, within ``band`` of the median of
    the last three): a glitched reading at rest (a random count, as a faulty encoder gives)
    would otherwise end the rest early.  A stopped wheel whose count flickers between two
    neighbours stays at rest here, where "no count change" would end the rest at the last
    flicker."""
    n = angle.shape[0]
    ok = clean_mask(t, angle, tol=band)
    if n >= 3:
        ok[-1] = abs(angle[-1] - np.median(angle[-3:])) <= band
    clean = np.flatnonzero(ok)
    if clean.size == 0:
        return None
    rev = angle[clean][::-1]
    spread = np.maximum.accumulate(rev) - np.minimum.accumulate(rev)
    if not (spread > band).any():
        return 0
    still = int(np.argmax(spread > band))        # clean samples at the end within the band
    if still <= 1:
        return None
    return int(clean[clean.size - still])


def find_coasts(tr: Trial, min_duration: float = MIN_COAST) -> list[tuple[int, int]]:
    """Coast-down segments [a, b): nothing scheduled (n_a = -1), nothing on, wheel moving.

    A segment ends where the wheel comes to rest (:func:`rest_start`; the first sample at
    rest is the last one kept): the samples at rest after it would pull the fitted
    deceleration towards zero."""
    idle = (tr.n_a < 0) & (tr.q == 0)
    edges = np.flatnonzero(np.diff(np.concatenate(([False], idle, [False])).astype(np.int8)))
    out = []
    for a, b in zip(edges[::2], edges[1::2]):
        rest = rest_start(tr.t[a:b], tr.angle[a:b])
        if rest == 0:
            continue                              # it never moved
        last = b if rest is None else a + rest + 1
        if tr.t[last - 1] - tr.t[a] >= min_duration:
            out.append((int(a), int(last)))
    return out


# -- CSV --------------------------------------------------------------------------------------
def read_csv(path: str | Path) -> Trial:
    """Read one trial from a CSV file with a header row (columns in any order).

    Columns: t [s], angle [rad], q (0/1), eta (0..15), n_a (0..15, or -1 when no actuator is
    scheduled), phi_a [rad], phi_d [rad] (empty when n_a = -1), optional speed [rad/s] and
    session_t [s] (when the row ran in the session, on the clock of t: it places the trial
    in its session, :mod:`.session`).
    Raises :class:`TrialError` naming the row (1 = header) and column at fault.
    """
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise TrialError(f"{path}: cannot read: {exc.strerror}") from None
    rows = list(csv.reader(text.splitlines()))
    if not rows:
        raise TrialError(f"{path}: empty file; expected a header row with {list(CSV_REQUIRED)}")
    header = [h.strip() for h in rows[0]]
    missing = [c for c in CSV_REQUIRED if c not in header]
    if missing:
        raise TrialError(f"{path}: row 1 (header): missing column(s) {missing}; found {header}; "
                         f"expected {list(CSV_REQUIRED)} plus optional {list(CSV_OPTIONAL)}")
    unknown = [h for h in header if h not in CSV_REQUIRED + CSV_OPTIONAL]
    if unknown:
        raise TrialError(f"{path}: row 1 (header): unknown column(s) {unknown}; expected "
                         f"{list(CSV_REQUIRED)} plus optional {list(CSV_OPTIONAL)}")
    dup = sorted({h for h in header if header.count(h) > 1})
    if dup:
        raise TrialError(f"{path}: row 1 (header): column(s) {dup} appear more than once")
    col = {h: i for i, h in enumerate(header)}
    cols = [c for c in CSV_REQUIRED + CSV_OPTIONAL if c in col]
    data = {c: [] for c in cols}
    for r, row in enumerate(rows[1:], start=2):
        if not row or all(not x.strip() for x in row):
            continue
        if len(row) != len(header):
            raise TrialError(f"{path}: row {r}: {len(row)} fields, the header has {len(header)}")
        vals = {c: row[col[c]].strip() for c in cols}
        scheduled = True
        for c in cols:
            v = vals[c]
            where = f"{path}: row {r}, column {c}"
            if c in ("q", "eta", "n_a"):
                try:
                    x = int(float(v))
                    if x != float(v):
                        raise ValueError
                except ValueError:
                    raise TrialError(f"{where}: {v!r} is not an integer") from None
                lo, hi = {"q": (0, 1), "eta": (0, 15), "n_a": (-1, 15)}[c]
                if not lo <= x <= hi:
                    raise TrialError(f"{where}: {x} is outside {lo}..{hi}")
                if c == "n_a":
                    scheduled = x >= 0
                data[c].append(x)
                continue
            if v == "" and c in ("phi_a", "phi_d", "speed", "session_t"):
                data[c].append(math.nan)
                continue
            try:
                x = float(v)
            except ValueError:
                raise TrialError(f"{where}: {v!r} is not a number") from None
            if not math.isfinite(x):
                raise TrialError(f"{where}: {v!r} is not finite")
            if c in ("phi_a", "phi_d") and abs(x) > SECTOR + 1e-9:
                raise TrialError(f"{where}: {x!r} rad is outside [-pi/8, pi/8] (did you write "
                                 f"degrees? angles are in radians)")
            data[c].append(x)
        if scheduled and (math.isnan(data["phi_a"][-1]) or math.isnan(data["phi_d"][-1])):
            raise TrialError(f"{path}: row {r}, column phi_a/phi_d: empty although n_a = "
                             f"{data['n_a'][-1]} schedules an actuator")
        if data["q"][-1] == 1 and not scheduled and math.isnan(data["phi_a"][-1]):
            raise TrialError(f"{path}: row {r}, column n_a: -1 (nothing scheduled) but q = 1 "
                             f"and no phi_a / phi_d for the active actuator")
    if len(data["t"]) < 30:
        raise TrialError(f"{path}: {len(data['t'])} data rows; a trial needs at least 30")
    a = {c: np.asarray(v, dtype=float) for c, v in data.items()}
    start = _session_start(path, a["t"], a["session_t"]) if "session_t" in a else None
    return Trial(path.stem, a["t"], a["angle"], a["q"].astype(np.int8), a["eta"].astype(np.int64),
                 a["n_a"].astype(np.int64), a["phi_a"], a["phi_d"], a.get("speed"), str(path),
                 start)


#: How far session_t - t may wander within one file [s]: both count the same seconds.
SESSION_CLOCK_TOL = 1e-3


def _session_start(path: Path, t: np.ndarray, session_t: np.ndarray) -> float:
    """The session time [s] at the first row, from the ``session_t`` column: every row must
    have one, and it must run with t (session_t - t constant within
    :data:`SESSION_CLOCK_TOL`)."""
    bad = np.flatnonzero(~np.isfinite(session_t))
    if bad.size:
        raise TrialError(f"{path}: row {int(bad[0]) + 2}, column session_t: empty; the session "
                         f"time [s] of every row is needed (or leave the column out)")
    off = session_t - t
    k = int(np.argmax(np.abs(off - off[0])))
    if abs(off[k] - off[0]) > SESSION_CLOCK_TOL:
        raise TrialError(f"{path}: row {k + 2}, column session_t: {session_t[k]!r} s does not run "
                         f"with t (session_t - t is {off[k]:.6g} s here, {off[0]:.6g} s in row 2); "
                         f"session_t is the session time [s] of each row, on the clock of t")
    return float(session_t[0])


def write_csv(trial: Trial, path: str | Path) -> None:
    """Write a trial in the CSV format :func:`read_csv` reads (nan angles as empty fields)."""
    cols = list(CSV_REQUIRED) + (["speed"] if trial.speed is not None else []) + (
        ["session_t"] if trial.session_start is not None else [])
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(cols)
        for k in range(trial.t.shape[0]):
            row = [repr(float(trial.t[k])), repr(float(trial.angle[k])), int(trial.q[k]),
                   int(trial.eta[k]), int(trial.n_a[k])]
            row += ["" if math.isnan(x) else repr(float(x)) for x in (trial.phi_a[k], trial.phi_d[k])]
            if trial.speed is not None:
                row.append(repr(float(trial.speed[k])))
            if trial.session_start is not None:
                row.append(repr(float(trial.session_start + (trial.t[k] - trial.t[0]))))
            w.writerow(row)


# -- bags -------------------------------------------------------------------------------------
def read_bag(path: str | Path) -> list[Trial]:
    """Trials from a bag: the recording of each namespace that has ``telemetry`` (and
    ``command``) topics, cut into trials at the rests between them
    (:func:`~.session.split_stream`); each trial's session time is the bag's clock (the
    time its first telemetry message was recorded [s], plus the device time since).

    The command in effect at each sample is the one whose sequence number the telemetry
    reports as latched (``last_command_sequence``), else the latest one recorded at or before
    the sample; samples before any command, or with HV off, have n_a = -1.
    """
    from hasel_wheel_bag import reader
    from hasel_wheel_common import topics
    from hasel_wheel_ident.session import split_stream

    tel: dict[str, list] = {}
    first: dict[str, float] = {}
    cmds: dict[str, dict[int, tuple[int, float, float]]] = {}
    timed: dict[str, list[tuple[float, int, float, float]]] = {}
    tel_suffix = "/" + topics.TELEMETRY.name
    cmd_suffix = "/" + topics.COMMAND.name
    for topic, _t, m in reader.read_messages(path):
        if topic.endswith(tel_suffix):
            ns = topic[: -len(tel_suffix)]
            first.setdefault(ns, _t * 1e-9)
            tel.setdefault(ns, []).append((m.device_time_us * 1e-6, m.angle, m.q, m.eta,
                                           m.last_command_sequence, m.hv_monitor))
        elif topic.endswith(cmd_suffix):
            ns = topic[: -len(cmd_suffix)]
            cmds.setdefault(ns, {})[int(m.sequence)] = (int(m.n_a), float(m.phi_a), float(m.phi_d))
            timed.setdefault(ns, []).append((_t * 1e-9, int(m.n_a), float(m.phi_a),
                                             float(m.phi_d)))
    if not tel:
        raise TrialError(f"{path}: no telemetry topic (…/{topics.TELEMETRY.name}) in this bag")
    out = []
    for ns, rows in sorted(tel.items()):
        arr = np.asarray(rows, dtype=float)
        table = cmds.get(ns, {})
        n_a = np.full(len(rows), -1, dtype=np.int64)
        pa = np.full(len(rows), math.nan)
        pd = np.full(len(rows), math.nan)
        # a command the firmware's own schedule latched carries no host sequence number:
        # then the latest command recorded at or before the sample stands
        by_time = sorted(timed.get(ns, []))
        times = np.array([c[0] for c in by_time])
        for k, seq in enumerate(arr[:, 4].astype(np.int64)):
            if arr[k, 5] <= 0.0:                     # HV off: nothing scheduled
                continue
            if seq in table:
                n_a[k], pa[k], pd[k] = table[seq]
            elif times.size:
                i = int(np.searchsorted(times, arr[k, 0] + 1e-9, side="right")) - 1
                if i >= 0:
                    n_a[k], pa[k], pd[k] = by_time[i][1:]
        name = (Path(path).name + ns.replace("/", "_")) if ns else Path(path).name
        whole = Trial(name, arr[:, 0], arr[:, 1], arr[:, 2].astype(np.int8),
                      arr[:, 3].astype(np.int64), n_a, pa, pd, None, f"{path}{ns or ''}",
                      first[ns])
        out.extend(split_stream(whole))
    return out


def separate_wheels(path: str | Path) -> str | None:
    """A warning when the bag at ``path`` records several wheels rather than runs of one
    (``hasel_wheel demo --wheels N`` without ``--same-wheel``, read from its recorded
    configuration: ``wheels`` > 1 and ``same_wheel`` not "true"; bags from before that flag
    had only separate wheels), else None.  Each such wheel draws its own actuator gains, and
    the identification fits one wheel to all its trials."""
    from hasel_wheel_bag import reader

    cfg = reader.bag_configuration(path)
    try:
        wheels = int(cfg.get("wheels", "1"))
    except ValueError:
        return None
    if wheels < 2 or cfg.get("same_wheel", "false") == "true":
        return None
    return (f"{path} records {wheels} separate wheels (hasel_wheel demo --wheels {wheels} "
            f"without --same-wheel), each with actuator gains of its own, and they are "
            f"identified as one wheel; record runs of one wheel with --same-wheel")


def load_trials(paths: list[str | Path]) -> list[Trial]:
    """Trials from CSV files, bag directories or .mcap files (a bag may hold several)."""
    out: list[Trial] = []
    for p in paths:
        p = Path(p)
        if p.suffix.lower() == ".csv":
            out.append(read_csv(p))
        elif p.is_dir() or p.suffix.lower() == ".mcap":
            out.extend(read_bag(p))
        else:
            raise TrialError(f"{p}: not a .csv file, a bag directory or a .mcap file")
    names = [t.name for t in out]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise TrialError(f"trial names must be unique, got {dup} more than once")
    return out
