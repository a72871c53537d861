"""OpenBLAS's kernels: pinned by ``hasel_wheel identify``, left to OpenBLAS by the package
import (hasel_wheel_ident.numerics).

Each case runs in a fresh interpreter: the kernels are chosen once, when OpenBLAS loads."""
import json
import math
import os
import shutil
import subprocess
import sys

import pytest

from hasel_wheel_ident import numerics as N
from hasel_wheel_ident import synthetic as S
from hasel_wheel_ident.data import write_csv
from hasel_wheel_sim.plant import PlantConfig

needs_pin = pytest.mark.skipif(not N.pinnable(), reason="not an x86-64 CPU with AVX2 and FMA")


def _env(**env: str) -> dict:
    """This process's environment without OPENBLAS_CORETYPE, plus ``env``."""
    return {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"} | env


def _fresh(code: str, **env: str) -> dict:
    """Run ``code`` in a new interpreter without OPENBLAS_CORETYPE (plus ``env``); returns
    the JSON it prints."""
    out = subprocess.run([sys.executable, "-c", code], env=_env(**env), capture_output=True,
                         text=True, check=True, timeout=60)
    return json.loads(out.stdout)


PROBE = ("import json; from hasel_wheel_ident.numerics import blas_in_use; "
         "print(json.dumps(blas_in_use()))")
#: a process that loaded numpy (OpenBLAS's own kernels), then asks for the pinned ones
RERUN = ("import sys, numpy; from hasel_wheel_ident.numerics import rerun_pinned; "
         "rerun_pinned(); " + PROBE)


def test_importing_the_package_leaves_openblas_its_own_kernels():
    own = _fresh("import numpy; " + PROBE)
    got = _fresh("import hasel_wheel_ident, numpy; " + PROBE)
    assert got["coretype_env"] is None
    assert [b["kernels"] for b in got["blas"]] == [b["kernels"] for b in own["blas"]]


@needs_pin
def test_a_process_that_loaded_other_kernels_is_rerun_with_the_pinned_ones():
    got = _fresh(RERUN)
    assert {b["kernels"] for b in got["blas"]} == {N.KERNEL}


@needs_pin
def test_a_kernel_set_the_user_chose_is_kept():
    got = _fresh(RERUN, OPENBLAS_CORETYPE="Sandybridge")
    assert got["coretype_env"] == "Sandybridge"
    assert {b["kernels"] for b in got["blas"]} == {"Sandybridge"}


def test_nothing_is_pinned_once_numpy_has_loaded():
    got = _fresh("import numpy, json, hasel_wheel_ident; "
                 "from hasel_wheel_ident.numerics import pin_blas_kernels; "
                 "print(json.dumps({'again': pin_blas_kernels(), "
                 "'env': __import__('os').environ.get('OPENBLAS_CORETYPE')}))")
    assert got == {"again": None, "env": None}


@needs_pin
def test_the_identify_command_runs_the_pinned_kernels(tmp_path):
    specs = tuple(S.SyntheticTrial(math.radians(a), drive=12.0, coast=6.0) for a in (2.0, 6.0))
    paths = []
    for tr in S.record_set(specs, config=PlantConfig(seed=4, switching="tick")):
        paths.append(str(tmp_path / f"{tr.name}.csv"))
        write_csv(tr, paths[-1])
    exe = shutil.which("hasel_wheel", path=os.path.dirname(sys.executable))
    subprocess.run([exe, "identify", *paths, "--out", str(tmp_path / "r"), "--folds", "2",
                    "--only", "viscous_drag", "--quiet"], env=_env(), check=True,
                   capture_output=True, timeout=600)
    got = json.loads((tmp_path / "r" / "report.json").read_text())["numerics"]
    assert {b["kernels"] for b in got["blas"]} == {N.KERNEL}
    if got["coretype_env"] is None:      # not re-run: OpenBLAS chose these kernels itself
        own = _fresh("import numpy; " + PROBE)
        assert {b["kernels"] for b in own["blas"]} == {N.KERNEL}
    else:
        assert got["coretype_env"] == N.KERNEL
