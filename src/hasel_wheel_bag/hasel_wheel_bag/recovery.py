"""Reading an MCAP file whose recorder was killed: no summary, maybe a record cut off.

Such a file is read record by record, in the order it was written, up to where it breaks
off: every finished chunk is read, and what is lost is what the recorder still held in
memory (at most one chunk) and a record that was cut.  The reader's ``warn`` callback is
told what was lost.  ``test_bag_recovery.py`` holds these rules.
"""
from __future__ import annotations

import os
import struct
from pathlib import Path
from typing import Any, Callable, Iterator

from mcap.reader import NonSeekingReader
from mcap.records import Metadata
from mcap.stream_reader import CRCValidationError, StreamReader

from hasel_wheel_bag.layout import (MCAP0_MAGIC, MCAP_DATA_ERRORS, NOTE_BAD_CHECKSUM, NOTE_CUT,
                                    NOTE_UNFINISHED, BagNote)


def recovered_records(fh: Any, f: Path, topics: list[str] | None,
                      say: Callable[[str], None]) -> Iterator[tuple[Any, Any, Any]]:
    """(schema, channel, message) records of the unfinished file ``fh`` (named ``f``), in
    file order, only of ``topics`` when given, up to where it breaks off; then one
    ``say(note)`` (a :class:`~.layout.BagNote`) naming what was lost."""
    reader = NonSeekingReader(fh, validate_crcs=True)
    count, last = 0, None
    try:
        for record in reader.iter_messages(topics=topics, log_time_order=False):
            count += 1
            last = record[2].log_time
            yield record
    except CRCValidationError as exc:
        say(BagNote(f"{f}: the recording was not closed (killed?), and a chunk's checksum is "
                    f"wrong ({exc}); read {count} messages{_until(last)}; reading stops at the "
                    f"damaged chunk, and every chunk after it is lost too",
                    NOTE_BAD_CHECKSUM, messages=count))
    except MCAP_DATA_ERRORS as exc:
        size, at = f.stat().st_size, whole_records_end(fh)
        where = (f"ends after its last finished chunk at byte {size}" if at >= size else
                 f"is cut inside a record that starts at byte {at} of {size} "
                 f"({type(exc).__name__})")
        text = (f"{f}: the recording was not closed (killed?) and {where}; read {count} "
                f"messages{_until(last)}; lost: what the recorder still held in memory (at most "
                f"one chunk){'' if at >= size else ' and the record that was cut'}")
        say(BagNote(text, NOTE_UNFINISHED, messages=count) if at >= size else
            BagNote(text, NOTE_CUT, messages=count, cut_at=at, size=size))
    else:
        say(BagNote(f"{f}: the recording was not closed (killed?): no summary, but every chunk "
                    f"is whole; read {count} messages{_until(last)}; lost: what the recorder "
                    f"still held in memory (at most one chunk)", NOTE_UNFINISHED, messages=count))


def recovered_metadata(fh: Any) -> Iterator[Metadata]:
    """The metadata records of the unfinished file ``fh``, from its start, top-level records
    only (chunks are not opened); stops without error where the file is cut."""
    fh.seek(0)
    try:
        for record in StreamReader(fh, emit_chunks=True).records:
            if isinstance(record, Metadata):
                yield record
    except (*MCAP_DATA_ERRORS, EOFError):
        return                     # a file cut inside a record: what was read before it


def whole_records_end(fh: Any) -> int:
    """Byte offset where the file's whole records end (MCAP records are an opcode byte and
    a little-endian uint64 length, then that many bytes)."""
    fh.seek(0, os.SEEK_END)
    size = fh.tell()
    pos = len(MCAP0_MAGIC)
    while pos + 9 <= size:
        fh.seek(pos + 1)
        (length,) = struct.unpack("<Q", fh.read(8))
        if pos + 9 + length > size:
            break
        pos += 9 + length
    return pos


def _until(t_ns: int | None) -> str:
    return "" if t_ns is None else f", up to t = {t_ns / 1e9:.6f} s"
