"""The rosbag2 layout of a bag: which MCAP files it holds, its metadata.yaml, its constants.

A bag is a directory ``<name>/`` holding ``<name>_0.mcap`` and ``metadata.yaml`` (rosbag2
metadata version 9, as Jazzy writes it); a lone ``.mcap`` file is read as a bag too.  A file
was finished when it ends with the closing MCAP magic; one that does not was left by a
recorder that was killed (:mod:`.recovery` reads it).  Errors carry a :class:`BagErrorCode`
and warnings are :class:`BagNote` texts; ``test_bag_recovery.py`` holds both.
"""
from __future__ import annotations

import os
import struct
from enum import Enum
from pathlib import Path
from typing import Any

import yaml
from mcap.exceptions import McapError

try:                                    # mcap's own zstd decoder (a dependency of mcap)
    from zstandard import ZstdError
except ImportError:                     # pragma: no cover
    ZstdError = McapError

ROS_DISTRO = "jazzy"
METADATA_VERSION = 9
MCAP0_MAGIC = b"\x89MCAP0\r\n"       # the first (and last) 8 bytes of an MCAP file
#: Name of the MCAP metadata records that carry the run's configuration (custom_data).
CONFIG_RECORD = "hasel_wheel/configuration"
#: What mcap raises on damaged data (a cut record, a bad chunk, a wrong length).
MCAP_DATA_ERRORS = (McapError, ValueError, struct.error, ZstdError)


class BagErrorCode(str, Enum):
    """Why a bag cannot be written or read (:attr:`BagError.code`)."""

    OTHER = "other"
    EXISTS = "exists"                          # the output directory is not empty
    NO_SUCH_BAG = "no_such_bag"                # neither a directory nor a file
    NO_FILES = "no_files"                      # a directory without metadata.yaml or .mcap
    METADATA_NOT_YAML = "metadata_not_yaml"
    METADATA_NOT_ROSBAG2 = "metadata_not_rosbag2"
    METADATA_NO_FILE_LIST = "metadata_no_file_list"
    FILE_MISSING = "file_missing"              # listed in metadata.yaml, not on disk
    FILE_EMPTY = "file_empty"
    NOT_MCAP = "not_mcap"
    CORRUPT = "corrupt"                        # a finished file with damaged data
    TOPIC_DECLARED = "topic_declared"          # add_topic twice
    TOPIC_UNDECLARED = "topic_undeclared"      # write before add_topic
    CUSTOM_DATA_NOT_TEXT = "custom_data_not_text"
    EXPORT_FORMAT = "export_format"
    EXPORT_NEEDS_PYARROW = "export_needs_pyarrow"


class BagError(RuntimeError):
    """A bag cannot be written or read; the message says which file and why for a reader,
    :attr:`code` (a :class:`BagErrorCode`) says why for a program."""

    def __init__(self, message: str, code: BagErrorCode = BagErrorCode.OTHER) -> None:
        super().__init__(message)
        self.code = code


class BagNote(str):
    """A warning a reader passes to its ``warn`` callback: the text for a reader, with
    :attr:`kind` (one of the ``NOTE_*`` names) and :attr:`facts` (numbers, names) for a
    program.  It is a ``str``, so ``print`` and ``warnings.warn`` take it as it is."""

    kind: str
    facts: dict[str, Any]

    def __new__(cls, text: str, kind: str, **facts: Any) -> "BagNote":
        note = super().__new__(cls, text)
        note.kind = kind
        note.facts = facts
        return note


#: A killed recording whose chunks are all whole (facts: messages).
NOTE_UNFINISHED = "unfinished"
#: A killed recording cut inside a record (facts: messages, cut_at, size [bytes]).
NOTE_CUT = "cut"
#: A killed recording with a chunk whose checksum is wrong (facts: messages).
NOTE_BAD_CHECKSUM = "bad_checksum"
#: A channel skipped because its messages cannot be decoded (facts: topic).
NOTE_UNDECODABLE = "undecodable"


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
                       f"reindex` or read the .mcap file directly",
                       BagErrorCode.METADATA_NOT_YAML) from exc
    info = data.get("rosbag2_bagfile_information") if isinstance(data, dict) else None
    if not isinstance(info, dict):
        raise BagError(f"{meta}: no 'rosbag2_bagfile_information' mapping, so not rosbag2 "
                       f"metadata; delete it and run `ros2 bag reindex` or read the .mcap file "
                       f"directly", BagErrorCode.METADATA_NOT_ROSBAG2)
    return info


def mcap_files(path: str | os.PathLike) -> list[Path]:
    """The MCAP files of a bag directory (in metadata order) or a single .mcap file."""
    p = Path(path)
    if p.is_file():
        return [p]
    if not p.is_dir():
        raise BagError(f"{p}: no such bag (expected a rosbag2 directory or a .mcap file)",
                       BagErrorCode.NO_SUCH_BAG)
    info = bag_metadata(p)
    if info is not None:
        names = info.get("relative_file_paths")
        if not isinstance(names, list) or not names:
            raise BagError(f"{p / 'metadata.yaml'}: no relative_file_paths list; delete it and "
                           f"run `ros2 bag reindex` or read the .mcap file directly",
                           BagErrorCode.METADATA_NO_FILE_LIST)
        return [p / str(f) for f in names]
    files = sorted(p.glob("*.mcap"))
    if not files:
        raise BagError(f"{p}: directory holds neither metadata.yaml nor any .mcap file",
                       BagErrorCode.NO_FILES)
    return files


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
        return has_summary(fh)


def has_summary(fh: Any) -> bool:
    """Whether the open binary file ``fh`` was finished: it ends with the closing MCAP magic
    (after the footer; a finished file may still have no summary section, and is then read
    in order).  Moves the file position."""
    fh.seek(0, os.SEEK_END)
    if fh.tell() < 2 * len(MCAP0_MAGIC):
        return False
    fh.seek(-len(MCAP0_MAGIC), os.SEEK_END)
    return fh.read(len(MCAP0_MAGIC)) == MCAP0_MAGIC
