"""Tracking metrics per reference segment, computed online in bounded memory.

A segment starts at a change of the reference and lasts until the next change (the last one
until the end of the run).  Per segment (:class:`SegmentMetrics`):

* steady-state error [%] = |mean(v) - ref| / ref and NRMSE = RMS(v - ref) / ref over the
  steady window, the segment's last ``window`` seconds;
* the transition time: rise time after a step up, fall time after a step down, from the step
  until the speed first reaches the new reference (NaN for the first segment);
* the settling time: from the step until the speed first comes within 2 % of the reference
  (``test_bag_metrics.py::test_segments_match_the_closed_forms``,
  ``test_steady_windows_are_the_last_window_seconds_of_each_segment``).

:class:`SegmentTracker` takes the samples and reference changes in time order and keeps only
the last ``window`` seconds of samples, so a bag of any length is measured in the same
memory (``test_the_tracker_keeps_only_the_steady_window_in_memory``).  A sample stamped at
the very time of a reference change belongs to the new segment, whichever of the two arrives
first (``test_a_sample_at_the_step_belongs_to_the_new_segment_in_either_order``).  NaN speeds
and NaN references are left out.  Errors are relative to |ref| (a reference of 0, a stop, has
none: NaN) (``test_nan_speeds_and_references_are_left_out_and_a_negative_reference_is_relative``,
``test_a_stop_segment_has_no_relative_error_instead_of_a_crash``).
"""
from __future__ import annotations

import math
from collections import deque
from typing import NamedTuple


class SegmentMetrics(NamedTuple):
    reference: float       # [rad/s]
    steady_error: float    # |mean(speed) - ref| / |ref| over the steady window [%]
    nrmse: float           # RMSE(speed - ref) / |ref| over the steady window [1]
    transition: float      # from the step until the speed first reaches ref [s] (rise/fall)
    settle: float          # from the step until the speed first comes within 2 % of ref [s]


class SegmentTracker:
    """Online :class:`SegmentMetrics`; ``window`` [s] is the steady window."""

    def __init__(self, window: float = 10.0) -> None:
        self.window = window
        self.profile: list[tuple[float, float]] = []    # (start [s], reference [rad/s])
        self.ends: list[float] = []                      # end of each finished segment [s]
        self.segments: list[SegmentMetrics] = []
        self._ring: deque[tuple[float, float]] = deque()  # this segment's last window seconds
        self._pending: list[float] = []                   # speeds stamped _pending_t
        self._pending_t: float | None = None
        self._last: tuple[float | None, float | None] = (None, None)   # last two sample times
        self._settle = math.nan
        self._trans = math.nan

    def sample(self, t: float, v: float) -> None:
        """A speed sample v [rad/s] at t [s] (t not decreasing); NaN is left out."""
        if v != v:
            return
        if self._pending_t is not None and t != self._pending_t:
            self._commit()
        self._pending.append(v)
        self._pending_t = t

    def reference(self, t: float, ref: float) -> None:
        """The reference [rad/s] from t [s] on; a repeat of the current value is no change,
        and NaN is left out."""
        if ref != ref:
            return
        if self._pending_t is not None and self._pending_t < t:
            self._commit()
        if self.profile and ref == self.profile[-1][1]:
            return
        if self.profile:
            self._close(t)
        self.profile.append((t, ref))
        self._ring.clear()
        self._settle = self._trans = math.nan

    def finish(self, end: float | None = None) -> list[SegmentMetrics]:
        """Close the last segment at ``end`` [s] (default: one sample interval after the
        last sample) and return every segment's metrics."""
        self._commit()
        if end is None:
            t1, t0 = self._last
            end = (t1 + (t1 - t0 if t0 is not None else 0.0)) if t1 is not None else math.nan
        if self.profile and len(self.segments) < len(self.profile):
            self._close(end)
        return self.segments

    @property
    def last_time(self) -> float | None:
        """Time [s] of the last sample seen."""
        return self._pending_t if self._pending_t is not None else self._last[0]

    def _commit(self) -> None:
        t = self._pending_t
        if t is None:
            return
        self._last = (t, self._last[0])
        if self.profile:
            t0, ref = self.profile[-1]
            prev = self.profile[-2][1] if len(self.profile) > 1 else None
            ring = self._ring
            for v in self._pending:
                if math.isnan(self._settle) and abs(v - ref) <= 0.02 * abs(ref):
                    self._settle = t - t0
                if (math.isnan(self._trans) and prev is not None
                        and ((v >= ref) if ref > prev else (v <= ref))):
                    self._trans = t - t0
                ring.append((t, v))
            while ring and ring[0][0] < t - self.window:
                ring.popleft()
        self._pending = []
        self._pending_t = None

    def _close(self, t1: float) -> None:
        ref = self.profile[-1][1]
        steady = [v for t, v in self._ring if t >= t1 - self.window]
        if steady and ref:
            mean = sum(steady) / len(steady)
            ss = abs(mean - ref) / abs(ref) * 100.0
            nrmse = math.sqrt(sum((v - ref) ** 2 for v in steady) / len(steady)) / abs(ref)
        else:           # no sample in the window, or a stop (ref = 0): relative error undefined
            ss = nrmse = math.nan
        self.segments.append(SegmentMetrics(ref, ss, nrmse, self._trans, self._settle))
        self.ends.append(t1)
