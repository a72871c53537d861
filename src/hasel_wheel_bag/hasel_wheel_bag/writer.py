"""Writing bags without ROS: :class:`BagWriter`, MCAP in rosbag2's directory layout.

Messages are CDR-encoded (:mod:`.cdr_encode`) and every channel's schema is the full
``ros2msg`` definition (:mod:`.interfaces`), so ``ros2 bag info/play``, Foxglove, rosbags and
our tools all open the same bag.  The MCAP file also carries rosbag2's ``rosbag2`` metadata
record and per-channel ``offered_qos_profiles`` / ``topic_type_hash``, as Jazzy's MCAP
storage plugin writes them; ``metadata.yaml`` is rosbag2 metadata version 9.
``test_bag_roundtrip.py`` holds these rules (rosbags reads every field back).
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping

import yaml
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter

from hasel_wheel_bag import interfaces
from hasel_wheel_bag.cdr_encode import encoder_for
from hasel_wheel_bag.layout import (CONFIG_RECORD, METADATA_VERSION, ROS_DISTRO, BagError,
                                    BagErrorCode)
from hasel_wheel_common.topics import QosSpec

#: The MCAP header's library field of the bags we write.
LIBRARY = "hasel_wheel_bag.writer (mcap-python)"


@dataclass
class _Channel:
    channel_id: int
    type: str
    qos: QosSpec
    encoder: Callable[[Any], bytes]
    count: int = 0


def _qos_yaml(qos: QosSpec) -> str:
    return yaml.safe_dump([qos.rosbag2()], sort_keys=False)


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
    ...     bag.add_topic("/telemetry", "hasel_wheel_msgs/msg/WheelTelemetry", STREAM)
    ...     bag.write("/telemetry", {...}, t_ns)
    """

    def __init__(self, path: str | os.PathLike, chunk_size: int = 1024 * 1024,
                 custom_data: Mapping[str, str] | None = None) -> None:
        """``chunk_size``: bytes of uncompressed messages per chunk (the most a killed
        recorder loses); ``custom_data``: strings for metadata.yaml's custom_data."""
        self.path = Path(path)
        if self.path.exists() and any(self.path.iterdir()):
            raise BagError(f"{self.path}: bag directory exists and is not empty; choose a new "
                           f"output directory or remove the old bag", BagErrorCode.EXISTS)
        self.path.mkdir(parents=True, exist_ok=True)
        self.file_name = f"{self.path.name}_0.mcap"
        self._fh = open(self.path / self.file_name, "wb")
        self._mcap = McapWriter(_HandOver(self._fh), chunk_size=chunk_size,
                                compression=CompressionType.ZSTD)
        self._mcap.start(profile="ros2", library=LIBRARY)
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, _Channel] = {}
        self._t_min: int | None = None
        self._t_max: int | None = None
        self.custom_data: dict[str, str] = {}
        self._closed = False
        self.add_custom_data(custom_data or {})

    def add_custom_data(self, data: Mapping[str, str]) -> None:
        """Add strings to the bag's configuration: metadata.yaml's custom_data, and at once an
        MCAP metadata record (:data:`~.layout.CONFIG_RECORD`), so even a killed recording
        keeps it."""
        bad = {k: type(v).__name__ for k, v in data.items() if not isinstance(v, str)}
        if bad:
            raise BagError(f"custom data must be strings (YAML text for structures); got {bad}",
                           BagErrorCode.CUSTOM_DATA_NOT_TEXT)
        if data:
            self.custom_data.update(data)
            self._mcap.add_metadata(CONFIG_RECORD, dict(data))

    def add_topic(self, topic: str, datatype: str, qos: QosSpec) -> None:
        """Declare a topic before writing to it (its schema is embedded once per type)."""
        if topic in self._channels:
            raise BagError(f"topic {topic!r} is already declared", BagErrorCode.TOPIC_DECLARED)
        text = interfaces.full_definition(datatype)
        if datatype not in self._schemas:
            self._schemas[datatype] = self._mcap.register_schema(datatype, "ros2msg", text.encode())
        cid = self._mcap.register_channel(topic, "cdr", self._schemas[datatype],
                                          {"offered_qos_profiles": _qos_yaml(qos),
                                           "topic_type_hash": ""})
        self._channels[topic] = _Channel(cid, datatype, qos, encoder_for(datatype, text))

    def write(self, topic: str, message: Mapping[str, Any], t_ns: int) -> None:
        """Encode ``message`` (a dict shaped like the ROS message) and write it at ``t_ns``."""
        ch = self._channels.get(topic)
        if ch is None:
            raise BagError(f"topic {topic!r} was not declared with add_topic()",
                           BagErrorCode.TOPIC_UNDECLARED)
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
