"""Bag topics to CSV, one file per topic, with flat columns (no rclpy, no ROS).

Columns: ``t`` (the message's log time [s] on the bag's clock: the embedded runner's
simulated time from 0, or ROS time since the epoch), then every field
of the message flattened with dots (``header.stamp.sec``, ``position[0]``).  Arrays are
flattened by index; the first message of a topic fixes how many columns an array gets, and a
later message with a different length fills what fits and is counted in the returned
report, never silently.  Units are those of the message definitions (SI, radians).
"""
from __future__ import annotations

import csv
import os
import warnings
from pathlib import Path
from typing import Any, Callable, Mapping

from .bagio import read_messages


def flatten(msg: Any, prefix: str = "") -> dict[str, Any]:
    """{dotted field name: value} of a decoded message (nested messages and arrays
    flattened; strings kept as they are).  A message may be decoded by mcap-ros2-support
    (fields in ``__slots__``), by :mod:`.cdr_flat` (a namedtuple) or be a dict of fields."""
    out: dict[str, Any] = {}
    names = getattr(msg, "_fields", None) if isinstance(msg, tuple) else getattr(
        msg, "__slots__", None)
    if isinstance(msg, Mapping):
        items = msg.items()
    elif names is not None:
        items = ((name, getattr(msg, name)) for name in names)
    else:
        items = None
    if items is not None:
        for name, value in items:
            out.update(flatten(value, f"{prefix}{name}."))
        return out
    key = prefix[:-1]
    if isinstance(msg, (list, tuple)):
        for i, v in enumerate(msg):
            out.update(flatten(v, f"{key}[{i}]."))
        return out
    if isinstance(msg, (bytes, bytearray)):
        return {key: msg.hex()}
    return {key: msg}


def export_csv(path: str | os.PathLike, out_dir: str | os.PathLike,
               topics: list[str] | None = None,
               warn: Callable[[str], None] | None = None) -> dict[str, dict[str, Any]]:
    """Write ``<out_dir>/<topic with / as __>.csv`` for each topic (all when ``topics`` is
    None).  Returns {topic: {"file", "rows", "misfits"}}: misfits counts messages whose
    arrays had another length than the first's."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    writers: dict[str, tuple[Any, Any, list[str]]] = {}
    report: dict[str, dict[str, Any]] = {}
    try:
        for topic, t_ns, msg in read_messages(path, topics=topics, warn=warn):
            row = flatten(msg)
            if topic not in writers:
                name = topic.strip("/").replace("/", "__") or "root"
                fh = open(out / f"{name}.csv", "w", newline="", encoding="utf-8")
                columns = ["t"] + list(row)
                w = csv.writer(fh)
                w.writerow(columns)
                writers[topic] = (fh, w, columns)
                report[topic] = {"file": str(out / f"{name}.csv"), "rows": 0, "misfits": 0}
            fh, w, columns = writers[topic]
            if len(row) != len(columns) - 1 or any(c not in row for c in columns[1:]):
                report[topic]["misfits"] += 1
            w.writerow([f"{t_ns / 1e9:.9f}"] + [row.get(c, "") for c in columns[1:]])
            report[topic]["rows"] += 1
    finally:
        for fh, _, _ in writers.values():
            fh.close()
    if topics:
        missing = [t for t in topics if t not in report]
        if missing:
            (warn or warnings.warn)(f"{path}: no messages on {', '.join(missing)} (check the "
                                    f"names with `hasel_wheel bag info`)")
    return report
