"""The Teensyduino layer of the firmware (``firmware/teensy``) on the host: the sketch and its
board adapters, compiled against a mock Arduino API with a simulated board
(``firmware/host/mock_arduino``), pass every check of ``firmware/host/board_check.cpp``."""
import re
import subprocess

import pytest

from hasel_wheel_sim.device_cpp import BUILD_ROOT, build_core, compiler_missing

pytestmark = pytest.mark.xdist_group("firmware_board")

TARGET = "hasel_board_check"
#: The checks the board layer must pass (board_check.cpp prints more).
REQUIRED = ("safe_setup", "shift_order", "encoder_frame", "tick_ack", "drop_whole_frame",
            "rx_leftover", "watchdog_pin", "hardware_watchdog")
LINE = re.compile(r"^check (\w+): (pass|fail)\b", re.M)


@pytest.fixture(scope="module")
def board_check() -> tuple[subprocess.CompletedProcess, dict[str, str]]:
    """The check executable's run, and each check's outcome by name."""
    missing = compiler_missing()
    if missing:
        pytest.skip(f"the firmware's host check needs {missing}; install g++ and cmake to run it")
    out = build_core(BUILD_ROOT, targets=(TARGET,))
    run = subprocess.run([str(out / TARGET)], capture_output=True, text=True, timeout=120)
    return run, dict(LINE.findall(run.stdout))


@pytest.mark.parametrize("name", REQUIRED)
def test_board_check_passes(board_check, name):
    run, outcome = board_check
    got = outcome.get(name, "not reported")
    assert got == "pass", f"check {name}: {got}\n{run.stdout}"


def test_board_check_exits_zero_with_no_failed_check(board_check):
    run, outcome = board_check
    failed = [n for n, r in outcome.items() if r != "pass"]
    assert run.returncode == 0 and not failed, f"failed: {failed}\n{run.stdout}{run.stderr}"
