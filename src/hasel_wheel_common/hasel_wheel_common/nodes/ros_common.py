"""Helpers shared by the rclpy nodes: QoS, message filling, diagnostics, parameter descriptors.

This module imports rclpy and message packages; only node modules import it.
"""
from __future__ import annotations

import importlib
from typing import Any, Iterable, Mapping

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from hasel_wheel_common.stop_request import StopRequest, StopRequested
from hasel_wheel_common.topics import QosSpec, Topic

#: Longest wait for callbacks before the node loop checks for a stop request again [s].
STOP_POLL = 0.1

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
    a stop request (:mod:`hasel_wheel_common.stop_request`: SIGINT, SIGTERM, or the parent
    process gone), an external shutdown, or, for a node with a ``finished`` future, its
    completion; then destroy the node, shut rclpy down and return (exit status 0).  rclpy's
    own signal handlers are not installed: the process handles its signals, so a second
    SIGINT during clean-up finds nothing half torn down.  Tests: ``test_stop_request.py``
    (the requests, without ROS) and ``test_launch_stops.py`` (every way of stopping a launch,
    on ROS 2).
    """
    import rclpy
    from rclpy.exceptions import ParameterException
    from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    stop = StopRequest()
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    try:
        node = factory()
    except (ValueError, ParameterException) as exc:   # ParameterError and rclpy's own checks
        print(f"{name}: {exc}")                       # (type, range): name the field and range
        rclpy.try_shutdown()
        raise SystemExit(2)
    except StopRequested:
        rclpy.try_shutdown()
        stop.finish()
        return
    stop.arm()
    finished = getattr(node, "finished", None)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    try:
        while not (stop.stopped() or (finished is not None and finished.done())):
            executor.spin_once(timeout_sec=STOP_POLL)
    except ExternalShutdownException:
        pass
    if stop.reason is not None:
        node.get_logger().info(f"stopping: {stop.reason}")
    executor.shutdown()
    node.destroy_node()
    rclpy.try_shutdown()
    stop.finish()
