"""The compilation marks of the core: a kernel (NRT off) cannot allocate."""
import numpy as np
import pytest

from hasel_wheel_sim import jit as J


def _allocating(n):
    return np.zeros(n).sum()


def _summing(a):
    total = 0.0
    for x in a:
        total += x
    return total


@pytest.mark.skipif(not J.HAVE_NUMBA, reason="numba not installed: kernels run interpreted")
def test_a_kernel_refuses_to_allocate():
    # With reference counting off, an array made inside would be neither freed nor safely
    # returned; numba must refuse to compile it instead of running it.
    import numba

    kernel = J.jit_kernel(_allocating)
    with pytest.raises(numba.core.errors.TypingError, match="zeros"):
        kernel(3)


def test_a_kernel_computes_what_the_python_function_does():
    a = np.array([0.5, 1.25, -2.0, 4.0])
    assert J.jit_kernel(_summing)(a) == 3.75


@pytest.mark.skipif(not J.HAVE_NUMBA, reason="numba not installed: nothing is cached")
def test_the_cache_lies_under_the_directory_the_environment_names(tmp_path):
    # in a fresh interpreter (the directory is chosen at import): under HASEL_WHEEL_JIT_CACHE,
    # in a subdirectory keyed by the core's sources; unwritable, it falls back beside jit.py
    import os
    import subprocess
    import sys
    probe = "from hasel_wheel_sim import jit; import numba; print(numba.config.CACHE_DIR)"
    env = dict(os.environ, HASEL_WHEEL_JIT_CACHE=str(tmp_path / "cache"))
    out = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True,
                         text=True, check=True).stdout.strip()
    assert os.path.dirname(out) == str(tmp_path / "cache")
    assert os.path.basename(out).startswith("numba-") and os.path.isdir(out)
    (tmp_path / "file").write_text("")           # a file cannot hold a directory
    env["HASEL_WHEEL_JIT_CACHE"] = str(tmp_path / "file")
    out = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True,
                         text=True, check=True).stdout.strip()
    assert os.path.dirname(out) == os.path.join(os.path.dirname(J.__file__), "__pycache__")


@pytest.mark.skipif(not J.HAVE_NUMBA or "PYTEST_XDIST_WORKER" not in __import__("os").environ,
                    reason="only on a pytest-xdist worker (./dev test)")
def test_each_test_worker_compiles_into_a_cache_of_its_own():
    import os
    import numba
    worker = os.environ["PYTEST_XDIST_WORKER"]
    assert os.path.dirname(numba.config.CACHE_DIR).endswith(
        os.path.join(".cache", "numba", worker))
