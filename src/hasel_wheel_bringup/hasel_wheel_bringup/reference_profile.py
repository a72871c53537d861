"""A reference profile played by the wheel's own clock (no ROS): the references [rad/s] a
run steps through, each from its start time [s] after the first sample.

``profile_node`` publishes it on the ROS graph, so the graph runs the same profile as the
embedded runner (:data:`hasel_wheel_mpc.closed_loop.FIG11_PROFILE` by default).  Test:
``test_reference_profile.py``.
"""
from __future__ import annotations

import math
from typing import Sequence

from hasel_wheel_mpc.closed_loop import FIG11_DURATION, FIG11_PROFILE

Profile = tuple[tuple[float, float], ...]


def parse_profile(text: str) -> Profile:
    """``"0:1.0, 40:1.5, ..."`` (start [s]:reference [rad/s]) as ((0.0, 1.0), (40.0, 1.5), ...).

    Raises ValueError naming the item that is not ``start:reference`` with finite numbers,
    starts that are not increasing from 0, or a negative reference.
    """
    out = []
    for item in (p.strip() for p in text.split(",")):
        start, sep, ref = item.partition(":")
        try:
            pair = (float(start), float(ref))
        except ValueError:
            pair = None
        if not sep or pair is None or not all(math.isfinite(x) for x in pair):
            raise ValueError(f"profile item {item!r}: expected start:reference, e.g. 40:1.5 "
                             f"(start [s], reference [rad/s])")
        out.append(pair)
    return check_profile(out)


def check_profile(profile: Sequence[tuple[float, float]]) -> Profile:
    """``profile`` as a tuple, if its first start is 0, its starts increase and its
    references are >= 0 [rad/s]; else ValueError naming the entry."""
    profile = tuple((float(t), float(r)) for t, r in profile)
    if not profile or profile[0][0] != 0.0:
        raise ValueError(f"profile {profile!r}: expected a first entry starting at 0 s")
    for (t0, _), (t1, r1) in zip(profile, profile[1:]):
        if t1 <= t0:
            raise ValueError(f"profile entry {t1:g}:{r1:g}: starts must increase "
                             f"(after {t0:g} s)")
    for t, r in profile:
        if r < 0.0:
            raise ValueError(f"profile entry {t:g}:{r:g}: expected a reference >= 0 rad/s")
    return profile


def profile_text(profile: Profile) -> str:
    """The text :func:`parse_profile` reads back as ``profile``."""
    return ", ".join(f"{t:g}:{r:g}" for t, r in profile)


class ProfilePlayer:
    """Which reference is due as the device clock runs: :meth:`step` with each sample's
    device time [s] answers the reference to publish [rad/s] when it changes, else None;
    :attr:`done` once ``duration`` [s] has passed since the first sample."""

    def __init__(self, profile: Profile = FIG11_PROFILE,
                 duration: float = FIG11_DURATION) -> None:
        self.profile = check_profile(profile)
        if not (math.isfinite(duration) and duration > self.profile[-1][0]):
            raise ValueError(f"duration = {duration!r} s: expected more than the last start "
                             f"({self.profile[-1][0]:g} s)")
        self.duration = duration
        self._t0: float | None = None
        self._next = 0
        self.done = False

    def step(self, device_t: float) -> float | None:
        """The reference due at ``device_t`` [s] if it is a new one, else None."""
        if self._t0 is None:
            self._t0 = device_t
        t = device_t - self._t0
        self.done = t >= self.duration
        due = None
        while self._next < len(self.profile) and t >= self.profile[self._next][0]:
            due = self.profile[self._next][1]
            self._next += 1
        return due
