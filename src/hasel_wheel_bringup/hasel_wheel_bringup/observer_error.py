"""How far a recorded observer's speed is from the simulator's true speed, from bags.

Every ``<ns>/state_estimate`` is paired with the ``<ns>/sim/true_state`` of the same header
stamp (the observer stamps an estimate with its telemetry sample's stamp, and the simulator
stamps its true state on the same clock), from the estimates' bag or from another one: a
replay's bag (``replay.launch.py``) holds new estimates for the recorded samples, and the
original run's bag holds the truth.  The first ``skip`` seconds after the first paired
estimate (the observer acquiring the wheel) are left out
(``test_observer_error.py::test_alternating_offset_has_its_rms_and_the_start_is_left_out``,
``test_a_replay_s_estimates_pair_with_the_original_run_s_truth``).
"""
from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from hasel_wheel_common import topics
from hasel_wheel_bag.layout import BagError
from hasel_wheel_bag.reader import read_messages

SUFFIX_ESTIMATE = "/" + topics.STATE_ESTIMATE.name
SUFFIX_TRUE = "/" + topics.TRUE_STATE.name


@dataclass
class ObserverError:
    """One wheel's observer speed error (speeds rad/s, times s)."""

    namespace: str
    pairs: int            # estimates paired with a true state after the skip [1]
    unpaired: int         # estimates after the skip with no true state of their stamp [1]
    rms: float            # RMS of xi2_estimate - xi2_true [rad/s]
    p99: float            # 99th percentile of |xi2_estimate - xi2_true| [rad/s]
    median: float         # median of |xi2_estimate - xi2_true| [rad/s]
    skip: float           # [s] left out at the start

    def text(self) -> str:
        return (f"{self.namespace}: observer speed error over {self.pairs} estimates (the first "
                f"{self.skip:g} s left out, {self.unpaired} without a true state): RMS "
                f"{self.rms:.4f} rad/s, median |e| {self.median:.4f}, p99 |e| {self.p99:.4f}")


def _stamp(m) -> int:
    return m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec


def _by_namespace(path, suffix: str) -> dict[str, dict[int, float]]:
    out: dict[str, dict[int, float]] = {}
    for topic, _, m in read_messages(path, select=lambda name: name.endswith(suffix)):
        out.setdefault(topic[: -len(suffix)], {})[_stamp(m)] = float(m.xi2)
    return out


def observer_error(path: str | os.PathLike, truth: str | os.PathLike | None = None,
                   skip: float = 2.0) -> list[ObserverError]:
    """Per namespace with estimates in ``path``: the error against the true states in
    ``truth`` (default: ``path`` itself).  Raises :class:`BagError` when nothing pairs."""
    if not skip >= 0.0:
        raise BagError(f"skip = {skip!r} s: expected a time >= 0")
    true = _by_namespace(truth if truth is not None else path, SUFFIX_TRUE)
    estimates = _by_namespace(path, SUFFIX_ESTIMATE)
    out = []
    for ns, est in sorted(estimates.items()):
        ref = true.get(ns, {})
        paired = sorted(k for k in est if k in ref)
        if not paired:
            continue
        t0 = paired[0] + round(skip * 1e9)
        keys = [k for k in paired if k >= t0]
        e = np.array([est[k] - ref[k] for k in keys])
        a = np.abs(e)
        unpaired = sum(1 for k in est if k >= t0 and k not in ref)
        out.append(ObserverError(ns, len(keys), unpaired,
                                 float(np.sqrt(np.mean(e * e))) if e.size else float("nan"),
                                 float(np.percentile(a, 99)) if a.size else float("nan"),
                                 float(np.median(a)) if a.size else float("nan"), skip))
    if not out:
        raise BagError(f"{path}: no {SUFFIX_ESTIMATE[1:]} pairs by stamp with a "
                       f"{SUFFIX_TRUE[1:]} in {truth or path}")
    return out
