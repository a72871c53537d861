"""When the driver node opens its serial link: once the telemetry has its listeners.

The device streams telemetry from the moment the link connects, and a subscriber (the
recorder above all) can only subscribe once the driver's publisher has made the topic known;
a link started at once would hand its first samples to nobody.  The node therefore waits
until ``wanted`` subscriptions match its telemetry publisher (the observer, the MPC and the
recorder in the closed-loop launch), or ``timeout`` seconds, whichever comes first.  The
device keeps HV off meanwhile: it is off at power-up until the host enables it.
Test: ``test_link_start.py``.
"""
from __future__ import annotations


def link_may_start(matched: int, wanted: int, waited: float, timeout: float) -> bool:
    """True when ``matched`` >= ``wanted`` subscriptions, or ``waited`` >= ``timeout`` [s]."""
    return matched >= wanted or waited >= timeout
