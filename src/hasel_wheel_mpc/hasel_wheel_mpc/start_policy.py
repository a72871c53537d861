"""When a wheel is started, restarted, or given up: the start and stall policies' rules.

A wheel is *still* when its encoder moved less than ``still_speed`` x the window over the
last encoder window (:data:`~hasel_wheel_mpc.core.START_SAMPLES` samples).  A still wheel
with no pad on is started with a START (protocol v1.1): the pad in contact switches on at
once and pushes (docs/model.md, "Start from rest").  A wheel that was rolling and has been
slower than ``still_speed`` for ``stall_time`` [s] while the reference is above zero has
*stalled*: the MPC gives way to the start policy again.  Every START of a standing wheel
counts as a restart until the wheel reaches half its reference; the START after ``max_restarts`` of them is
not sent: the policy gives up, HV goes off, and diagnostics say at which pad.
Tests: ``test_start_policy.py``, ``test_core.py``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

from hasel_wheel_sim.params import FieldSpec, ParameterError, check_value

#: Unit and allowed range of each :class:`StartConfig` field.
START_FIELDS = {
    "still_speed": FieldSpec("rad/s", 0.0, 1.0, high_closed=True),
    "stall_time": FieldSpec("s", 0.1, 60.0, True, True),
    "max_restarts": FieldSpec("count", 0.0, 100.0, True, True),
}

#: A restart run ends once the wheel reaches this fraction of its reference [1].
RECOVERED = 0.5

#: The verdict of :meth:`StallMonitor.start` when it gives up.
GIVE_UP = "give_up"


@dataclass(frozen=True)
class StartConfig:
    """Start and stall policies (SI units).

    ``still_speed`` [rad/s]: slower than this, the wheel counts as standing.
    ``stall_time`` [s]: that long standing, with a reference above zero, is a stall.
    ``max_restarts`` [count]: STARTs in a row that do not bring the wheel to half its
    reference before HV goes off.
    """

    still_speed: float = 0.1
    stall_time: float = 1.0
    max_restarts: int = 5

    def __post_init__(self) -> None:
        """Range-check every field (:data:`START_FIELDS`); raises ParameterError naming it."""
        for name, spec in START_FIELDS.items():
            check_value(name, getattr(self, name), spec, "start")
        if not float(self.max_restarts).is_integer():
            raise ParameterError(f"start: field 'max_restarts' = {self.max_restarts!r} is not a "
                                 f"whole number of restarts")


class StallVerdict(NamedTuple):
    """What :meth:`StallMonitor.start` found: GIVE_UP, and the pad in contact (0..15)."""

    what: str
    pad: int


class StallMonitor:
    """Finds stalls and counts the STARTs in a row (module docstring)."""

    def __init__(self, config: StartConfig | None = None) -> None:
        self.config = config or StartConfig()
        self.restarts = 0           # STARTs since the wheel last reached half its reference
        self.total_restarts = 0     # stalls found since the start [count]
        self._still_since: float | None = None

    def step(self, t: float, still: bool, speed: float, reference: float,
             started: bool) -> bool:
        """One sample at ``t`` [s]: ``still`` from the encoder, ``speed`` [rad/s] the MPC's,
        ``reference`` [rad/s], ``started`` whether the MPC drives (not the start policy).
        True when the wheel has stalled now: the start policy takes it back."""
        if reference > 0.0 and speed >= RECOVERED * reference:
            self.restarts = 0
        if not still or reference <= 0.0 or not started:
            self._still_since = None
            return False
        if self._still_since is None:
            self._still_since = t
        if t - self._still_since < self.config.stall_time:
            return False
        self._still_since = None
        self.total_restarts += 1
        return True

    def start(self, pad: int) -> StallVerdict | None:
        """A START of ``pad`` (0..15) is due: None to send it, or GIVE_UP when
        ``max_restarts`` STARTs in a row have not brought the wheel to half its reference."""
        if self.restarts >= self.config.max_restarts:
            return StallVerdict(GIVE_UP, pad)
        self.restarts += 1
        return None
