"""Fixtures shared by this package's tests (tests import nothing from here)."""
import pytest


@pytest.fixture(scope="session")
def firmware_build():
    """The C++ firmware core built for the host (skips where no compiler exists)."""
    from hasel_wheel_sim.device_cpp import compiler_missing, default_build
    missing = compiler_missing()
    if missing:
        pytest.skip(f"the C++ firmware core needs {missing}; install g++ and cmake to run it")
    return default_build()
