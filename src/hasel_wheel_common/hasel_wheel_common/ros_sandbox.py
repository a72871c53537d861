"""Whether tests may start a ROS 2 graph here: rclpy present, and DDS confined to this machine.

The project's tests that create nodes or launch files run only where ROS 2 is installed and
only inside a network namespace that has nothing but loopback (``unshare --net``, then
``ip link set lo up``), with ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``.  Anywhere else they
skip, and say why.  This module never imports rclpy.
"""
from __future__ import annotations

import importlib.util
import os
import socket
from typing import Mapping, Sequence


def network_interfaces() -> list[str]:
    """Names of the interfaces of this process's network namespace (``['lo']`` in a
    loopback-only one).  /sys/class/net would show the host's unless /sys is remounted."""
    return sorted(name for _, name in socket.if_nameindex())


def ros_graph_unavailable(interfaces: Sequence[str] | None = None,
                          environ: Mapping[str, str] | None = None) -> str | None:
    """None when a test may start ROS 2 nodes here, else the reason it may not.

    ``interfaces`` and ``environ`` default to this process's network interfaces and
    environment."""
    names = network_interfaces() if interfaces is None else sorted(interfaces)
    env = os.environ if environ is None else environ
    others = [n for n in names if n != "lo"]
    if others or "lo" not in names:
        return (f"this network namespace has interfaces besides lo ({', '.join(others)}) or no "
                f"lo: DDS could leave the machine; run inside `unshare --net` with only lo up")
    if env.get("ROS_AUTOMATIC_DISCOVERY_RANGE") != "LOCALHOST":
        return (f"ROS_AUTOMATIC_DISCOVERY_RANGE is {env.get('ROS_AUTOMATIC_DISCOVERY_RANGE')!r}; "
                f"expected 'LOCALHOST'")
    for module in ("rclpy", "launch_testing"):
        if importlib.util.find_spec(module) is None:
            return f"{module} is not importable (source a ROS 2 Jazzy setup.bash to run this)"
    return None
