"""Closed-loop metrics of a recorded run, per wheel and per reference segment, from its bag
(no rclpy, no ROS), in one pass and bounded memory.

For every namespace that has a reference topic (``<ns>/reference_speed``; when the bag's
metadata shows it without messages, as in a ROS recording that subscribed after the reference
was published, the ``reference_speed`` of the MPC's ``mpc_status`` records;
``test_bag_metrics.py::test_without_reference_messages_the_mpc_status_gives_the_reference``)
the speed is taken from the simulator's true state (``<ns>/sim/true_state``, xi2) when the bag
has it, else from the observer (``<ns>/state_estimate``, xi2) -- a recording from the real
wheel has no true state, and its metrics then include the observer's error
(``test_a_declared_but_empty_true_state_falls_back_to_the_observer``).  The reference
messages make the profile: each starts a segment that lasts until the next (the last until
the last speed sample).  Per segment, the definitions of :mod:`~hasel_wheel_mpc.segments`:
steady-state error [%] and NRMSE over the segment's last ``window`` seconds, the rise or fall
time after a step, and the settling time to 2 %.  From ``<ns>/mpc_status``: decisions,
deadline misses and the smallest deadline slack [s] of the driving (not braking) decisions.
From ``<ns>/telemetry``: the link's lost samples (gaps in the device's sample counter), device
restarts (the counter going back) and samples with fault flags
(``test_link_errors_come_from_the_telemetry_counter_and_flags``).

Memory: per wheel the last ``window`` seconds of speed samples and one record per segment,
whatever the bag's length.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Callable

from hasel_wheel_bag.layout import topic_names
from hasel_wheel_bag.reader import read_messages

from hasel_wheel_mpc.segments import SegmentMetrics, SegmentTracker

SUFFIX_REFERENCE = "/reference_speed"
SUFFIX_TRUE = "/sim/true_state"
SUFFIX_ESTIMATE = "/state_estimate"
SUFFIX_STATUS = "/mpc_status"
SUFFIX_TELEMETRY = "/telemetry"


@dataclass
class WheelMetrics:
    """One wheel's run (times in seconds on the bag's clock)."""

    namespace: str
    speed_source: str                        # the topic the speed came from
    reference_source: str                    # the topic the reference came from
    profile: list[tuple[float, float]]       # (start [s], reference [rad/s])
    duration: float                          # [s] end of the last segment
    segments: list[SegmentMetrics]
    steady_windows: list[tuple[float, float]] = field(default_factory=list)   # [s, s)
    decisions: int = 0
    deadline_misses: int = 0
    min_slack: float = math.nan              # [s]
    telemetry_samples: int = 0
    lost_samples: int = 0                    # gaps in the device's sample counter [samples]
    device_restarts: int = 0                 # the sample counter went back
    duplicate_samples: int = 0               # the same sample counter twice
    fault_samples: int = 0                   # samples with any fault flag set
    fault_flags: int = 0                     # every flag seen (WheelTelemetry.FAULT_* bits)

    def text(self) -> str:
        out = [f"wheel {self.namespace or '/'} (speed from {self.speed_source}, reference from "
               f"{self.reference_source}): "
               f"{self.decisions} MPC decisions, {self.deadline_misses} deadline misses, "
               f"smallest slack {1e3 * self.min_slack:.2f} ms",
               f"  link: {self.telemetry_samples} telemetry samples, {self.lost_samples} lost "
               f"(sequence gaps), {self.device_restarts} device restarts, "
               f"{self.duplicate_samples} duplicates, {self.fault_samples} with fault flags "
               f"(bits 0x{self.fault_flags:x})",
               "  start [s]  ref [rad/s]  steady window [s]   steady err [%]   NRMSE  "
               "rise/fall [s]  settle [s]"]
        for (t0, _), (w0, w1), m in zip(self.profile, self.steady_windows, self.segments):
            out.append(f"  {t0:9.2f}  {m.reference:11.3f}  {w0:8.2f}-{w1:<8.2f}  "
                       f"{m.steady_error:14.2f}  {m.nrmse:6.3f}  {m.transition:13.2f}  "
                       f"{m.settle:10.2f}")
        return "\n".join(out)


@dataclass
class _Wheel:
    speeds: dict[str, SegmentTracker]        # speed topic suffix -> its tracker
    status_reference: bool = False           # the reference comes from mpc_status
    decisions: int = 0
    misses: int = 0
    min_slack: float = math.inf
    samples: int = 0
    lost: int = 0
    restarts: int = 0
    duplicates: int = 0
    faulty: int = 0
    flags: int = 0
    last_seq: int | None = None


def bag_metrics(path: str | os.PathLike, window: float = 10.0,
                warn: Callable[[str], None] | None = None,
                progress: bool = False) -> list[WheelMetrics]:
    """Metrics of every wheel in the bag (see the module docstring); ``window`` [s] is the
    steady window at the end of each segment; ``progress``: a progress bar on stderr (on a
    terminal)."""
    known = topic_names(path)
    wheels: dict[str, _Wheel] = {}

    def wheel(topic: str, suffix: str) -> _Wheel:
        ns = topic[: -len(suffix)]
        w = wheels.get(ns)
        if w is None:
            # the observer's speed only where no true speed was recorded, when the metadata
            # says which topics there are; else both are followed and the choice made at the end
            if known is None:
                sources = (SUFFIX_TRUE, SUFFIX_ESTIMATE)
            else:
                sources = (SUFFIX_TRUE,) if ns + SUFFIX_TRUE in known else (SUFFIX_ESTIMATE,)
            # a ROS recording that missed the reference (published before the recorder
            # subscribed, or set as a parameter): the MPC's status records carry it
            from_status = known is not None and ns + SUFFIX_REFERENCE not in known
            w = wheels[ns] = _Wheel({s: SegmentTracker(window) for s in sources}, from_status)
        return w

    suffixes = (SUFFIX_REFERENCE, SUFFIX_TRUE, SUFFIX_ESTIMATE, SUFFIX_STATUS, SUFFIX_TELEMETRY)

    def wanted(name: str) -> bool:
        if not name.endswith(suffixes):
            return False
        return not (known is not None and name.endswith(SUFFIX_ESTIMATE)
                    and name[: -len(SUFFIX_ESTIMATE)] + SUFFIX_TRUE in known)

    for topic, t_ns, m in read_messages(path, warn=warn, select=wanted,
                                        progress="bag metrics" if progress else None):
        t = t_ns / 1e9
        if topic.endswith(SUFFIX_REFERENCE):
            for tracker in wheel(topic, SUFFIX_REFERENCE).speeds.values():
                tracker.reference(t, float(m.data))
        elif topic.endswith(SUFFIX_TRUE) or topic.endswith(SUFFIX_ESTIMATE):
            suffix = SUFFIX_TRUE if topic.endswith(SUFFIX_TRUE) else SUFFIX_ESTIMATE
            tracker = wheel(topic, suffix).speeds.get(suffix)
            if tracker is not None:
                tracker.sample(t, m.xi2)
        elif topic.endswith(SUFFIX_STATUS):
            w = wheel(topic, SUFFIX_STATUS)
            if w.status_reference:
                for tracker in w.speeds.values():
                    tracker.reference(t, float(m.reference_speed))
            w.decisions += 1
            w.misses += bool(m.deadline_missed)
            if not m.braking:           # a braking decision has no deadline fallback
                w.min_slack = min(w.min_slack, float(m.deadline_slack))
        else:
            w = wheel(topic, SUFFIX_TELEMETRY)
            w.samples += 1
            seq = m.sequence
            if w.last_seq is not None:
                if seq > w.last_seq + 1:
                    w.lost += seq - w.last_seq - 1
                elif seq == w.last_seq:
                    w.duplicates += 1
                elif seq < w.last_seq:
                    w.restarts += 1
            w.last_seq = seq
            if m.fault_flags:
                w.faulty += 1
                w.flags |= m.fault_flags
    out = []
    for ns, w in sorted(wheels.items()):
        chosen = next((s for s in (SUFFIX_TRUE, SUFFIX_ESTIMATE)
                       if s in w.speeds and w.speeds[s].last_time is not None), None)
        if chosen is None:
            continue
        tracker = w.speeds[chosen]
        if not tracker.profile:
            continue
        segs = tracker.finish()
        out.append(WheelMetrics(
            ns, ns + chosen, ns + (SUFFIX_STATUS if w.status_reference else SUFFIX_REFERENCE),
            tracker.profile, tracker.ends[-1], segs,
            [(max(t0, t1 - window), t1) for (t0, _), t1 in zip(tracker.profile, tracker.ends)],
            w.decisions, w.misses, w.min_slack if w.decisions else math.nan,
            w.samples, w.lost, w.restarts, w.duplicates, w.faulty, w.flags))
    return out
