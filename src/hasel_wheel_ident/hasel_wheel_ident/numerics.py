"""The same numbers on every Linux x86-64 machine with AVX2: OpenBLAS's kernels pinned (no rclpy).

OpenBLAS, the BLAS that numpy and scipy wheels ship, picks its kernels for the CPU it finds
(``DYNAMIC_ARCH``), and kernels for different CPUs sum in different orders.  The
identification's choices are made at gates (a held-out cut of 10 %, a p-value, a refit's
convergence), and a fit that lands near a gate can fall on either side with the last bits of
its sums: on a machine where OpenBLAS chose its SkylakeX kernels (AVX-512), four
end-to-end identification tests that pass with the Haswell kernels chose differently (one
of them named nothing where two effects were planted).  Pinning one kernel set
(``OPENBLAS_CORETYPE=Haswell``: AVX2 and FMA, Intel Core since 2013, AMD since 2015) gives the
same report for the same recording on every such machine, as Intel's MKL does with
``MKL_CBWR``.  The kernels are chosen when OpenBLAS loads, so the pin only works before the
first ``import numpy``; the package imports this module first (``hasel_wheel_mpc/__init__``).

A value the user set for ``OPENBLAS_CORETYPE`` is kept; nothing is pinned on a CPU without
AVX2 and FMA, on other architectures, or when numpy was already imported.
"""
from __future__ import annotations

import os
import platform
import sys

#: The OpenBLAS kernel set pinned on x86-64 (needs AVX2 and FMA).
KERNEL = "Haswell"
_NEEDS = {"avx2", "fma"}


def _cpu_flags() -> set[str]:
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as f:
            for line in f:
                if line.startswith("flags"):
                    return set(line.split(":", 1)[1].split())
    except OSError:
        pass
    return set()


def pin_blas_kernels() -> str | None:
    """Set ``OPENBLAS_CORETYPE`` to :data:`KERNEL` when that can still take effect and the
    CPU runs it.  Returns the core type in force after the call (the user's own, or the
    pinned one), or None when nothing is pinned."""
    own = os.environ.get("OPENBLAS_CORETYPE")
    if own:
        return own
    if "numpy" in sys.modules:
        return None                      # OpenBLAS has chosen its kernels already
    if platform.machine().lower() not in ("x86_64", "amd64") or not _NEEDS <= _cpu_flags():
        return None
    os.environ["OPENBLAS_CORETYPE"] = KERNEL
    return KERNEL


def blas_in_use() -> dict:
    """The BLAS libraries loaded in this process: ``[{library, version, kernels}]`` under
    ``"blas"`` (kernels: the architecture OpenBLAS runs, e.g. "Haswell"), and
    ``"coretype_env"``, the ``OPENBLAS_CORETYPE`` value (null when unset).  ``blas`` is
    empty without threadpoolctl."""
    try:
        from threadpoolctl import threadpool_info
    except ImportError:
        info = []
    else:
        info = [i for i in threadpool_info() if i.get("user_api") == "blas"]
    return {"blas": [{"library": i.get("internal_api"), "version": i.get("version"),
                      "kernels": i.get("architecture")} for i in info],
            "coretype_env": os.environ.get("OPENBLAS_CORETYPE") or None}
