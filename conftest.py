"""Test-session set-up shared by every package (pytest loads it before any test module).

``./dev test`` runs the suite on several pytest-xdist workers, and on a fresh clone they all
compile the numba core at once.  numba does not lock its cache index (see
``hasel_wheel_sim.jit``), so each worker, and every process its tests start, compiles into a
cache of its own: ``.cache/numba/<worker>`` here.  Every worker runs OpenBLAS's pinned
kernels (``hasel_wheel_ident.numerics``), as the identification command does.
"""
import os
from pathlib import Path

_WORKER = os.environ.get("PYTEST_XDIST_WORKER")
if _WORKER and "HASEL_WHEEL_JIT_CACHE" not in os.environ:
    os.environ["HASEL_WHEEL_JIT_CACHE"] = str(Path(__file__).resolve().parent / ".cache"
                                              / "numba" / _WORKER)

# The suite runs the OpenBLAS kernels that `hasel_wheel identify` and the identification
# benchmarks run (docs/identification.md, "Numerics"), on every machine that can: a verdict
# that sits at one of the identification's gates then takes one route, the one its test holds.
# Before any test module loads numpy; a value the user set is kept.
from hasel_wheel_ident.numerics import pin_blas_kernels  # noqa: E402

pin_blas_kernels()

