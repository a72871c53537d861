"""What a bag holds, without decoding a message: topics, counts, rates, gaps, duration and
the run's configuration (no rclpy, no ROS).

One pass over the bag's records (:func:`~.reader.read_raw`), with memory that does not grow
with the bag's length: per topic a count, the first and last stamp, the largest interval,
and the count of *gaps*, intervals longer than ``GAP_FACTOR`` times the topic's nominal
period.  The nominal period is the median of the topic's first ``PERIOD_SAMPLES`` intervals
(a 300 Hz topic: 1/300 s), so a topic published at a steady rate gets its gaps counted
against that rate; a topic that is only published on change (a reference, a command) gets
its rate and largest interval, and its gap count means little.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hasel_wheel_bag.layout import file_finished, mcap_files

from hasel_wheel_bag.reader import bag_configuration, read_raw

GAP_FACTOR = 3.0        # an interval this many nominal periods long is a gap
PERIOD_SAMPLES = 1000   # intervals the nominal period is taken from


@dataclass
class TopicInfo:
    """One topic of a bag; times in seconds from the bag's start, rates in Hz."""

    topic: str
    type: str
    count: int = 0
    first_s: float = float("nan")
    last_s: float = float("nan")
    rate_hz: float = float("nan")         # (count - 1) / (last - first)
    period_s: float = float("nan")        # nominal: median of the first intervals
    max_interval_s: float = float("nan")  # the longest time between two messages
    gaps: int = 0                         # intervals > GAP_FACTOR x period_s


@dataclass
class BagInfo:
    """The whole bag: ``files`` as (name, bytes, closed properly), times in seconds."""

    path: str
    files: list[tuple[str, int, bool]]
    start_ns: int | None
    duration_s: float
    messages: int
    topics: dict[str, TopicInfo]
    configuration: dict[str, str] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)

    def text(self) -> str:
        """A human-readable summary, one topic per line."""
        out = [f"bag: {self.path}"]
        for name, size, closed in self.files:
            out.append(f"  file {name}: {size / 1024:.1f} KiB"
                       + ("" if closed else "  (not closed: recovered up to its last chunk)"))
        out.append(f"  duration {self.duration_s:.3f} s, {self.messages} messages, "
                   f"{len(self.topics)} topics")
        width = max((len(t) for t in self.topics), default=5)
        out.append(f"  {'topic':<{width}}  {'count':>8}  {'rate [Hz]':>9}  "
                   f"{'max gap [s]':>11}  {'gaps':>5}  type")
        for t in sorted(self.topics.values(), key=lambda t: t.topic):
            out.append(f"  {t.topic:<{width}}  {t.count:>8}  {t.rate_hz:>9.2f}  "
                       f"{t.max_interval_s:>11.4f}  {t.gaps:>5}  {t.type}")
        if self.configuration:
            out.append("  configuration (metadata.yaml custom_data, or the MCAP configuration records):")
            for k, v in self.configuration.items():
                first = str(v).splitlines()[0] if str(v) else ""
                more = len(str(v).splitlines()) - 1
                out.append(f"    {k}: {first}" + (f"  (+{more} lines)" if more > 0 else ""))
        for w in self.warnings:
            out.append(f"  warning: {w}")
        return "\n".join(out)


@dataclass
class _Running:
    """One topic during the pass (stamps in ns)."""

    info: TopicInfo
    first: int
    last: int
    max_interval: int = 0
    head: list[int] = field(default_factory=list)   # the first PERIOD_SAMPLES intervals
    period: float | None = None                     # their median, once there are enough
    gaps_after: int = 0                             # gaps after the head

    def add(self, t: int) -> None:
        self.info.count += 1
        dt = t - self.last
        self.last = t
        self.max_interval = max(self.max_interval, dt)
        if self.period is None:
            self.head.append(dt)
            if len(self.head) == PERIOD_SAMPLES:
                self.period = float(np.median(self.head))
        elif self.period > 0 and dt > GAP_FACTOR * self.period:
            self.gaps_after += 1

    def finish(self, start: int) -> TopicInfo:
        i = self.info
        if self.head:
            period = self.period if self.period is not None else float(np.median(self.head))
            i.period_s = period / 1e9
            i.gaps = (sum(1 for d in self.head if d > GAP_FACTOR * period) if period > 0
                      else 0) + self.gaps_after
            i.max_interval_s = self.max_interval / 1e9
        i.first_s = (self.first - start) / 1e9
        i.last_s = (self.last - start) / 1e9
        if self.last > self.first:
            i.rate_hz = (i.count - 1) / ((self.last - self.first) / 1e9)
        return i


def bag_info(path: str | os.PathLike,
             progress: bool = False) -> BagInfo:
    """Read a bag (directory or .mcap file) once and summarise it as a :class:`BagInfo`
    (counts, rates [Hz], intervals [s], configuration, the reader's warnings).
    ``progress``: a progress bar on stderr (on a terminal).  Gaps are not counted for a topic whose
    median interval is 0 (repeated stamps)."""
    p = Path(path)
    said: list[str] = []
    running: dict[str, _Running] = {}
    start: int | None = None
    end: int | None = None
    n = 0
    for topic, type_, t, _data in read_raw(p, warn=said.append,
                                           progress="bag info" if progress else None):
        n += 1
        start = t if start is None or t < start else start
        end = t if end is None or t > end else end
        r = running.get(topic)
        if r is None:
            running[topic] = _Running(TopicInfo(topic, type_, 1), t, t)
        else:
            r.add(t)
    topics = {name: r.finish(start) for name, r in running.items()}
    files = [(f.name, f.stat().st_size, file_finished(f)) for f in mcap_files(p)]
    return BagInfo(str(p), files, start, ((end - start) / 1e9) if n else 0.0, n, topics,
                   bag_configuration(p), said)
