"""Bags without ROS: MCAP files in rosbag2's directory layout, written and read with ``mcap``.

A bag is a directory ``<name>/`` holding ``<name>_0.mcap`` and ``metadata.yaml`` (rosbag2
metadata version 9, as Jazzy writes it).  Messages are CDR-encoded and every channel's schema
is the full ``ros2msg`` definition, so ``ros2 bag info/play``, Foxglove, rosbags and our
tools all open the same bag.  The MCAP file also carries rosbag2's ``rosbag2`` metadata
record and per-channel ``offered_qos_profiles`` / ``topic_type_hash``, as Jazzy's MCAP
storage plugin writes them.
"""
from __future__ import annotations

import os
import struct
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping

import yaml
from mcap.exceptions import McapError
from mcap.reader import NonSeekingReader, make_reader
from mcap.records import Metadata
from mcap.stream_reader import CRCValidationError, StreamReader
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter
from mcap_ros2._dynamic import serialize_dynamic  # the CDR encoder behind mcap_ros2's Writer
from mcap_ros2.decoder import DecoderFactory

from hasel_wheel_bag import interfaces
from hasel_wheel_bag.cdr_flat import CDR_LE, flat_decoder
from hasel_wheel_common.topics import QosSpec

try:                                    # mcap's own zstd decoder (a dependency of mcap)
    from zstandard import ZstdError
except ImportError:                     # pragma: no cover
    ZstdError = McapError

ROS_DISTRO = "jazzy"
METADATA_VERSION = 9
MCAP0_MAGIC = b"\x89MCAP0\r\n"       # the first (and last) 8 bytes of an MCAP file
#: Name of the MCAP metadata records that carry the run's configuration (custom_data).
CONFIG_RECORD = "hasel_wheel/configuration"


class BagError(RuntimeError):
    """A bag cannot be written or read; the message says which file and why."""


@dataclass
class _Channel:
    channel_id: int
    type: str
    qos: QosSpec
    encoder: Any
    count: int = 0


def _qos_yaml(qos: QosSpec) -> str:
    return yaml.safe_dump([qos.rosbag2()], sort_keys=False)


def stamp(t_ns: int) -> dict[str, int]:
    """builtin_interfaces/Time as a dict from nanoseconds."""
    return {"sec": int(t_ns // 1_000_000_000), "nanosec": int(t_ns % 1_000_000_000)}


class _HandOver:
    """A file for the MCAP writer that flushes every write to the OS at once (the file itself
    is buffered).  The writer writes a finished chunk in one write and its message indexes
    in the next, so a recorder killed with SIGKILL leaves every finished chunk (at worst
    without the last chunk's indexes, which the reader does not need) and loses only the
    chunk it was still filling in memory."""

    def __init__(self, fh: Any) -> None:
        self._fh = fh

    def write(self, data: bytes) -> int:
        n = self._fh.write(data)
        self._fh.flush()
        return n

    def tell(self) -> int:
        return self._fh.tell()

    def flush(self) -> None:
        self._fh.flush()


class BagWriter:
    """Write messages (given as dicts) to a new rosbag2-layout MCAP bag.

    >>> with BagWriter("out/run1") as bag:                        # doctest: +SKIP
    ...     bag.add_topic("/telemetry", "hasel_wheel_msgs/msg/WheelTelemetry", SENSOR)
    ...     bag.write("/telemetry", {...}, t_ns)
    """

    def __init__(self, path: str | os.PathLike, chunk_size: int = 1024 * 1024,
                 custom_data: Mapping[str, str] | None = None) -> None:
        """``chunk_size``: bytes of uncompressed messages per chunk (the most a killed
        recorder loses); ``custom_data``: strings for metadata.yaml's custom_data."""
        self.path = Path(path)
        if self.path.exists() and any(self.path.iterdir()):
            raise BagError(f"{self.path}: bag directory exists and is not empty; choose a new "
                           f"output directory or remove the old bag")
        self.path.mkdir(parents=True, exist_ok=True)
        self.file_name = f"{self.path.name}_0.mcap"
        self._fh = open(self.path / self.file_name, "wb")
        self._mcap = McapWriter(_HandOver(self._fh), chunk_size=chunk_size,
                                compression=CompressionType.ZSTD)
        self._mcap.start(profile="ros2", library="hasel_wheel_bag.bagio (mcap-python)")
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, _Channel] = {}
        self._t_min: int | None = None
        self._t_max: int | None = None
        self.custom_data: dict[str, str] = {}
        self._closed = False
        self.add_custom_data(custom_data or {})

    def add_custom_data(self, data: Mapping[str, str]) -> None:
        """Add strings to the bag's configuration: metadata.yaml's custom_data, and at once an
        MCAP metadata record (:data:`CONFIG_RECORD`), so even a killed recording keeps it."""
        bad = {k: type(v).__name__ for k, v in data.items() if not isinstance(v, str)}
        if bad:
            raise BagError(f"custom data must be strings (YAML text for structures); got {bad}")
        if data:
            self.custom_data.update(data)
            self._mcap.add_metadata(CONFIG_RECORD, dict(data))

    def add_topic(self, topic: str, datatype: str, qos: QosSpec) -> None:
        """Declare a topic before writing to it (its schema is embedded once per type)."""
        if topic in self._channels:
            raise BagError(f"topic {topic!r} is already declared")
        if datatype not in self._schemas:
            text = interfaces.full_definition(datatype)
            self._schemas[datatype] = self._mcap.register_schema(datatype, "ros2msg", text.encode())
        encoders = serialize_dynamic(datatype, interfaces.full_definition(datatype))
        cid = self._mcap.register_channel(topic, "cdr", self._schemas[datatype],
                                          {"offered_qos_profiles": _qos_yaml(qos),
                                           "topic_type_hash": ""})
        self._channels[topic] = _Channel(cid, datatype, qos, encoders[datatype])

    def write(self, topic: str, message: Mapping[str, Any], t_ns: int) -> None:
        """Encode ``message`` (a dict shaped like the ROS message) and write it at ``t_ns``."""
        ch = self._channels.get(topic)
        if ch is None:
            raise BagError(f"topic {topic!r} was not declared with add_topic()")
        data = ch.encoder(message)
        self._mcap.add_message(ch.channel_id, log_time=t_ns, data=data, publish_time=t_ns,
                               sequence=ch.count)
        ch.count += 1
        if self._t_min is None or t_ns < self._t_min:
            self._t_min = t_ns
        if self._t_max is None or t_ns > self._t_max:
            self._t_max = t_ns

    def metadata(self) -> dict[str, Any]:
        """rosbag2 metadata (version 9) of what has been written so far."""
        start = self._t_min or 0
        duration = (self._t_max - start) if self._t_max is not None else 0
        total = sum(c.count for c in self._channels.values())
        return {"rosbag2_bagfile_information": {
            "version": METADATA_VERSION,
            "storage_identifier": "mcap",
            "duration": {"nanoseconds": duration},
            "starting_time": {"nanoseconds_since_epoch": start},
            "message_count": total,
            "topics_with_message_count": [
                {"topic_metadata": {"name": name, "type": c.type, "serialization_format": "cdr",
                                    "offered_qos_profiles": [c.qos.rosbag2()],
                                    "type_description_hash": ""},
                 "message_count": c.count}
                for name, c in self._channels.items()],
            "compression_format": "",
            "compression_mode": "",
            "relative_file_paths": [self.file_name],
            "files": [{"path": self.file_name,
                       "starting_time": {"nanoseconds_since_epoch": start},
                       "duration": {"nanoseconds": duration},
                       "message_count": total}],
            "custom_data": dict(self.custom_data) or None,
            "ros_distro": ROS_DISTRO,
        }}

    def close(self) -> None:
        """Finish the MCAP file (summary, rosbag2 record) and write metadata.yaml."""
        if self._closed:
            return
        meta = self.metadata()
        inner = yaml.safe_dump(meta["rosbag2_bagfile_information"], sort_keys=False)
        self._mcap.add_metadata("rosbag2", {"serialized_metadata": inner})
        self._mcap.finish()
        self._fh.close()
        with open(self.path / "metadata.yaml", "w", encoding="utf-8") as f:
            yaml.safe_dump(meta, f, sort_keys=False)
        self._closed = True

    def __enter__(self) -> "BagWriter":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def bag_metadata(path: str | os.PathLike) -> dict[str, Any] | None:
    """The ``rosbag2_bagfile_information`` mapping of a bag directory's metadata.yaml, or
    None when there is none (a lone .mcap file, or a killed recording).  A metadata.yaml that
    is not rosbag2 metadata raises :class:`BagError` naming it."""
    meta = Path(path) / "metadata.yaml"
    if not meta.is_file():
        return None
    try:
        data = yaml.safe_load(meta.read_text(encoding="utf-8"))
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise BagError(f"{meta}: not readable YAML ({exc}); delete it and run `ros2 bag "
                       f"reindex` or read the .mcap file directly") from exc
    info = data.get("rosbag2_bagfile_information") if isinstance(data, dict) else None
    if not isinstance(info, dict):
        raise BagError(f"{meta}: no 'rosbag2_bagfile_information' mapping, so not rosbag2 "
                       f"metadata; delete it and run `ros2 bag reindex` or read the .mcap file "
                       f"directly")
    return info


def bag_configuration(path: str | os.PathLike) -> dict[str, str]:
    """The configuration a bag was recorded with (key -> text): the :data:`CONFIG_RECORD`
    metadata records of its first MCAP file (written before its first message, so a killed
    recording keeps them), updated by metadata.yaml's custom_data (which ``ros2 bag record
    --custom-data`` writes, and which a ``ros2 bag reindex`` leaves out); {} when neither has
    any."""
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
        if _has_summary(fh):
            fh.seek(0)
            records = make_reader(fh).iter_metadata()
        else:                      # killed: scan the top-level records (chunks not opened)
            fh.seek(0)
            records = (r for r in StreamReader(fh, emit_chunks=True).records
                       if isinstance(r, Metadata))
        try:
            for record in records:
                if record.name == CONFIG_RECORD:
                    out.update(record.metadata)
        except (McapError, ValueError, struct.error, EOFError):
            pass                   # a file cut inside a record: what was read before it
    return out


def mcap_files(path: str | os.PathLike) -> list[Path]:
    """The MCAP files of a bag directory (in metadata order) or a single .mcap file."""
    p = Path(path)
    if p.is_file():
        return [p]
    if not p.is_dir():
        raise BagError(f"{p}: no such bag (expected a rosbag2 directory or a .mcap file)")
    info = bag_metadata(p)
    if info is not None:
        names = info.get("relative_file_paths")
        if not isinstance(names, list) or not names:
            raise BagError(f"{p / 'metadata.yaml'}: no relative_file_paths list; delete it and "
                           f"run `ros2 bag reindex` or read the .mcap file directly")
        return [p / str(f) for f in names]
    files = sorted(p.glob("*.mcap"))
    if not files:
        raise BagError(f"{p}: directory holds neither metadata.yaml nor any .mcap file")
    return files


def read_messages(path: str | os.PathLike, topics: list[str] | None = None,
                  warn: Callable[[str], None] | None = None,
                  select: Callable[[str], bool] | None = None,
                  progress: str | None = None) -> Iterator[tuple[str, int, Any]]:
    """Yield (topic, log_time_ns, decoded message) from a bag, in log-time order per file.

    A file that was never finished (the recorder was killed: no summary, maybe a record cut
    off at the end) is read record by record, in the order it was written, up to the last
    complete chunk, and ``warn`` (e.g. ``print``; default :func:`warnings.warn`) is told what
    was lost.  A channel whose messages cannot be decoded (a type without a ros2msg schema)
    is skipped with one warning.  A file that is not MCAP at all raises :class:`BagError`
    naming it.  ``select(topic)``, when given, picks topics by name before anything is
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


def topic_names(path: str | os.PathLike) -> set[str] | None:
    """The bag's topics that hold messages, from its metadata.yaml, without reading a
    message; None when there is no metadata (a single .mcap file, or a killed recording)."""
    info = bag_metadata(path) if Path(path).is_dir() else None
    if info is None:
        return None
    try:
        return {t["topic_metadata"]["name"] for t in info.get("topics_with_message_count") or []
                if t.get("message_count", 0) > 0}
    except (TypeError, KeyError, AttributeError):
        return None                     # malformed: the caller reads the messages instead


def file_finished(f: str | os.PathLike) -> bool:
    """Whether an MCAP file was closed properly (it ends with its summary and footer)."""
    with open(f, "rb") as fh:
        return _has_summary(fh)


def _files(path: str | os.PathLike, topics: list[str] | None, say: Callable[[str], None],
           select: Callable[[str], bool] | None = None, progress: str | None = None
           ) -> Iterator[tuple[Path, Iterator[tuple[Any, Any, Any]]]]:
    """(file, its (schema, channel, message) records) for every MCAP file of a bag, only of
    ``topics`` and of topics ``select`` accepts (when given).  Each file stays open while its
    records are consumed; a consumer that stops early leaves it to be closed when this
    generator is (garbage-)collected or closed."""
    for f in mcap_files(path):
        if not f.is_file():
            raise BagError(f"{f}: listed in the bag's metadata.yaml but missing")
        if f.stat().st_size == 0:
            raise BagError(f"{f}: empty file (the recorder stopped before writing anything)")
        with open(f, "rb") as fh:
            if fh.read(len(MCAP0_MAGIC)) != MCAP0_MAGIC:
                raise BagError(f"{f}: not an MCAP file (it does not start with the MCAP magic "
                               f"bytes); a rosbag2 bag here must use the mcap storage")
            fh.seek(0)
            finished = _has_summary(fh)
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
                records = _recover(fh, f, topics, say)
            if select is not None:
                records = (r for r in records if select(r[1].topic))
            if progress:
                records = _progress_bar(records, f"{progress}: {f.name}", total)
            yield f, records


def _progress_bar(records: Iterator[Any], label: str, total: int | None) -> Iterator[Any]:
    """``records`` with a tqdm bar on stderr (left out when stderr is not a terminal)."""
    from tqdm import tqdm
    with tqdm(records, desc=label, total=total, unit=" msg", unit_scale=True, disable=None,
              leave=False, mininterval=0.5) as bar:
        yield from bar


def _named_errors(records: Iterator[Any], f: Path) -> Iterator[Any]:
    """Records of a finished file; a corrupt one becomes a :class:`BagError` naming the file."""
    try:
        yield from records
    except (McapError, ValueError, struct.error, ZstdError, RuntimeError) as exc:
        raise BagError(f"{f}: corrupt MCAP data ({type(exc).__name__}: {exc}); the file was "
                       f"closed properly, so this is damage, not a killed recording") from exc


def _has_summary(fh: Any) -> bool:
    """Whether the file was finished: it ends with the closing MCAP magic (after the footer;
    a finished file may still have no summary section, and is then read in order)."""
    fh.seek(0, os.SEEK_END)
    if fh.tell() < 2 * len(MCAP0_MAGIC):
        return False
    fh.seek(-len(MCAP0_MAGIC), os.SEEK_END)
    return fh.read(len(MCAP0_MAGIC)) == MCAP0_MAGIC


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
        say(f"{f}: topic {channel.topic}: its schema cannot be read ({exc}); skipped")
        return None
    if generic is None:
        say(f"{f}: topic {channel.topic} ({channel.message_encoding}, schema "
            f"{schema.name if schema else 'none'}) has no ROS 2 decoder; skipped")
        return None
    if channel.message_encoding != "cdr" or schema is None or schema.encoding != "ros2msg":
        return generic
    flat = flat_decoder(schema.name, schema.data.decode("utf-8", "replace"))
    if flat is None:
        return generic

    def decode(data: bytes) -> Any:
        return flat(data) if data[:2] == CDR_LE else generic(data)

    return decode


def _recover(fh: Any, f: Path, topics: list[str] | None,
             say: Callable[[str], None]) -> Iterator[tuple[Any, Any, Any]]:
    """(schema, channel, message) records of an unfinished file, in file order, up to where
    it breaks off."""
    reader = NonSeekingReader(fh, validate_crcs=True)
    count, last = 0, None
    try:
        for record in reader.iter_messages(topics=topics, log_time_order=False):
            count += 1
            last = record[2].log_time
            yield record
    except CRCValidationError as exc:
        say(f"{f}: the recording was not closed (killed?), and a chunk's checksum is wrong "
            f"({exc}); read {count} messages{_until(last)}; reading stops at the damaged "
            f"chunk, and every chunk after it is lost too")
    except (McapError, ValueError, struct.error, ZstdError) as exc:
        size, at = f.stat().st_size, _whole_records_end(fh)
        where = (f"ends after its last finished chunk at byte {size}" if at >= size else
                 f"is cut inside a record that starts at byte {at} of {size} "
                 f"({type(exc).__name__})")
        say(f"{f}: the recording was not closed (killed?) and {where}; read {count} messages"
            f"{_until(last)}; lost: what the recorder still held in memory (at most one "
            f"chunk){'' if at >= size else ' and the record that was cut'}")
    else:
        say(f"{f}: the recording was not closed (killed?): no summary, but every chunk is "
            f"whole; read {count} messages{_until(last)}; lost: what the recorder still held "
            f"in memory (at most one chunk)")


def _whole_records_end(fh: Any) -> int:
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
