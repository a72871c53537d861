"""Optional numba compilation of the model core.

The model is written as plain scalar Python (``math`` on floats, numpy arrays indexed
element by element), which numba compiles to machine code when it is installed.  Without
numba the very same functions run interpreted: correct, only slower.  Set the environment
variable ``HASEL_WHEEL_NO_JIT=1`` to force the interpreted path (useful for debugging).

Compiled code is cached on disk.  numba invalidates a cached function only when its own
source file changes, not when a constant it uses from another module does (our index
layout lives in ``layout.py``), so the cache directory is keyed by a hash of every source
file of the compiled core.  It lies under ``HASEL_WHEEL_JIT_CACHE`` when that names a
writable directory, else beside this file, else in the temporary directory.  numba does not
lock its cache index: two processes that save two signatures of one function at the same
moment can pair an entry with the other's code, so processes that compile at the same time
(the test suite's workers) should each have their own directory (the project's conftest.py).
"""
from __future__ import annotations

import hashlib
import os
import tempfile
from pathlib import Path
from typing import Any, Callable

_CORE_FILES = ("jit.py", "layout.py", "model.py", "integrator.py")

try:  # pragma: no cover - exercised implicitly
    if os.environ.get("HASEL_WHEEL_NO_JIT"):
        raise ImportError("disabled by HASEL_WHEEL_NO_JIT")
    import numba

    HAVE_NUMBA = True
except ImportError:  # pragma: no cover
    numba = None
    HAVE_NUMBA = False


def _cache_dir() -> str:
    here = Path(__file__).resolve().parent
    digest = hashlib.sha256()
    for name in _CORE_FILES:
        digest.update((here / name).read_bytes())
    key = f"numba-{digest.hexdigest()[:16]}"
    own = os.environ.get("HASEL_WHEEL_JIT_CACHE")
    for base in ((Path(own),) if own else ()) + (here / "__pycache__",
                                                 Path(tempfile.gettempdir()) / "hasel_wheel_sim"):
        try:
            d = base / key
            d.mkdir(parents=True, exist_ok=True)
            probe = d / ".writable"
            probe.touch()
            return str(d)
        except OSError:
            continue
    return ""


if HAVE_NUMBA:  # pragma: no branch
    _dir = _cache_dir()
    if _dir:
        numba.config.CACHE_DIR = _dir


def jit(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Compile ``fn`` with ``numba.njit(cache=True)`` when numba is available."""
    if HAVE_NUMBA:
        return numba.njit(cache=bool(numba.config.CACHE_DIR), nogil=True)(fn)
    return fn


def jit_inline(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Like :func:`jit`, and inlined into compiled callers (``inline='always'``).

    For the small functions of the RK4 inner loop: a compiled call that passes arrays pays
    reference counting on every call, which costs more than the arithmetic
    (bench_model.py prints both).
    """
    if HAVE_NUMBA:
        return numba.njit(cache=bool(numba.config.CACHE_DIR), nogil=True, inline="always")(fn)
    return fn


def jit_kernel(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Like :func:`jit`, compiled without numba's reference counting (NRT off).

    For compiled loops that allocate nothing.  Such a function never owns an array, yet with
    NRT on, numba increments and decrements the count of every array it passes to an inlined
    call: a few atomic operations per RK4 stage, which cost more than the whole flow map
    without actuation (bench_model.py runs the batch both ways).  A function marked so that
    tries to allocate fails to compile, so the mark cannot cause a leak or a dangling array
    (tested).

    Division follows IEEE (``error_model="numpy"``: x/0 is inf or nan) instead of raising
    ZeroDivisionError, which saves a test and a branch on every division of the force law.
    Every divisor in these kernels is a validated positive parameter or is tested first.
    """
    if HAVE_NUMBA:
        return numba.njit(cache=bool(numba.config.CACHE_DIR), nogil=True, _nrt=False,
                          error_model="numpy")(fn)
    return fn


def jit_parallel(fn: Callable[..., Any]) -> Callable[..., Any]:
    """Like :func:`jit`, with ``parallel=True``: ``prange`` loops run on all cores."""
    if HAVE_NUMBA:
        return numba.njit(cache=bool(numba.config.CACHE_DIR), nogil=True, parallel=True)(fn)
    return fn


#: ``numba.prange`` when compiled, ``range`` otherwise.
prange = numba.prange if HAVE_NUMBA else range
