"""Helpers shared by the rclpy nodes: QoS, message filling, diagnostics, parameter descriptors.

This module imports rclpy and message packages; only node modules import it.
"""
from __future__ import annotations

import importlib
from typing import Any, Iterable, Mapping

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from hasel_wheel_common.topics import QosSpec, Topic

_RELIABILITY = {"reliable": ReliabilityPolicy.RELIABLE, "best_effort": ReliabilityPolicy.BEST_EFFORT}
_DURABILITY = {"volatile": DurabilityPolicy.VOLATILE,
               "transient_local": DurabilityPolicy.TRANSIENT_LOCAL}
_HISTORY = {"keep_last": HistoryPolicy.KEEP_LAST, "keep_all": HistoryPolicy.KEEP_ALL}


def qos_profile(spec: QosSpec) -> QoSProfile:
    """rclpy QoSProfile of a topic-table entry."""
    return QoSProfile(history=_HISTORY[spec.history], depth=spec.depth,
                      reliability=_RELIABILITY[spec.reliability],
                      durability=_DURABILITY[spec.durability])


def message_class(datatype: str) -> type:
    """The rclpy message class of 'pkg/msg/Name'."""
    pkg, _, name = datatype.split("/")
    return getattr(importlib.import_module(f"{pkg}.msg"), name)


def create_publishers(node: Any, table: Iterable[Topic]) -> dict[str, Any]:
    """One publisher per topic-table entry (name, type, QoS), keyed by the topic's name."""
    return {t.name: node.create_publisher(message_class(t.type), t.name, qos_profile(t.qos))
            for t in table}


def fill(msg: Any, data: Mapping[str, Any]) -> Any:
    """Copy a message dict (as built by ``hasel_wheel_common.samples``) into ``msg``; returns it.

    Nested dicts fill nested messages (``header.stamp``); lists are assigned as they are.
    """
    for key, value in data.items():
        if isinstance(value, Mapping):
            fill(getattr(msg, key), value)
        else:
            setattr(msg, key, value)
    return msg


def diagnostic_array(stamp: Any, name: str, hardware_id: str, level: int, message: str,
                     values: Mapping[str, str]) -> DiagnosticArray:
    """One-status DiagnosticArray (level: DiagnosticStatus.OK/WARN/ERROR/STALE)."""
    status = DiagnosticStatus(level=bytes([level]), name=name, message=message,
                              hardware_id=hardware_id,
                              values=[KeyValue(key=k, value=v) for k, v in values.items()])
    arr = DiagnosticArray(status=[status])
    arr.header.stamp = stamp
    return arr


def publish_status(node: Any, publisher: Any, kind: str, hardware_id: str, level: int,
                   message: str, values: Mapping[str, str]) -> None:
    """Publish one status named '<node's fully qualified name>: <kind>', stamped now."""
    publisher.publish(diagnostic_array(
        node.get_clock().now().to_msg(), f"{node.get_fully_qualified_name()}: {kind}",
        hardware_id, level, message, values))


def float_param(description: str, low: float, high: float, read_only: bool = False) -> ParameterDescriptor:
    """Descriptor of a double parameter with an inclusive range."""
    return ParameterDescriptor(description=description, read_only=read_only,
                               floating_point_range=[FloatingPointRange(from_value=low, to_value=high,
                                                                        step=0.0)])


def int_param(description: str, low: int, high: int, read_only: bool = False) -> ParameterDescriptor:
    """Descriptor of an integer parameter with an inclusive range."""
    return ParameterDescriptor(description=description, read_only=read_only,
                               integer_range=[IntegerRange(from_value=low, to_value=high, step=1)])


def text_param(description: str, read_only: bool = True,
               choices: Iterable[str] | None = None) -> ParameterDescriptor:
    """Descriptor of a string (or bool) parameter; ``choices`` go into additional_constraints."""
    extra = f"one of: {', '.join(choices)}" if choices else ""
    return ParameterDescriptor(description=description, read_only=read_only,
                               additional_constraints=extra)


def run_node(factory: Any, name: str, args: Any = None) -> None:
    """The Jazzy demos' ``main()`` (demo_nodes_py talker.py), shared by every node.

    Build the node (a bad parameter or file exits with status 2 and the reason), spin until
    Ctrl-C or an external shutdown (or, for a node with a ``finished`` future, until that
    completes), then destroy the node and shut rclpy down.  A second SIGINT during clean-up
    (a terminal's Ctrl-C plus the one ``ros2 launch`` forwards) is ignored, so
    ``destroy_node`` still runs to the end once.
    """
    import rclpy
    from rclpy.exceptions import ParameterException
    from rclpy.executors import ExternalShutdownException

    rclpy.init(args=args)
    try:
        node = factory()
    except (ValueError, ParameterException) as exc:   # ParameterError and rclpy's own checks
        print(f"{name}: {exc}")                       # (type, range): name the field and range
        rclpy.try_shutdown()
        raise SystemExit(2)
    try:
        finished = getattr(node, "finished", None)
        if finished is None:
            rclpy.spin(node)
        else:
            rclpy.spin_until_future_complete(node, finished)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except RuntimeError:
        # rclpy's RCLError "failed to initialize wait set: the given context is not valid":
        # SIGINT's handler shut the context down while the executor was building its wait set
        # (a known race, ros2/ros2cli#854).  That is the shutdown asked for; anything else is not.
        if rclpy.ok():
            raise
    finally:
        try:
            node.destroy_node()
        except KeyboardInterrupt:
            pass
        rclpy.try_shutdown()
