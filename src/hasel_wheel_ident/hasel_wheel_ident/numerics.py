"""OpenBLAS's kernels pinned for the identification command and the benchmarks (no rclpy).

OpenBLAS, the BLAS that numpy and scipy wheels ship, picks its kernels for the CPU it finds
(``DYNAMIC_ARCH``), and kernels for different CPUs sum in different orders, so a fit's last
bits differ between, say, the SkylakeX (AVX-512) and the Haswell (AVX2 and FMA) kernels.
The identification decides at gates (a held-out cut of 10 %, a Wald p-value, a refit's
convergence), and a fit that lands within rounding of a gate can fall on either side.
``hasel_wheel identify`` (:func:`rerun_pinned`, called by ``hasel_wheel_ident.cli``) and the
identification benchmarks (:func:`pin_blas_kernels`, before they import numpy) run
``OPENBLAS_CORETYPE=Haswell``: the same report for the same recording on every x86-64
machine with AVX2 and FMA, as Intel's MKL does with ``MKL_CBWR``.  Importing the package
pins nothing: a program that uses it keeps OpenBLAS's own choice.

numpy's own vector loops are a second source: they take AVX-512 routes where the CPU has
AVX-512 and AVX2 routes elsewhere (:func:`has_avx512`), and no switch pins them.

The kernels are chosen once, when OpenBLAS loads.  A value the user set for
``OPENBLAS_CORETYPE`` is kept; nothing is pinned on a CPU without AVX2 and FMA or on other
architectures.  test_numerics.py holds these rules.
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


def has_avx512() -> bool:
    """Whether this CPU has AVX-512 (``avx512f``), on which numpy's own vector loops (exp,
    log, sums) take their AVX-512 routes; without it they take AVX2 routes, whose last bits
    differ.  Pinning OpenBLAS does not pin these."""
    return "avx512f" in _cpu_flags()


def pinnable() -> bool:
    """Whether this machine runs the :data:`KERNEL` kernels (x86-64 with AVX2 and FMA)."""
    return platform.machine().lower() in ("x86_64", "amd64") and _NEEDS <= _cpu_flags()


def pin_blas_kernels() -> str | None:
    """Set ``OPENBLAS_CORETYPE`` to :data:`KERNEL` when that can still take effect (numpy not
    yet imported) and the CPU runs it.  Returns the core type in force after the call (the
    user's own, or the pinned one), or None when nothing is pinned."""
    own = os.environ.get("OPENBLAS_CORETYPE")
    if own:
        return own
    if "numpy" in sys.modules or not pinnable():
        return None                      # OpenBLAS has chosen its kernels already
    os.environ["OPENBLAS_CORETYPE"] = KERNEL
    return KERNEL


def rerun_pinned() -> None:
    """Make this process run OpenBLAS's :data:`KERNEL` kernels: pin them if numpy is not yet
    imported, else, when OpenBLAS already loaded other kernels, replace the process by the
    same command line (``sys.orig_argv``) with ``OPENBLAS_CORETYPE`` set.  Returns without
    doing either when the user set ``OPENBLAS_CORETYPE``, the CPU does not run the kernels
    (:func:`pinnable`), or the kernels in use are :data:`KERNEL` or unknown (no
    threadpoolctl).  For a command's entry point only: the re-run starts the program over."""
    if pin_blas_kernels() is not None or os.environ.get("OPENBLAS_CORETYPE") or not pinnable():
        return
    kernels = {b["kernels"] for b in blas_in_use()["blas"] if b["library"] == "openblas"}
    if not kernels or kernels == {KERNEL}:
        return
    sys.stdout.flush()
    sys.stderr.flush()
    os.execve(sys.executable, [sys.executable, *sys.orig_argv[1:]],
              dict(os.environ, OPENBLAS_CORETYPE=KERNEL))


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
