"""When a node process should stop: SIGINT, SIGTERM, or the process that started it gone.

Every node stops the same way however it is asked to (Ctrl-C in a terminal, SIGINT to its
process group, SIGTERM from ``kill``, systemd or ``ros2 launch``'s escalation, or the death
of the ``ros2 launch``/``ros2 run`` process that started it): the first request is recorded
and the node's loop ends, destroys the node and exits with status 0; later signals are
ignored, so a second SIGINT (a terminal's plus the one launch forwards) can interrupt
neither the clean-up nor, once the node is gone, the process's exit.  While the node is
still being built (loading or compiling its model) a request raises :class:`StopRequested`
at once instead, so a slow start never has to be killed.

Tests: ``test_stop_request.py``.
"""
from __future__ import annotations

import os
import signal
from types import FrameType

#: The signals that ask a node to stop.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class StopRequested(BaseException):
    """Raised by a stop signal that arrives before :meth:`StopRequest.arm` (a BaseException,
    like KeyboardInterrupt, so that no ``except Exception`` swallows it)."""


class StopRequest:
    """The first stop request of this process; install it before building the node.

    ``reason`` is None until a request arrives, then a short name: 'SIGINT', 'SIGTERM' or
    'parent exited'.
    """

    def __init__(self) -> None:
        self.reason: str | None = None
        self._armed = False
        self._parent = os.getppid()
        self._previous = {s: signal.signal(s, self._on_signal) for s in STOP_SIGNALS}

    def _on_signal(self, signum: int, _frame: FrameType | None) -> None:
        if self.reason is None:
            self.reason = signal.Signals(signum).name
            if not self._armed:
                raise StopRequested(self.reason)

    def arm(self) -> None:
        """From now on a request only sets :attr:`reason` (the loop checks :meth:`stopped`)."""
        self._armed = True

    def stopped(self) -> bool:
        """True once a stop was requested or the parent process has exited (its child is
        then re-parented: ``os.getppid()`` changes)."""
        if self.reason is None and os.getppid() != self._parent:
            self.reason = "parent exited"
        return self.reason is not None

    def finish(self) -> None:
        """Ignore stop signals from now on: the process is about to exit.  Python resets
        its handlers to the default while it exits, and a late SIGINT (launch forwards one
        once any node has exited) would then kill it with status -2 instead of 0."""
        for s in STOP_SIGNALS:
            signal.signal(s, signal.SIG_IGN)

    def restore(self) -> None:
        """Put back the signal handlers that were installed before."""
        for s, handler in self._previous.items():
            signal.signal(s, handler)
