"""Optional numba compilation of the model core.

The model is written as plain scalar Python (``math`` on floats, numpy arrays indexed
element by element), which numba compiles to machine code when it is installed.  Without
numba the very same functions run interpreted: correct, only slower.  Set the environment
variable ``HASEL_WHEEL_NO_JIT=1`` to force the interpreted path (useful for debugging).
"""
from __future__ import annotations

import os
from typing import Any, Callable

try:  # pragma: no cover - exercised implicitly
    if os.environ.get("HASEL_WHEEL_NO_JIT"):
        raise ImportError("disabled by HASEL_WHEEL_NO_JIT")
    import numba

    HAVE_NUMBA = True
except ImportError:  # pragma: no cover
    numba = None
    HAVE_NUMBA = False


def jit(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Compile ``fn`` with ``numba.njit(cache=True)`` when numba is available."""
    if HAVE_NUMBA:
        return numba.njit(cache=True, nogil=True)(fn)
    return fn
