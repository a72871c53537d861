"""The verdict of an identification on data whose truth is known (the benchmarks' sweeps).

``right``: exactly the true effect was chosen (nothing, on data with none); ``wrong``: any
other name; ``missed``: nothing chosen where an effect was on.  A miss is ``below the
floor`` when even the true model (the plant's own parameters) does not cut the nominal
fit's held-out simulation error by the tool's bar ``min_gain``: then no fitted model could
pass the bar either, and the data cannot show the effect.
"""
from __future__ import annotations

from collections.abc import Iterable


def below_floor(before: float, true_error: float, min_gain: float = 0.10) -> bool:
    """Whether the true model's simulation error ``true_error`` [rad/s] is less than
    ``min_gain`` [1, in 0..1) below the nominal fit's held-out error ``before`` [rad/s]."""
    if not 0.0 <= min_gain < 1.0:
        raise ValueError(f"min_gain must be a fraction in [0, 1) (0.10 is a 10 % cut), got "
                         f"{min_gain!r}")
    if not (before > 0.0 and true_error > 0.0):
        raise ValueError(f"simulation errors must be positive [rad/s], got before={before!r}, "
                         f"true_error={true_error!r}")
    return before / true_error < 1.0 / (1.0 - min_gain)


def verdict(chosen: Iterable[str], truth: str | None, before: float | None = None,
            true_error: float | None = None, min_gain: float = 0.10) -> str:
    """``right``, ``wrong``, ``missed`` or ``missed below the floor`` (module docstring) for
    the effects ``chosen`` (in the order chosen) on data with the effect ``truth`` (None:
    none).  A miss is judged against the floor when the true model's error ``true_error``
    [rad/s] is given, with the nominal fit's held-out error ``before`` [rad/s]."""
    chosen = tuple(chosen)
    if chosen == ((truth,) if truth else ()):
        return "right"
    if chosen:
        return "wrong"
    if true_error is not None:
        if before is None:
            raise ValueError("true_error needs before, the nominal fit's held-out simulation "
                             "error [rad/s], to judge a miss against the floor")
        if below_floor(before, true_error, min_gain):
            return "missed below the floor"
    return "missed"
