"""Reading bags without ROS: messages decoded or raw, and the configuration they carry.

Files come from :func:`~.layout.mcap_files`.  A finished file is read in log-time order
through its summary; an unfinished one (the recorder was killed) through :mod:`.recovery`.
Flat ROS 2 types decode with :mod:`.cdr_flat`, the rest with mcap-ros2-support's
``DecoderFactory``.  ``test_bag_roundtrip.py`` and ``test_bag_recovery.py`` hold these rules.
"""
from __future__ import annotations

import os
import warnings
from pathlib import Path
from typing import Any, Callable, Iterator

from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

from hasel_wheel_bag.cdr_flat import CDR_LE, flat_decoder
from hasel_wheel_bag.layout import (CONFIG_RECORD, MCAP0_MAGIC, MCAP_DATA_ERRORS,
                                    NOTE_UNDECODABLE, BagError, BagErrorCode, BagNote,
                                    bag_metadata, has_summary, mcap_files)
from hasel_wheel_bag.progress import progress_bar
from hasel_wheel_bag.recovery import recovered_metadata, recovered_records


def read_messages(path: str | os.PathLike, topics: list[str] | None = None,
                  warn: Callable[[str], None] | None = None,
                  select: Callable[[str], bool] | None = None,
                  progress: str | None = None) -> Iterator[tuple[str, int, Any]]:
    """Yield (topic, log_time_ns, decoded message) from a bag, in log-time order per file.

    A file that was never finished (the recorder was killed: no summary, maybe a record cut
    off at the end) is read record by record, in the order it was written, up to the last
    complete chunk, and ``warn`` (e.g. ``print``; default :func:`warnings.warn`) is told what
    was lost.  A channel whose messages cannot be decoded (a type without a ros2msg schema)
    is skipped with one warning.  Warnings are :class:`~.layout.BagNote` texts.  A file that
    is not MCAP at all raises :class:`BagError` naming it.  ``select(topic)``, when given, picks topics by name before anything is
    decoded (e.g. by suffix, when the namespaces are not known in advance).  ``progress``,
    when given, labels a progress bar on stderr (shown only on a terminal)."""
    say = warn or (lambda text: warnings.warn(text, stacklevel=3))
    for f, records in _files(path, topics, say, select, progress):
        yield from _decoded(records, f, say)


def read_raw(path: str | os.PathLike, topics: list[str] | None = None,
             warn: Callable[[str], None] | None = None,
             progress: str | None = None) -> Iterator[tuple[str, str, int, bytes]]:
    """Yield (topic, type, log_time_ns, CDR bytes) from a bag without decoding (for counts,
    rates and copies); files and ``progress`` are handled as in :func:`read_messages`."""
    say = warn or (lambda text: warnings.warn(text, stacklevel=3))
    for _f, records in _files(path, topics, say, progress=progress):
        for schema, channel, message in records:
            yield (channel.topic, schema.name if schema else "", message.log_time,
                   message.data)


def bag_configuration(path: str | os.PathLike) -> dict[str, str]:
    """The configuration a bag was recorded with (key -> text): the
    :data:`~.layout.CONFIG_RECORD` metadata records of its first MCAP file (written before
    its first message, so a killed recording keeps them), updated by metadata.yaml's
    custom_data (which ``ros2 bag record --custom-data`` writes, and which a ``ros2 bag
    reindex`` leaves out); {} when neither has any."""
    p = Path(path)
    info = bag_metadata(p) if p.is_dir() else None
    custom = {str(k): str(v) for k, v in ((info or {}).get("custom_data") or {}).items()}
    return {**_config_records(p), **custom}


def _config_records(p: Path) -> dict[str, str]:
    files = mcap_files(p)
    out: dict[str, str] = {}
    if not files or not files[0].is_file():
        return out
    with open(files[0], "rb") as fh:
        if has_summary(fh):
            fh.seek(0)
            records = make_reader(fh).iter_metadata()
        else:
            records = recovered_metadata(fh)
        try:
            for record in records:
                if record.name == CONFIG_RECORD:
                    out.update(record.metadata)
        except (*MCAP_DATA_ERRORS, EOFError):
            pass                   # a file cut inside a record: what was read before it
    return out


def _files(path: str | os.PathLike, topics: list[str] | None, say: Callable[[str], None],
           select: Callable[[str], bool] | None = None, progress: str | None = None
           ) -> Iterator[tuple[Path, Iterator[tuple[Any, Any, Any]]]]:
    """(file, its (schema, channel, message) records) for every MCAP file of a bag, only of
    ``topics`` and of topics ``select`` accepts (when given).  Each file stays open while its
    records are consumed; a consumer that stops early leaves it to be closed when this
    generator is (garbage-)collected or closed."""
    for f in mcap_files(path):
        if not f.is_file():
            raise BagError(f"{f}: listed in the bag's metadata.yaml but missing",
                           BagErrorCode.FILE_MISSING)
        if f.stat().st_size == 0:
            raise BagError(f"{f}: empty file (the recorder stopped before writing anything)",
                           BagErrorCode.FILE_EMPTY)
        with open(f, "rb") as fh:
            if fh.read(len(MCAP0_MAGIC)) != MCAP0_MAGIC:
                raise BagError(f"{f}: not an MCAP file (it does not start with the MCAP magic "
                               f"bytes); a rosbag2 bag here must use the mcap storage",
                               BagErrorCode.NOT_MCAP)
            fh.seek(0)
            finished = has_summary(fh)
            fh.seek(0)
            total = None
            if finished:
                reader = make_reader(fh, validate_crcs=True)
                wanted = topics
                summary = reader.get_summary() if (select or progress) else None
                if summary is not None and select is not None:
                    # filter by channel before mcap orders messages by time: the unwanted
                    # ones then never enter its queue (most of the time of a filtered read)
                    wanted = {c.topic for c in summary.channels.values() if select(c.topic)
                              and (topics is None or c.topic in topics)}
                if summary is not None and summary.statistics is not None:
                    counts = summary.statistics.channel_message_counts
                    total = sum(n for cid, n in counts.items() if wanted is None
                                or summary.channels[cid].topic in wanted)
                records = _named_errors(reader.iter_messages(topics=wanted), f)
            else:
                records = recovered_records(fh, f, topics, say)
            if select is not None:
                records = (r for r in records if select(r[1].topic))
            if progress:
                records = progress_bar(records, f"{progress}: {f.name}", total)
            yield f, records


def _named_errors(records: Iterator[Any], f: Path) -> Iterator[Any]:
    """Records of a finished file; a corrupt one becomes a :class:`BagError` naming the file."""
    try:
        yield from records
    except (*MCAP_DATA_ERRORS, RuntimeError) as exc:
        raise BagError(f"{f}: corrupt MCAP data ({type(exc).__name__}: {exc}); the file was "
                       f"closed properly, so this is damage, not a killed recording",
                       BagErrorCode.CORRUPT) from exc


def _decoded(messages: Iterator[tuple[Any, Any, Any]], f: Path,
             say: Callable[[str], None]) -> Iterator[tuple[str, int, Any]]:
    """Decode (schema, channel, message) tuples; skip channels that have no decoder."""
    factory = DecoderFactory()
    decoders: dict[int, Any] = {}
    for schema, channel, message in messages:
        decode = decoders.get(channel.id, ...)
        if decode is ...:
            decode = decoders[channel.id] = _decoder_for(factory, schema, channel, f, say)
        if decode is not None:
            yield channel.topic, message.log_time, decode(message.data)


def _decoder_for(factory: DecoderFactory, schema: Any, channel: Any, f: Path,
                 say: Callable[[str], None]) -> Callable[[bytes], Any] | None:
    """The decoder of a channel: :mod:`.cdr_flat` for flat ROS 2 types (with the generic one
    for big-endian data), mcap-ros2-support's for the rest, None (and a warning) if none."""
    try:
        generic = factory.decoder_for(channel.message_encoding, schema)
    except Exception as exc:             # a schema the ros2msg parser rejects
        say(BagNote(f"{f}: topic {channel.topic}: its schema cannot be read ({exc}); skipped",
                    NOTE_UNDECODABLE, topic=channel.topic))
        return None
    if generic is None:
        say(BagNote(f"{f}: topic {channel.topic} ({channel.message_encoding}, schema "
                    f"{schema.name if schema else 'none'}) has no ROS 2 decoder; skipped",
                    NOTE_UNDECODABLE, topic=channel.topic))
        return None
    if channel.message_encoding != "cdr" or schema is None or schema.encoding != "ros2msg":
        return generic
    flat = flat_decoder(schema.name, schema.data.decode("utf-8", "replace"))
    if flat is None:
        return generic

    def decode(data: bytes) -> Any:
        return flat(data) if data[:2] == CDR_LE else generic(data)

    return decode
