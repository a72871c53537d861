"""PNG figures of a recorded run, per wheel (no rclpy, no ROS; matplotlib's Agg backend).

For every namespace with ``telemetry``:

* ``<ns>_speed.png``: speed against the reference, like paper Fig. 11 (the simulator's true
  speed when recorded, the observer's estimate, the reference);
* ``<ns>_raster.png``: the actuator raster: which actuator (eta, 0..15) has HV on (q = 1)
  over time, with q below it;
* ``<ns>_force.png``: the actuator force F_a [N] against the contact angle xi_c = xi1 -
  eta pi/8 [deg], recovered from the motion by inverting the flow map (38) with the wheel's
  parameters (the recorded controller's, else the paper's): F_a = (J xi2' + tau_f' sign xi2)
  / (r sin xi_c) while q = 1; binned medians with their quartiles, and the model's force law
  (43) at the median speed and commanded phi_a for comparison;
* ``<ns>_observer.png``: the observer's speed against the raw encoder speed (a finite
  difference of the 10-bit angle) and, when recorded, the true speed.

The force recovery needs the wheel's acceleration: from the true speed when the bag has it,
else from a Savitzky-Golay derivative of the observer's speed, which smooths the force curve.
"""
from __future__ import annotations

import math
import os
from array import array
from collections import defaultdict
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after the backend is chosen)
import numpy as np  # noqa: E402
from scipy import signal  # noqa: E402

from hasel_wheel_common import topics
from hasel_wheel_bag.layout import BagError  # noqa: E402
from hasel_wheel_bag.reader import bag_configuration, read_messages  # noqa: E402
from hasel_wheel_sim import layout as L  # noqa: E402
from hasel_wheel_sim.model import SECTOR, force_law, param_vector  # noqa: E402
from hasel_wheel_sim.params import WheelParams  # noqa: E402

from hasel_wheel_mpc.config import ControllerConfig  # noqa: E402

DPI = 110
SUFFIXES = {"/" + tp.name: key for tp, key in (
    (topics.TELEMETRY, "tel"), (topics.STATE_ESTIMATE, "est"), (topics.TRUE_STATE, "true"),
    (topics.REFERENCE, "ref"), (topics.COMMAND, "cmd"))}
#: Savitzky-Golay window for accelerations from the observer's speed [s]
ACCEL_WINDOW = 0.1


def _split(topic: str) -> tuple[str, str] | None:
    for suffix, key in SUFFIXES.items():
        if topic.endswith(suffix):
            return topic[: -len(suffix)], key
    return None


def _collect(path, progress: bool) -> dict[str, dict[str, dict[str, array]]]:
    """{namespace: {stream: {column: array('d')}}} of what the figures need."""
    data: dict[str, dict[str, dict[str, array]]] = defaultdict(
        lambda: defaultdict(lambda: defaultdict(lambda: array("d"))))
    for topic, t_ns, m in read_messages(path, select=lambda n: _split(n) is not None,
                                        progress="bag plot" if progress else None):
        ns, key = _split(topic)
        cols = data[ns][key]
        cols["t"].append(t_ns / 1e9)
        if key == "tel":
            cols["angle"].append(m.angle)
            cols["q"].append(m.q)
            cols["eta"].append(m.eta)
            cols["eta_u"].append(m.eta_unwrapped)
        elif key in ("est", "true"):
            cols["xi1"].append(m.xi1)
            cols["xi2"].append(m.xi2)
        elif key == "ref":
            cols["v"].append(m.data)
        else:
            cols["phi_a"].append(m.phi_a)
    return {ns: {k: {c: np.frombuffer(a) for c, a in v.items()} for k, v in d.items()}
            for ns, d in data.items()}


def _params(path, ns: str) -> tuple[WheelParams, str]:
    text = bag_configuration(path).get(f"{ns}/controller.yaml")
    if text is None:
        return WheelParams(), "the paper's parameters"
    return ControllerConfig.from_yaml(text).params, "the recorded controller's model"


def _save(fig, out: Path, name: str) -> Path:
    fig.tight_layout()
    fig.savefig(out / name, dpi=DPI)
    plt.close(fig)
    return out / name


def _ref_steps(ref: dict, t_end: float) -> tuple[np.ndarray, np.ndarray]:
    t = np.append(ref["t"], t_end)
    v = np.append(ref["v"], ref["v"][-1])
    return t, v


def raw_encoder_speed(t: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """(n,) finite difference [rad/s] of encoder angles (n,) [rad] at times t (n,) [s]; the
    first sample repeats the second's."""
    v = np.empty_like(angle)
    if angle.size < 2:
        return np.zeros_like(angle)
    v[1:] = np.diff(angle) / np.maximum(np.diff(t), 1e-9)
    v[0] = v[1]
    return v


def force_samples(t: np.ndarray, xi1: np.ndarray, xi2: np.ndarray, q: np.ndarray,
                  eta_u: np.ndarray, params: WheelParams, smooth: bool
                  ) -> tuple[np.ndarray, np.ndarray]:
    """(contact angle [rad], F_a [N]) at every sample with q = 1, from the flow map (38)
    inverted: F_a = (xi2' / inv_inertia + friction sign xi2) / (r sin xi_c).  All inputs
    (n,) on one time base; ``smooth``: differentiate with a Savitzky-Golay filter (noisy
    speeds), else with central differences (a true speed)
    (``test_bag_plot.py::test_the_force_recovered_from_the_true_motion_is_the_force_law``)."""
    pv = param_vector(params)
    if smooth and t.size > 7:
        dt = float(np.median(np.diff(t)))
        n = max(5, int(round(ACCEL_WINDOW / dt)) | 1)
        acc = signal.savgol_filter(xi2, min(n, t.size - (1 - t.size % 2)), 2, deriv=1, delta=dt)
    else:
        acc = np.gradient(xi2, t) if t.size > 1 else np.zeros_like(xi2)
    xc = xi1 - eta_u * SECTOR
    on = (q == 1) & (np.abs(np.sin(xc)) > 1e-3)
    tau = acc[on] / pv[L.P_INV_INERTIA] + pv[L.P_FRICTION] * np.sign(xi2[on])
    return xc[on], tau / (pv[L.P_R] * np.sin(xc[on]))


def plot_bag(path: str | os.PathLike, out_dir: str | os.PathLike,
             namespaces: list[str] | None = None, progress: bool = False) -> list[Path]:
    """Write the figures (see the module docstring) for every wheel (or ``namespaces``) of
    the bag into ``out_dir``; returns the files.  Raises BagError when there is no wheel."""
    data = _collect(path, progress)
    wheels = sorted(ns for ns, d in data.items() if "tel" in d and
                    (namespaces is None or ns in namespaces))
    if not wheels:
        raise BagError(f"{path}: nothing to plot: no telemetry"
                       + (f" under {namespaces}" if namespaces else ""))
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files = []
    for ns in wheels:
        d = data[ns]
        stem = ns.strip("/").replace("/", "_") or "root"
        files += [_speed(d, out, stem, ns), _raster(d, out, stem, ns),
                  _force(d, out, stem, ns, *_params(path, ns)), _observer(d, out, stem, ns)]
    return files


def _speed(d, out: Path, stem: str, ns: str) -> Path:
    fig, ax = plt.subplots(figsize=(9, 3.6))
    tel = d["tel"]
    if "true" in d:
        ax.plot(d["true"]["t"], d["true"]["xi2"], lw=0.6, label="true speed (simulator)")
    if "est" in d:
        ax.plot(d["est"]["t"], d["est"]["xi2"], lw=0.4, alpha=0.7, label="observer estimate")
    if "ref" in d:
        ax.step(*_ref_steps(d["ref"], tel["t"][-1]), "k--", where="post", lw=1.0,
                label="reference")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("wheel speed xi2 [rad/s]")
    ax.set_title(f"{ns}: speed against reference (cf. paper Fig. 11)")
    ax.legend(loc="lower right", fontsize=8)
    return _save(fig, out, f"{stem}_speed.png")


def _raster(d, out: Path, stem: str, ns: str) -> Path:
    tel = d["tel"]
    fig, (ax, axq) = plt.subplots(2, 1, figsize=(9, 4.6), sharex=True,
                                  gridspec_kw={"height_ratios": [3, 1]})
    on = tel["q"] == 1
    ax.scatter(tel["t"][on], tel["eta"][on], s=2, marker="|", c=tel["eta"][on], cmap="tab20")
    ax.set_yticks(range(0, 16, 3))
    ax.set_ylim(-0.5, 15.5)
    ax.set_ylabel("actuator eta (HV on)")
    ax.set_title(f"{ns}: actuator raster")
    axq.step(tel["t"], tel["q"], where="post", lw=0.5)
    axq.set_ylim(-0.1, 1.1)
    axq.set_ylabel("q")
    axq.set_xlabel("time [s]")
    return _save(fig, out, f"{stem}_raster.png")


def _force(d, out: Path, stem: str, ns: str, params: WheelParams, source: str) -> Path:
    tel = d["tel"]
    fig, ax = plt.subplots(figsize=(7, 4))
    motion = d.get("true") or d.get("est")
    if motion is not None and motion["t"].size > 2:
        # the state on the telemetry's time base (true state / estimate share its stamps)
        idx = np.clip(np.searchsorted(motion["t"], tel["t"]), 0, motion["t"].size - 1)
        xc, f = force_samples(tel["t"], motion["xi1"][idx], motion["xi2"][idx], tel["q"],
                              tel["eta_u"], params, smooth="true" not in d)
        deg = np.degrees(xc)
        edges = np.arange(0.0, 22.5 + 0.5, 0.5)
        mids, med, lo, hi = [], [], [], []
        for a, b in zip(edges[:-1], edges[1:]):
            sel = f[(deg >= a) & (deg < b)]
            if sel.size >= 5:
                mids.append((a + b) / 2)
                q1, q2, q3 = np.percentile(sel, [25, 50, 75])
                med.append(q2)
                lo.append(q2 - q1)
                hi.append(q3 - q2)
        if mids:
            ax.errorbar(mids, med, yerr=[lo, hi], fmt="o", ms=3, lw=0.8,
                        label=f"from the motion ({'true' if 'true' in d else 'observer'} speed)")
        pv = param_vector(params)
        speed = float(np.median(np.abs(motion["xi2"])))
        phi_a = float(np.median(d["cmd"]["phi_a"])) if "cmd" in d else math.radians(3.0)
        grid = np.radians(np.linspace(math.degrees(phi_a) + 0.05, 22.5, 200))
        ax.plot(np.degrees(grid), [force_law(x, speed, phi_a, pv) for x in grid], "k-", lw=1.0,
                label=f"model (43) at {speed:.2f} rad/s, phi_a {math.degrees(phi_a):.1f} deg")
    ax.set_xlabel("contact angle xi_c [deg]")
    ax.set_ylabel("actuator force F_a [N]")
    ax.set_title(f"{ns}: force against contact angle ({source})", fontsize=9)
    ax.legend(fontsize=8)
    return _save(fig, out, f"{stem}_force.png")


def _observer(d, out: Path, stem: str, ns: str) -> Path:
    tel = d["tel"]
    fig, ax = plt.subplots(figsize=(9, 3.6))
    ax.plot(tel["t"], raw_encoder_speed(tel["t"], tel["angle"]), lw=0.3, alpha=0.5,
            color="0.6", label="raw encoder finite difference")
    if "true" in d:
        ax.plot(d["true"]["t"], d["true"]["xi2"], lw=0.6, label="true speed (simulator)")
    if "est" in d:
        ax.plot(d["est"]["t"], d["est"]["xi2"], lw=0.6, label="observer estimate")
    hi = float(np.percentile(d["est"]["xi2"], 99.5)) if "est" in d else None
    if hi is not None and math.isfinite(hi):
        ax.set_ylim(min(0.0, float(np.percentile(d["est"]["xi2"], 0.5))) - 0.2, hi * 1.5 + 0.2)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("wheel speed [rad/s]")
    ax.set_title(f"{ns}: observer against the raw 10-bit encoder")
    ax.legend(loc="lower right", fontsize=8)
    return _save(fig, out, f"{stem}_observer.png")
