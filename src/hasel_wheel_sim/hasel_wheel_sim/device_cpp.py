"""The C++ firmware core (``firmware/core``), built for the host and driven from Python.

:func:`build_core` compiles it with the system's CMake and C++ compiler (once; later calls
reuse the build) and :class:`CppDeviceCore` loads the result with :mod:`ctypes`.  It has the
interface of :class:`~.device_core.DeviceCore`, so the virtual Teensy can run either, and the
tests hold the two to the same frames and state tick for tick (``test_firmware_lockstep.py``).
"""
from __future__ import annotations

import ctypes as C
import fcntl
import hashlib
import os
import shutil
import subprocess
from pathlib import Path

from hasel_wheel_common import protocol as P

from hasel_wheel_sim.device_core import DeviceState, Latched, Outputs, Sensors

#: The firmware sources: $HASEL_FIRMWARE_DIR, else ``firmware/`` of the repository this
#: package was installed from in development mode.
FIRMWARE_DIR = Path(os.environ.get("HASEL_FIRMWARE_DIR",
                                   Path(__file__).resolve().parents[3] / "firmware"))
#: Where :func:`default_build` builds: ``.cache/firmware`` beside ``firmware/``.
BUILD_ROOT = FIRMWARE_DIR.parent / ".cache" / "firmware"
#: Room for one tick's frames (every host frame answered, plus telemetry) [bytes].
TX_CAPACITY = 16 * 1024


class FirmwareBuildError(RuntimeError):
    """The host build of the firmware core is not possible or failed; the message says why."""


def compiler_missing() -> str:
    """'' when CMake and a C++ compiler are on PATH, else what is missing (for a skip)."""
    missing = [t for t in ("cmake",) if shutil.which(t) is None]
    if not any(shutil.which(c) for c in (os.environ.get("CXX", "c++"), "g++", "clang++")):
        missing.append("a C++ compiler (g++ or clang++)")
    return " and ".join(missing)


def _sources_digest(source: Path) -> str:
    h = hashlib.sha256()
    for p in sorted(source.rglob("*")):
        if p.is_file() and p.suffix in (".cpp", ".hpp", ".h", ".ino", ".txt") and \
                "build" not in p.relative_to(source).parts:
            h.update(str(p.relative_to(source)).encode())
            h.update(p.read_bytes())
    return h.hexdigest()[:16]


def build_core(build_root: str | os.PathLike, source: str | os.PathLike = FIRMWARE_DIR,
               build_type: str = "Release", targets: tuple[str, ...] = ()) -> Path:
    """Build the core for the host under ``build_root``; returns the directory holding
    ``libhasel_device_host.so`` and ``hasel_tick_bench`` (only ``targets`` when given).

    One build directory per version of the sources (a digest of them names it), built under a
    file lock, so parallel test workers share it; a second call only finds it up to date.
    """
    source = Path(source)
    if not (source / "CMakeLists.txt").is_file():
        raise FirmwareBuildError(f"no firmware sources at {source}: set HASEL_FIRMWARE_DIR to "
                                 f"the repository's firmware/ directory")
    missing = compiler_missing()
    if missing:
        raise FirmwareBuildError(f"cannot build the firmware core on this machine: {missing} "
                                 f"not found on PATH")
    out = Path(build_root) / f"host-{build_type.lower()}-{_sources_digest(source)}"
    out.mkdir(parents=True, exist_ok=True)
    only = [a for t in targets for a in ("--target", t)]
    configure = ["cmake", "-S", str(source), "-B", str(out), f"-DCMAKE_BUILD_TYPE={build_type}"]
    build = ["cmake", "--build", str(out), "-j", "2", *only]
    with open(out / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        # configured once; the build itself is incremental (nothing to do: well under a second)
        fresh = not (out / "CMakeCache.txt").exists()
        for cmd in ([configure] if fresh else []) + [build]:
            r = subprocess.run(cmd, capture_output=True, text=True)
            if r.returncode != 0:
                raise FirmwareBuildError(f"{' '.join(cmd)} failed ({r.returncode}):\n"
                                         f"{r.stdout[-4000:]}{r.stderr[-4000:]}")
    if fresh:
        _remove_stale_builds(out)
    return out


def _remove_stale_builds(current: Path) -> None:
    """Remove the builds of older sources beside ``current`` (same build type) that no
    process is using (their lock is free)."""
    prefix = current.name.rsplit("-", 1)[0] + "-"
    for old in current.parent.glob(prefix + "*"):
        if old == current or not (old / ".lock").exists():
            continue
        with open(old / ".lock", "w") as lock:
            try:
                fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                continue
            shutil.rmtree(old, ignore_errors=True)


def default_build() -> Path:
    """The host build the tests and the virtual Teensy use: $HASEL_DEVICE_CORE_BUILD when set
    (a directory built already, e.g. a variant of the core), else :func:`build_core` under
    :data:`BUILD_ROOT`."""
    given = os.environ.get("HASEL_DEVICE_CORE_BUILD")
    if given:
        if not (Path(given) / "libhasel_device_host.so").is_file():
            raise FirmwareBuildError(f"HASEL_DEVICE_CORE_BUILD={given} holds no "
                                     f"libhasel_device_host.so; build one with build_core()")
        return Path(given)
    return build_core(BUILD_ROOT)


class _Sensors(C.Structure):
    _fields_ = [("encoder_raw", C.c_uint16), ("encoder_ok", C.c_uint8),
                ("hv_monitor", C.c_float), ("current_monitor", C.c_float)]


class _Outputs(C.Structure):
    _fields_ = [("active_mask", C.c_uint16), ("hv_supply", C.c_uint8),
                ("telemetry_rate_hz", C.c_uint16), ("dropped", C.c_uint32)]


_LATCHED = ("valid", "seq", "n_a", "phi_a", "phi_d", "sector", "on_count", "off_count", "now")


class _Latched(C.Structure):
    _fields_ = [(n, C.c_double if n.startswith("phi") else C.c_int64) for n in _LATCHED]


_STATE_HEAD = ("hv_enabled", "estop", "faults", "counter", "sample_seq", "last_host_us",
               "hv_on_since_us", "on_since_us", "q", "eta_unwrapped", "last_command_seq")
_STATE_TAIL = ("telemetry_rate_hz", "watchdog_ms", "max_on_ms", "drain_mode",
               "encoder_started", "encoder_unwrapped", "encoder_bad_run")


class _State(C.Structure):
    _fields_ = ([(n, C.c_int64) for n in _STATE_HEAD] + [("pending", _Latched), ("target", _Latched)]
                + [(n, C.c_int64) for n in _STATE_TAIL])


class HwMessage(C.Structure):
    """``hasel::Message``: every field of every type side by side (protocol.hpp)."""

    _fields_ = [("type", C.c_uint8), ("counter", C.c_uint16),
                ("device_time_us", C.c_uint64), ("sample_seq", C.c_uint32),
                ("encoder_raw", C.c_uint16), ("encoder_unwrapped", C.c_int32), ("q", C.c_uint8),
                ("eta", C.c_uint8), ("eta_unwrapped", C.c_int32), ("active_mask", C.c_uint16),
                ("hv_monitor", C.c_float), ("current_monitor", C.c_float),
                ("last_command_seq", C.c_uint32), ("fault_flags", C.c_uint32),
                ("ref_type", C.c_uint8), ("ref_counter", C.c_uint16), ("command_seq", C.c_uint32),
                ("reason", C.c_uint8), ("n_a", C.c_uint8), ("phi_a", C.c_float),
                ("phi_d", C.c_float), ("host_time_us", C.c_uint64), ("enable", C.c_uint8),
                ("telemetry_rate_hz", C.c_uint16), ("watchdog_ms", C.c_uint16),
                ("max_on_ms", C.c_uint16), ("drain_mode", C.c_uint8)]


class HwDecoderStats(C.Structure):
    _fields_ = [(n, C.c_uint32) for n in ("frames", "crc_errors", "framing_errors", "oversize",
                                          "version_errors", "type_errors", "length_errors")]


#: protocol.py's field names where hasel::Message names them otherwise (ACK, REJECT).
_RENAMED = {P.ACK: {"acked_type": "ref_type", "acked_counter": "ref_counter"},
            P.REJECT: {"rejected_type": "ref_type", "rejected_counter": "ref_counter"}}


def load_library(build_dir: str | os.PathLike) -> C.CDLL:
    """Load ``libhasel_device_host.so`` from ``build_dir`` and declare its functions."""
    lib = C.CDLL(str(Path(build_dir) / "libhasel_device_host.so"))
    vp, sz, u8p = C.c_void_p, C.c_size_t, C.POINTER(C.c_uint8)
    sig = {
        "hw_message_size": (sz, []), "hw_device_new": (vp, []), "hw_device_free": (None, [vp]),
        "hw_device_reset": (None, [vp]), "hw_device_receive": (sz, [vp, C.c_char_p, sz]),
        "hw_device_tick": (sz, [vp, C.c_uint64, C.POINTER(_Sensors), u8p, sz, C.POINTER(_Outputs)]),
        "hw_device_state": (None, [vp, C.POINTER(_State)]),
        "hw_crc16": (C.c_uint16, [C.c_char_p, sz]), "hw_angle_counts": (C.c_int32, [C.c_float]),
        "hw_encode": (sz, [C.POINTER(HwMessage), u8p]),
        "hw_cobs_encode": (sz, [C.c_char_p, sz, u8p]), "hw_cobs_decode": (C.c_int, [C.c_char_p, sz, u8p]),
        "hw_decoder_new": (vp, []), "hw_decoder_free": (None, [vp]),
        "hw_decoder_feed": (sz, [vp, C.c_char_p, sz, C.POINTER(HwMessage), sz]),
        "hw_decoder_stats": (None, [vp, C.POINTER(HwDecoderStats)]),
    }
    for name, (res, args) in sig.items():
        f = getattr(lib, name)
        f.restype, f.argtypes = res, args
    if lib.hw_message_size() != C.sizeof(HwMessage):
        raise FirmwareBuildError(f"hasel::Message is {lib.hw_message_size()} bytes in the library "
                                 f"but {C.sizeof(HwMessage)} in device_cpp.HwMessage: update it")
    return lib


def split_frames(wire: bytes) -> list[bytes]:
    """Wire bytes cut into frames, each with its 0x00 delimiter."""
    parts = wire.split(b"\x00")
    return [p + b"\x00" for p in parts[:-1]]


class CppDeviceCore:
    """:class:`~.device_core.DeviceCore`'s interface over the C++ core (one device)."""

    def __init__(self, lib: C.CDLL) -> None:
        self.lib = lib
        self._dev = lib.hw_device_new()
        if not self._dev:
            raise MemoryError("hw_device_new failed")
        self._tx = (C.c_uint8 * TX_CAPACITY)()
        self._out = _Outputs()
        self._st = _State()

    def __del__(self) -> None:
        if getattr(self, "_dev", None):
            self.lib.hw_device_free(self._dev)
            self._dev = None

    def reset(self) -> None:
        """Power-up state (rule 1)."""
        self.lib.hw_device_reset(self._dev)

    def receive(self, data: bytes) -> int:
        """Buffer host bytes for the next tick; returns how many were taken."""
        return self.lib.hw_device_receive(self._dev, bytes(data), len(data))

    def tick(self, now_us: int, sensors: Sensors) -> tuple[list[bytes], Outputs]:
        """One tick (see :meth:`DeviceCore.tick`)."""
        s = _Sensors(sensors.encoder_raw, int(sensors.encoder_ok), sensors.hv_monitor,
                     sensors.current_monitor)
        n = self.lib.hw_device_tick(self._dev, now_us, C.byref(s), self._tx, TX_CAPACITY,
                                    C.byref(self._out))
        o = self._out
        if o.dropped:
            raise RuntimeError(f"{o.dropped} frames did not fit the {TX_CAPACITY}-byte buffer")
        return (split_frames(C.string_at(self._tx, n)),
                Outputs(o.active_mask, bool(o.hv_supply), o.telemetry_rate_hz))

    def state(self) -> DeviceState:
        """The device state, as :class:`DeviceState`."""
        self.lib.hw_device_state(self._dev, C.byref(self._st))
        st = self._st

        def latched(x: _Latched) -> Latched:
            return Latched(bool(x.valid), x.seq, x.n_a, x.phi_a, x.phi_d, x.sector, x.on_count,
                           x.off_count, bool(x.now))
        return DeviceState(bool(st.hv_enabled), bool(st.estop), st.faults, st.counter,
                           st.sample_seq, st.last_host_us, st.hv_on_since_us, st.on_since_us,
                           bool(st.q), st.eta_unwrapped, st.last_command_seq,
                           latched(st.pending), latched(st.target), st.telemetry_rate_hz,
                           st.watchdog_ms, st.max_on_ms, st.drain_mode)


class CppDecoder:
    """The C++ frame decoder: ``feed(bytes) -> [(type, counter, HwMessage), ...]``."""

    def __init__(self, lib: C.CDLL) -> None:
        self.lib = lib
        self._dec = lib.hw_decoder_new()
        self._buf = (HwMessage * 4096)()

    def __del__(self) -> None:
        if getattr(self, "_dec", None):
            self.lib.hw_decoder_free(self._dec)
            self._dec = None

    def feed(self, data: bytes) -> list[P.Frame]:
        """Every frame completed by ``data``, as protocol.py's :class:`~protocol.Frame`."""
        n = self.lib.hw_decoder_feed(self._dec, bytes(data), len(data), self._buf, len(self._buf))
        if n > len(self._buf):
            raise RuntimeError(f"{n} frames in one call; feed at most {len(self._buf)}")
        return [P.Frame(m.type, m.counter, message_of(m)) for m in self._buf[:n]]

    def stats(self) -> dict[str, int]:
        """The decoder's counts by cause (names as in :class:`protocol.DecoderStats`)."""
        st = HwDecoderStats()
        self.lib.hw_decoder_stats(self._dec, C.byref(st))
        return {n: getattr(st, n) for n, _ in HwDecoderStats._fields_}


def message_of(m: HwMessage) -> P.Message:
    """protocol.py's message for a decoded ``hasel::Message``."""
    cls = P.LAYOUT[m.type][1]
    names = _RENAMED.get(m.type, {})
    return cls(*(getattr(m, names.get(f, f)) for f in cls._fields))


def hw_message(msg: P.Message, counter: int) -> HwMessage:
    """The ``hasel::Message`` of a protocol.py message."""
    t = P.TYPE_OF[type(msg)]
    names = _RENAMED.get(t, {})
    m = HwMessage(type=t, counter=counter)
    for f, v in zip(type(msg)._fields, msg):
        setattr(m, names.get(f, f), v)
    return m


def encode(lib: C.CDLL, msg: P.Message, counter: int) -> bytes:
    """The C++ encoder's wire bytes of ``msg``."""
    buf = (C.c_uint8 * 80)()
    n = lib.hw_encode(C.byref(hw_message(msg, counter)), buf)
    return C.string_at(buf, n)
