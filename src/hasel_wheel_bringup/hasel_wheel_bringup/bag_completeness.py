"""Is a recording complete?  Per wheel, the bag's telemetry against the device node's own
count of what it published (its ``/diagnostics``, :mod:`hasel_wheel_common.published_count`).

The last device report in the bag says: ``P`` samples published, the last with sequence
``S``.  The bag is complete up to that report when it holds ``P`` telemetry samples with a
sequence up to ``S`` (``missing`` = 0).  Gaps in the sequence numbers are counted apart:
they include samples the device itself lost (a sim plant's dropouts, the serial link's
losses) as well as any the recording lost.  Test: ``test_bag_completeness.py``.
"""
from __future__ import annotations

import os
from dataclasses import dataclass

from hasel_wheel_bag.reader import read_messages
from hasel_wheel_common.published_count import LAST_SEQUENCE_KEY, PUBLISHED_KEY

SUFFIX_TELEMETRY = "/telemetry"


@dataclass(frozen=True)
class Completeness:
    """One wheel's telemetry in a bag (counts of samples)."""

    namespace: str
    recorded: int                  # telemetry messages in the bag
    sequence_gaps: int             # sequence numbers skipped between recorded samples
    published: int | None          # the device node's count at its last report in the bag
    last_sequence: int | None      # the sequence of its last published sample then
    recorded_until: int | None     # recorded samples with sequence <= last_sequence

    @property
    def missing(self) -> int | None:
        """Published but not recorded, up to the last report (None without a report)."""
        if self.published is None or self.recorded_until is None:
            return None
        return self.published - self.recorded_until

    def text(self) -> str:
        head = f"wheel {self.namespace or '/'}: {self.recorded} telemetry samples recorded, " \
               f"{self.sequence_gaps} sequence numbers skipped"
        if self.missing is None:
            return head + "; no device report (telemetry_published) in /diagnostics"
        return head + (f"; the device reported {self.published} published up to sequence "
                       f"{self.last_sequence}, the bag holds {self.recorded_until} of them: "
                       + ("complete" if self.missing == 0 else f"{self.missing} missing"))


def _namespace(status_name: str) -> str:
    """'/wheel0/sim: simulator' -> '/wheel0' (the reporting node's namespace)."""
    node = status_name.split(":", 1)[0].strip()
    return node.rsplit("/", 1)[0]


def bag_completeness(path: str | os.PathLike) -> list[Completeness]:
    """One :class:`Completeness` per namespace with a ``telemetry`` topic, by namespace."""
    sequences: dict[str, list[int]] = {}
    reports: dict[str, tuple[int, int]] = {}
    for topic, _t, msg in read_messages(path, select=lambda name: name.endswith(
            SUFFIX_TELEMETRY) or name == "/diagnostics"):
        if topic.endswith(SUFFIX_TELEMETRY):
            sequences.setdefault(topic[:-len(SUFFIX_TELEMETRY)], []).append(int(msg.sequence))
            continue
        for status in msg.status:
            values = {kv.key: kv.value for kv in status.values}
            if values.get(LAST_SEQUENCE_KEY, "-") != "-" and PUBLISHED_KEY in values:
                reports[_namespace(status.name)] = (int(values[PUBLISHED_KEY]),
                                                    int(values[LAST_SEQUENCE_KEY]))
    out = []
    for ns in sorted(sequences):
        seq = sorted(sequences[ns])
        gaps = sum(b - a - 1 for a, b in zip(seq, seq[1:]) if b > a + 1)
        published, last = reports.get(ns, (None, None))
        until = None if last is None else sum(1 for s in seq if s <= last)
        out.append(Completeness(ns, len(seq), gaps, published, last, until))
    return out
