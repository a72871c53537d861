"""Helpers for this package's launch files (imports launch, never rclpy; not part of the core).
"""
from __future__ import annotations

from launch.actions import RegisterEventHandler
from launch.event_handlers import OnProcessIO

#: What a node logs once it can take samples (its model is loaded or compiled).
READY = b"ready:"


def when_all_ready(nodes, actions) -> list:
    """Event handlers that return ``actions`` once every node in ``nodes`` has logged READY
    on stdout or stderr."""
    waiting = set(range(len(nodes)))

    def handler(i):
        def on_output(event):
            if i in waiting and READY in event.text:
                waiting.discard(i)
                if not waiting:
                    return actions
            return None
        return on_output

    return [RegisterEventHandler(OnProcessIO(target_action=n, on_stdout=handler(i),
                                             on_stderr=handler(i)))
            for i, n in enumerate(nodes)]
