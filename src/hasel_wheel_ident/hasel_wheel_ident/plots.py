"""The report's figures (PNG, matplotlib's Agg backend: no display needed).

Each function draws one figure from an :class:`~.identification.Identification` and returns the
file name it wrote under ``out``.
"""
from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after the backend is chosen)
import numpy as np  # noqa: E402

from hasel_wheel_ident.metrics import measured_speed, simulate_trial, speed_from_angle  # noqa: E402
from hasel_wheel_ident.residual import Diagnostics  # noqa: E402
from hasel_wheel_ident.identification import Identification  # noqa: E402

DPI = 110


def _save(fig, out: Path, name: str) -> str:
    fig.tight_layout()
    fig.savefig(out / name, dpi=DPI)
    plt.close(fig)
    return name


def speed_fits(ident: Identification, out: Path) -> str:
    """Measured vs simulated speed (free run) per trial, nominal and final model."""
    n = len(ident.trials)
    fig, axes = plt.subplots(n, 1, figsize=(9, 2.2 * n + 0.5), squeeze=False, sharex=False)
    for ax, (i, tr) in zip(axes[:, 0], enumerate(ident.trials)):
        v = measured_speed(tr)
        ax.plot(tr.t, v, color="0.6", lw=0.8, label="measured")
        for ev, style, label in ((ident.nominal, "C3", "nominal"),
                                 (ident.final, "C0", "identified")):
            if label == "identified" and ev is ident.nominal:
                continue
            prob = ident.problem(ev.effects)
            x0 = prob.window_starts(ev.fit.z)[prob.trial_windows[i][0]]
            x1, _ = simulate_trial(prob, ev.fit.theta, tr, x0)
            ax.plot(tr.t, speed_from_angle(tr.t, x1), style, lw=0.9,
                    label=f"{label} ({' + '.join(ev.effects) or 'paper model'})")
        ax.set_ylabel("speed [rad/s]")
        ax.set_title(tr.name, fontsize=9)
    axes[0, 0].legend(fontsize=8, loc="lower right")
    axes[-1, 0].set_xlabel("t [s]")
    return _save(fig, out, "speed_fit.png")


def correlations(before: Diagnostics, after: Diagnostics | None, out: Path) -> str:
    """Residual autocorrelation (whiteness) and cross-correlation with q, 99 % bands."""
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 3.4))
    for d, c, lab in ((before, "C3", "nominal"), (after, "C0", "identified")):
        if d is None:
            continue
        a1.plot(d.acf_lags, d.acf, c, marker=".", lw=0.8, label=lab)
        a2.plot(d.ccf_lags, d.ccf_q, c, lw=0.8, label=lab)
    for ax in (a1, a2):
        ax.axhspan(-before.band99, before.band99, color="0.85", label="99 % band")
        ax.set_xlabel("lag [samples]")
        ax.legend(fontsize=8)
    a1.set_title("autocorrelation of the angle residual")
    a2.set_title("cross-correlation with q")
    return _save(fig, out, "correlation.png")


def structure(before: Diagnostics, after: Diagnostics | None, out: Path) -> str:
    """Bin means (+- standard error) of the acceleration residual against every axis."""
    names = list(before.structures)
    cols = 4
    rows = max(1, math.ceil(len(names) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(12, 2.8 * rows), squeeze=False)
    for ax, name in zip(axes.ravel(), names):
        for d, c, lab in ((before, "C3", "nominal"), (after, "C0", "identified")):
            if d is None or name not in d.structures:
                continue
            st = d.structures[name]
            ax.errorbar(st.centers, st.means, yerr=st.stderr, color=c, fmt=".-", lw=0.8,
                        ms=3, label=f"{lab} (p={st.p_value:.0e})")
        st = before.structures[name]
        ax.set_xlabel(f"{name.replace('_', ' ')} [{st.unit}]")
        ax.set_ylabel("accel. residual [rad/s^2]", fontsize=8)
        ax.legend(fontsize=7)
    for ax in axes.ravel()[len(names):]:
        ax.axis("off")
    return _save(fig, out, "structure.png")


def spectra(before: Diagnostics, after: Diagnostics | None, out: Path) -> str:
    """Sinusoid-scan amplitude of the acceleration residual along wheel angle and time."""
    axes_names = list(before.spectra)
    fig, axes = plt.subplots(1, max(len(axes_names), 1), figsize=(11, 3.4), squeeze=False)
    for ax, name in zip(axes[0], axes_names):
        for d, c, lab in ((before, "C3", "nominal"), (after, "C0", "identified")):
            if d is None or name not in d.spectra:
                continue
            f, amp = d.spectra[name]
            ax.plot(f, amp, c, lw=0.8, label=lab)
        if name == "wheel_angle_unwrapped":
            ax.set_xlabel("frequency [cycles per rad of wheel angle]")
            ax.axvline(1 / (2 * math.pi), color="0.5", ls=":", lw=0.8)
        else:
            ax.set_xlabel("frequency [Hz]")
        ax.set_ylabel("amplitude [rad/s^2]")
        ax.legend(fontsize=8)
    return _save(fig, out, "spectra.png")


def evidence(ident: Identification, out: Path) -> str:
    """Score statistic of every candidate per round, and held-out error of those refitted."""
    rounds = ident.screenings
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.4))
    for k, scs in enumerate(rounds):
        ids = [s.candidate for s in scs]
        stat = [max(s.statistic, 1e-3) for s in scs]
        axes[0].scatter(stat, ids, label=f"round {k + 1}", s=18)
    axes[0].set_xscale("log")
    axes[0].set_xlabel("score statistic (chi^2)")
    axes[0].set_title("screening: predicted fall in squared error")
    labels = ["nominal"] + [" + ".join(e.effects) for rd in ident.rounds for e in rd]
    vals = [ident.nominal.heldout_rmse] + [e.heldout_rmse for rd in ident.rounds for e in rd]
    colors = ["0.5"] + ["C2" if e.accepted else "C3" for rd in ident.rounds for e in rd]
    axes[1].barh(labels, np.array(vals) * 1e3, color=colors)
    axes[1].set_xlabel("held-out window RMSE [mrad] (green: accepted)")
    if rounds:
        axes[0].legend(fontsize=8)
    return _save(fig, out, "evidence.png")
