"""Tests marked ``avx512_route`` hold a verdict that sits at one of the identification's
gates and takes its route on numpy's AVX-512 vector loops; on a CPU without AVX-512 numpy's
AVX2 loops round differently and the verdict flips, so they are skipped there, with the
reason (docs/identification.md, "Numerics")."""
import pytest

from hasel_wheel_ident.numerics import has_avx512


def pytest_collection_modifyitems(config, items):
    if has_avx512():
        return
    skip = pytest.mark.skip(reason="a verdict at a gate, held on numpy's AVX-512 routes; this "
                                   "CPU has AVX2 only (docs/identification.md, Numerics)")
    for item in items:
        if item.get_closest_marker("avx512_route"):
            item.add_marker(skip)
