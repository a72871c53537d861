"""The trials of a multiple-shooting fit laid end to end (:func:`lay_out`): every sample's
data concatenated, and each trial cut into windows of about ``window`` seconds that never
cross a trial boundary, with first guesses at their starts (:func:`initial_starts`).
Tested in ``test_ident_fit.py`` and ``test_ident_window_starts.py``."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hasel_wheel_sim.model import N_ACTUATORS

from hasel_wheel_ident.data import Trial, clean_mask


@dataclass
class Layout:
    """The concatenated samples of all trials (each (n,)): time ``t`` [s] in each trial's own
    clock, recorded angle ``y`` [rad], HV switch ``q`` (0/1), contact sector ``eta``
    (unwrapped), each sample's activation angle ``phi_a`` [rad] and time since its switch-on
    ``on_time`` [s], ``ok`` the samples counted in the residual, ``pad`` the pad in contact
    (0..15).  ``starts`` (w + 1,) each window's first sample and the end, ``window_trial``
    (w,) the trial of each window, ``trial_slices`` and ``trial_windows`` each trial's
    samples and windows, ``n`` the number of samples."""

    t: np.ndarray
    y: np.ndarray
    q: np.ndarray
    eta: np.ndarray
    phi_a: np.ndarray
    on_time: np.ndarray
    ok: np.ndarray
    pad: np.ndarray
    starts: np.ndarray
    window_trial: np.ndarray
    trial_slices: list[slice]
    trial_windows: list[range]
    n: int


def activation_columns(tr: Trial) -> tuple[np.ndarray, np.ndarray]:
    """(time since switch-on [s], activation angle [rad]) at every sample of ``tr``, from
    each activation's own angle (:func:`~.data.find_activations`), not the row's: a host logs
    its schedule when it sends it, the wheel's state when it arrives, so with a link delay
    the rows at an activation's end can already carry the next command's angle, and the rows
    after the schedule is cleared have none."""
    m = tr.t.shape[0]
    on_time = np.zeros(m)
    phi_a = np.zeros(m)
    for act in tr.activations:
        on_time[act.start:act.stop] = tr.t[act.start:act.stop] - tr.t[act.start]
        phi_a[act.start:act.stop] = act.phi_a
    return on_time, phi_a


def window_starts(tr: Trial, window: float) -> list[int]:
    """The first sample of each window of ``tr``: windows of ``window`` [s], a tail shorter
    than half a window joining the last."""
    m = tr.t.shape[0]
    out = []
    k = 0
    while k < m - 1:
        kk = int(np.searchsorted(tr.t, tr.t[k] + window))
        if m - kk < 0.5 * window / tr.sample_time:   # a short tail joins
            kk = m
        out.append(k)
        k = kk
    return out


def lay_out(trials: list[Trial], window: float,
            keep: tuple[float, float] | None) -> Layout:
    """The :class:`Layout` of ``trials`` with windows of ``window`` [s]; ``keep`` (t0, t1)
    [s] counts only the samples with t0 <= t < t1 (all when None)."""
    ts, ys, qs, es, pas, ots, oks, starts, owner = [], [], [], [], [], [], [], [], []
    n = 0
    trial_slices: list[slice] = []
    trial_windows: list[range] = []
    for j, tr in enumerate(trials):
        m = tr.t.shape[0]
        on_time, phi_a = activation_columns(tr)
        ts.append(tr.t)
        ys.append(tr.angle)
        qs.append(tr.q.astype(float))
        es.append(tr.eta_unwrapped.astype(float))
        pas.append(phi_a)
        ots.append(on_time)
        ok = clean_mask(tr.t, tr.angle)
        if keep is not None:
            ok &= (tr.t >= keep[0]) & (tr.t < keep[1])
        oks.append(ok)
        w0 = len(starts)
        for k in window_starts(tr, window):
            starts.append(n + k)
            owner.append(j)
        trial_windows.append(range(w0, len(starts)))
        trial_slices.append(slice(n, n + m))
        n += m
    return Layout(np.concatenate(ts), np.concatenate(ys), np.concatenate(qs),
                  np.concatenate(es), np.concatenate(pas), np.concatenate(ots),
                  np.concatenate(oks), np.concatenate(es).astype(np.int64) % N_ACTUATORS,
                  np.asarray(starts + [n], dtype=np.int64), np.asarray(owner),
                  trial_slices, trial_windows, n)


def initial_starts(lay: Layout) -> np.ndarray:
    """(w, 2) window starts from a line through the first 0.1 s of each window: angle [rad]
    and speed [rad/s], the speed no lower than 0."""
    n_windows = lay.starts.shape[0] - 1
    x0 = np.zeros((n_windows, 2))
    for w in range(n_windows):
        a, e = lay.starts[w], lay.starts[w + 1]
        b = max(min(a + int(np.searchsorted(lay.t[a:e], lay.t[a] + 0.1)), e), a + 2)
        ok = lay.ok[a:b] if lay.ok[a:b].sum() >= 2 else np.ones(b - a, dtype=bool)
        p = np.polyfit(lay.t[a:b][ok] - lay.t[a], lay.y[a:b][ok], 1)
        x0[w] = (p[1], max(p[0], 0.0))
    return x0
