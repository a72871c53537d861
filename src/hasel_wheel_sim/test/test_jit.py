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
