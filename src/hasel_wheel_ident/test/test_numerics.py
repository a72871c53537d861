"""OpenBLAS's kernels are pinned before numpy loads (hasel_wheel_ident.numerics).

Each case runs in a fresh interpreter: the kernels are chosen once, when OpenBLAS loads."""
import json
import os
import subprocess
import sys

import pytest

from hasel_wheel_ident import numerics as N

PINNABLE = (
    os.uname().machine in ("x86_64", "AMD64") and {"avx2", "fma"} <= N._cpu_flags())
needs_pin = pytest.mark.skipif(not PINNABLE, reason="not an x86-64 CPU with AVX2 and FMA")


def _fresh(code: str, **env: str) -> dict:
    """Run ``code`` in a new interpreter without OPENBLAS_CORETYPE (plus ``env``); returns
    the JSON it prints."""
    e = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"} | env
    out = subprocess.run([sys.executable, "-c", code], env=e, capture_output=True, text=True,
                         check=True, timeout=60)
    return json.loads(out.stdout)


PROBE = ("import json; from hasel_wheel_ident.numerics import blas_in_use; "
         "print(json.dumps(blas_in_use()))")


@needs_pin
def test_importing_the_package_first_runs_the_haswell_kernels():
    got = _fresh("import hasel_wheel_ident, numpy; " + PROBE)
    assert got["coretype_env"] == "Haswell"
    assert [b["kernels"] for b in got["blas"]] == ["Haswell"]


@needs_pin
def test_a_kernel_set_the_user_chose_is_kept():
    got = _fresh("import hasel_wheel_ident, numpy; " + PROBE, OPENBLAS_CORETYPE="Sandybridge")
    assert got["coretype_env"] == "Sandybridge"
    assert [b["kernels"] for b in got["blas"]] == ["Sandybridge"]


def test_nothing_is_pinned_once_numpy_has_loaded():
    got = _fresh("import numpy, json, hasel_wheel_mpc; "
                 "from hasel_wheel_ident.numerics import pin_blas_kernels; "
                 "print(json.dumps({'again': pin_blas_kernels(), "
                 "'env': __import__('os').environ.get('OPENBLAS_CORETYPE')}))")
    assert got == {"again": None, "env": None}


@needs_pin
@pytest.mark.skipif(os.environ.get("OPENBLAS_CORETYPE", N.KERNEL) != N.KERNEL,
                    reason="OPENBLAS_CORETYPE set to another kernel set by the user")
def test_this_suite_runs_the_pinned_kernels():
    # conftest.py imports the package before any test module imports numpy
    assert {b["kernels"] for b in N.blas_in_use()["blas"]} == {"Haswell"}
