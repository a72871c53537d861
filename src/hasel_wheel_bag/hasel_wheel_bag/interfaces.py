"""Message definitions as text, for writing self-describing bags without ROS.

Our own types are read from ``hasel_wheel_msgs/msg`` (packaged here through a link, so the
``.msg`` files stay the single source).  The few standard types we publish (std_msgs,
sensor_msgs, diagnostic_msgs, builtin_interfaces) ship as plain ``.msg`` texts under
``msg_defs/std``.  :func:`full_definition` concatenates a type with all its dependencies
in the layout rosbag2's recorder writes (``ros2msg`` schema encoding).
"""
from __future__ import annotations

import re
from functools import lru_cache
from importlib import resources

OWN_PACKAGE = "hasel_wheel_msgs"
_SEPARATOR = "=" * 80
_PRIMITIVES = {
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
    "int32", "uint32", "int64", "uint64", "string", "wstring",
}
_FIELD = re.compile(r"^\s*([A-Za-z0-9_/]+)(\[[^\]]*\])?(<=\d+)?\s+([A-Za-z0-9_]+)")


class UnknownMessageType(KeyError):
    """A message type has no definition here."""


def _split(datatype: str) -> tuple[str, str]:
    """'pkg/msg/Name' or 'pkg/Name' -> ('pkg', 'Name')."""
    parts = datatype.split("/")
    if len(parts) == 3 and parts[1] == "msg":
        return parts[0], parts[2]
    if len(parts) == 2:
        return parts[0], parts[1]
    raise UnknownMessageType(f"{datatype!r} is not a message type name; expected 'pkg/msg/Name'")


@lru_cache(maxsize=None)
def definition(datatype: str) -> str:
    """The ``.msg`` text of one type ('pkg/msg/Name'), without its dependencies."""
    pkg, name = _split(datatype)
    root = resources.files("hasel_wheel_bag") / "msg_defs"
    path = root / OWN_PACKAGE / f"{name}.msg" if pkg == OWN_PACKAGE else root / "std" / f"{pkg}__{name}.msg"
    if not path.is_file():
        raise UnknownMessageType(f"no definition of {pkg}/msg/{name} is packaged; known types: "
                                 f"{', '.join(known_types())}")
    return path.read_text(encoding="utf-8")


def known_types() -> list[str]:
    """Every type this package can describe, as 'pkg/msg/Name'."""
    root = resources.files("hasel_wheel_bag") / "msg_defs"
    own = [f"{OWN_PACKAGE}/msg/{p.name[:-4]}" for p in (root / OWN_PACKAGE).iterdir()
           if p.name.endswith(".msg")]
    std = [p.name[:-4].replace("__", "/msg/") for p in (root / "std").iterdir()
           if p.name.endswith(".msg")]
    return sorted(own + std)


def dependencies(datatype: str) -> list[str]:
    """Complex field types used by ``datatype``, depth first, each once ('pkg/Name')."""
    pkg, _ = _split(datatype)
    out: list[str] = []

    def visit(dt_pkg: str, text: str) -> None:
        for line in text.splitlines():
            line = line.split("#", 1)[0]
            m = _FIELD.match(line)
            if not m or "=" in line:
                continue
            ftype = m.group(1)
            if ftype in _PRIMITIVES:
                continue
            dep = ftype if "/" in ftype else f"{dt_pkg}/{ftype}"
            if dep == "Header":
                dep = "std_msgs/Header"
            if dep not in out:
                out.append(dep)
                dpkg, dname = _split(dep)
                visit(dpkg, definition(f"{dpkg}/msg/{dname}"))

    visit(pkg, definition(datatype))
    return out


@lru_cache(maxsize=None)
def full_definition(datatype: str) -> str:
    """The ros2msg schema text: the type followed by every dependency after a separator."""
    parts = [definition(datatype)]
    for dep in dependencies(datatype):
        dpkg, dname = _split(dep)
        parts.append(f"{_SEPARATOR}\nMSG: {dep}\n{definition(f'{dpkg}/msg/{dname}')}")
    return "\n".join(p.rstrip("\n") for p in parts) + "\n"
