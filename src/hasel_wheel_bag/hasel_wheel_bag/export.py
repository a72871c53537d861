"""Bag topics to CSV or Parquet, one file per topic, with flat columns (no rclpy, no ROS).

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

from hasel_wheel_bag.layout import BagError, BagErrorCode

from hasel_wheel_bag.reader import read_messages


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


class _CsvSink:
    suffix = ".csv"

    def __init__(self, file: Path, columns: list[str]) -> None:
        self._fh = open(file, "w", newline="", encoding="utf-8")
        self._w = csv.writer(self._fh)
        self._w.writerow(columns)

    def add(self, row: list[Any]) -> None:
        self._w.writerow([f"{row[0]:.9f}"] + ["" if v is None else v for v in row[1:]])

    def close(self) -> None:
        self._fh.close()


class _ParquetSink:
    """Rows gathered in batches of ``BATCH`` and written as row groups (bounded memory); the
    column types are fixed by the first batch."""

    suffix = ".parquet"
    BATCH = 50_000

    def __init__(self, file: Path, columns: list[str]) -> None:
        try:
            import pyarrow as pa
            import pyarrow.parquet as pq
        except ImportError as exc:
            raise BagError(f"Parquet export needs pyarrow, which cannot be imported ({exc}); "
                           f"install it (pip install 'pyarrow>=15'; with NumPy 1.x, as on "
                           f"Ubuntu 24.04: 'pyarrow>=15,<26') or export CSV",
                           BagErrorCode.EXPORT_NEEDS_PYARROW) from exc
        self._pa, self._pq = pa, pq
        self._file, self._columns = file, columns
        self._rows: list[list[Any]] = []
        self._writer = None
        self._schema = None

    def add(self, row: list[Any]) -> None:
        self._rows.append(row)
        if len(self._rows) >= self.BATCH:
            self._flush()

    def _flush(self) -> None:
        if not self._rows:
            return
        cols = {c: [r[i] for r in self._rows] for i, c in enumerate(self._columns)}
        table = self._pa.Table.from_pydict(cols, schema=self._schema)
        if self._writer is None:
            self._schema = table.schema
            self._writer = self._pq.ParquetWriter(self._file, self._schema)
        self._writer.write_table(table)
        self._rows = []

    def close(self) -> None:
        self._flush()
        if self._writer is not None:
            self._writer.close()


FORMATS = {"csv": _CsvSink, "parquet": _ParquetSink}


def export(path: str | os.PathLike, out_dir: str | os.PathLike,
           topics: list[str] | None = None, fmt: str = "csv",
           warn: Callable[[str], None] | None = None,
           progress: bool = False) -> dict[str, dict[str, Any]]:
    """Write ``<out_dir>/<topic with / as __>.<csv|parquet>`` for each topic (all when
    ``topics`` is None); ``fmt`` 'csv' or 'parquet' (needs pyarrow).  Column ``t`` is the log
    time [s], then the flattened fields.  Returns {topic: {"file", "rows", "misfits"}}:
    misfits counts messages whose arrays had another length than the first's (their
    missing cells are empty).  ``progress``: a progress bar on stderr (on a terminal)."""
    if fmt not in FORMATS:
        raise BagError(f"export format {fmt!r}: expected one of {sorted(FORMATS)}",
                       BagErrorCode.EXPORT_FORMAT)
    sink_cls = FORMATS[fmt]
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    sinks: dict[str, tuple[Any, list[str]]] = {}
    report: dict[str, dict[str, Any]] = {}
    try:
        for topic, t_ns, msg in read_messages(path, topics=topics, warn=warn,
                                              progress="bag export" if progress else None):
            row = flatten(msg)
            if topic not in sinks:
                name = topic.strip("/").replace("/", "__") or "root"
                file = out / f"{name}{sink_cls.suffix}"
                columns = ["t"] + list(row)
                sinks[topic] = (sink_cls(file, columns), columns)
                report[topic] = {"file": str(file), "rows": 0, "misfits": 0}
            sink, columns = sinks[topic]
            if len(row) != len(columns) - 1 or any(c not in row for c in columns[1:]):
                report[topic]["misfits"] += 1
            sink.add([t_ns / 1e9] + [row.get(c) for c in columns[1:]])
            report[topic]["rows"] += 1
    finally:
        for sink, _ in sinks.values():
            sink.close()
    if topics:
        missing = [t for t in topics if t not in report]
        if missing:
            (warn or warnings.warn)(f"{path}: no messages on {', '.join(missing)} (check the "
                                    f"names with `hasel_wheel bag info`)")
    return report


def export_csv(path: str | os.PathLike, out_dir: str | os.PathLike,
               topics: list[str] | None = None,
               warn: Callable[[str], None] | None = None) -> dict[str, dict[str, Any]]:
    """:func:`export` as CSV."""
    return export(path, out_dir, topics, "csv", warn)
