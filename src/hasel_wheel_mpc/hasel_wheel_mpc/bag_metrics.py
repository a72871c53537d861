"""Closed-loop metrics of a recorded run, per wheel and per reference segment, from its bag
(no rclpy, no ROS).

For every namespace that has a reference topic (``<ns>/reference_speed``) the speed is taken
from the simulator's true state (``<ns>/sim/true_state``, xi2) when the bag has it, else from
the observer (``<ns>/state_estimate``, xi2) -- a recording from the real wheel has no true
state, and its metrics then include the observer's error.  The reference messages make the
profile: each starts a segment that lasts until the next (the last until the last speed
sample).  Per segment, the same definitions as the closed-loop demo
(:func:`~.closed_loop.segment_metrics`): steady-state error [%] and NRMSE over the segment's
last ``window`` seconds, the rise or fall time after a step, and the settling time to 2 %.
From ``<ns>/mpc_status``: decisions, deadline misses and the smallest deadline slack [s].
"""
from __future__ import annotations

import math
import os
from array import array
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
from hasel_wheel_driver.bagio import read_messages, topic_names

from .closed_loop import LoopLog, SegmentMetrics, segment_metrics

SUFFIX_REFERENCE = "/reference_speed"
SUFFIX_TRUE = "/sim/true_state"
SUFFIX_ESTIMATE = "/state_estimate"
SUFFIX_STATUS = "/mpc_status"


@dataclass
class WheelMetrics:
    """One wheel's run (times in seconds on the bag's clock)."""

    namespace: str
    speed_source: str                        # the topic the speed came from
    profile: list[tuple[float, float]]       # (start [s], reference [rad/s])
    duration: float                          # [s] the last speed sample
    segments: list[SegmentMetrics]
    decisions: int = 0
    deadline_misses: int = 0
    min_slack: float = math.nan              # [s]

    def text(self) -> str:
        out = [f"wheel {self.namespace or '/'} (speed from {self.speed_source}): "
               f"{self.decisions} MPC decisions, {self.deadline_misses} deadline misses, "
               f"smallest slack {1e3 * self.min_slack:.2f} ms",
               "  start [s]  ref [rad/s]  steady err [%]   NRMSE  rise/fall [s]  settle [s]"]
        for (t0, _), m in zip(self.profile, self.segments):
            out.append(f"  {t0:9.2f}  {m.reference:11.3f}  {m.steady_error:14.2f}  "
                       f"{m.nrmse:6.3f}  {m.transition:13.2f}  {m.settle:10.2f}")
        return "\n".join(out)


@dataclass
class _Wheel:
    ref: list[tuple[float, float]] = field(default_factory=list)
    true_t: array = field(default_factory=lambda: array("d"))
    true_v: array = field(default_factory=lambda: array("d"))
    est_t: array = field(default_factory=lambda: array("d"))
    est_v: array = field(default_factory=lambda: array("d"))
    decisions: int = 0
    misses: int = 0
    min_slack: float = math.inf


def bag_metrics(path: str | os.PathLike, window: float = 10.0,
                warn: Callable[[str], None] | None = None) -> list[WheelMetrics]:
    """Metrics of every wheel in the bag (see the module docstring); ``window`` [s] is the
    steady window at the end of each segment.  Speeds are kept as float64 pairs (16 bytes
    per sample per wheel: about 17 MB per wheel-hour at 300 Hz)."""
    wheels: dict[str, _Wheel] = {}

    def wheel(topic: str, suffix: str) -> _Wheel:
        return wheels.setdefault(topic[: -len(suffix)], _Wheel())

    suffixes = (SUFFIX_REFERENCE, SUFFIX_TRUE, SUFFIX_ESTIMATE, SUFFIX_STATUS)
    known = topic_names(path)

    def wanted(name: str) -> bool:
        if not name.endswith(suffixes):
            return False
        # the observer's speed is not decoded where the true speed was recorded (when the
        # metadata says which topics there are)
        return not (known is not None and name.endswith(SUFFIX_ESTIMATE)
                    and name[: -len(SUFFIX_ESTIMATE)] + SUFFIX_TRUE in known)

    for topic, t_ns, m in read_messages(path, warn=warn, select=wanted):
        t = t_ns / 1e9
        if topic.endswith(SUFFIX_REFERENCE):
            wheel(topic, SUFFIX_REFERENCE).ref.append((t, float(m.data)))
        elif topic.endswith(SUFFIX_TRUE):
            w = wheel(topic, SUFFIX_TRUE)
            w.true_t.append(t)
            w.true_v.append(m.xi2)
        elif topic.endswith(SUFFIX_ESTIMATE):
            w = wheel(topic, SUFFIX_ESTIMATE)
            w.est_t.append(t)
            w.est_v.append(m.xi2)
        elif topic.endswith(SUFFIX_STATUS):
            w = wheel(topic, SUFFIX_STATUS)
            w.decisions += 1
            w.misses += bool(m.deadline_missed)
            w.min_slack = min(w.min_slack, float(m.deadline_slack))
    out = []
    for ns, w in sorted(wheels.items()):
        if not w.ref:
            continue
        t, v, source = ((w.true_t, w.true_v, ns + SUFFIX_TRUE) if len(w.true_t) else
                        (w.est_t, w.est_v, ns + SUFFIX_ESTIMATE))
        if not len(t):
            continue
        profile = _profile(w.ref)
        log = LoopLog(t=np.frombuffer(t), true_speed=np.frombuffer(v))     # no copies
        duration = t[-1] + (t[-1] - t[-2] if len(t) > 1 else 0.0)
        segs = segment_metrics(log, profile, duration, window)
        out.append(WheelMetrics(ns, source, profile, duration, segs, w.decisions, w.misses,
                                w.min_slack if w.decisions else math.nan))
    return out


def _profile(refs: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """(start, reference) of each change of the reference (repeats of the same value, as a
    latched topic re-sends it, do not start a segment)."""
    out: list[tuple[float, float]] = []
    for t, r in sorted(refs, key=lambda tr: tr[0]):           # stable: arrival order kept
        if not out or r != out[-1][1]:
            out.append((t, r))
    return out
