"""Test-session set-up shared by every package (pytest loads it before any test module).

``./dev test`` runs the suite on several pytest-xdist workers, and on a fresh clone they all
compile the numba core at once.  numba does not lock its cache index (see
``hasel_wheel_sim.jit``), so each worker, and every process its tests start, compiles into a
cache of its own: ``.cache/numba/<worker>`` here.
"""
import os
from pathlib import Path

_WORKER = os.environ.get("PYTEST_XDIST_WORKER")
if _WORKER and "HASEL_WHEEL_JIT_CACHE" not in os.environ:
    os.environ["HASEL_WHEEL_JIT_CACHE"] = str(Path(__file__).resolve().parent / ".cache"
                                              / "numba" / _WORKER)
