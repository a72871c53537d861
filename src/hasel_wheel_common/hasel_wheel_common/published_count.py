"""The device node's count of the telemetry it has published, as it reports it in
``/diagnostics``, so that a bag can be checked for completeness against it
(``hasel_wheel bag completeness``; test: ``test_bag_completeness.py``).

Both device nodes (driver and sim) report, under their status, ``telemetry_published``
(samples published since start) and ``telemetry_last_sequence`` (the ``sequence`` of the
last one): every sample of the bag with a sequence up to that one was published, and a
complete recording holds exactly ``telemetry_published`` of them.
"""
from __future__ import annotations

PUBLISHED_KEY = "telemetry_published"
LAST_SEQUENCE_KEY = "telemetry_last_sequence"


class PublishedCount:
    """Telemetry samples published so far and the sequence number of the last one."""

    def __init__(self) -> None:
        self.published = 0
        self.last_sequence: int | None = None

    def count(self, sequence: int) -> None:
        """One sample with this device sequence number was published."""
        self.published += 1
        self.last_sequence = sequence

    def diagnostics(self) -> dict[str, str]:
        """The two /diagnostics values (last sequence '-' before the first sample)."""
        return {PUBLISHED_KEY: str(self.published),
                LAST_SEQUENCE_KEY: "-" if self.last_sequence is None else str(self.last_sequence)}
