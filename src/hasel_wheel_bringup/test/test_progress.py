"""Progress bars of the long commands (:mod:`hasel_wheel_bag.progress`): drawn on stderr when
it is a terminal, left out when it is not; the library functions draw none unless asked."""
import fcntl
import math
import os
import struct
import subprocess
import sys
import termios
import threading
from contextlib import contextmanager

from hasel_wheel_bag.progress import progress_bar
from hasel_wheel_ident import candidates as C
from hasel_wheel_ident import synthetic as S
from hasel_wheel_ident.select import identify
from hasel_wheel_sim.plant import PlantConfig

from hasel_wheel_bringup import demo as D


class _Terminal:
    """A pseudo-terminal: ``file`` writes to it, ``text`` is what was written (complete when
    the ``terminal()`` block has ended)."""

    def __init__(self) -> None:
        self.master, self.slave = os.openpty()
        # 24 rows of 100 columns: tqdm fits its bar to the terminal, and draws nothing in 0
        fcntl.ioctl(self.slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))
        self.file = os.fdopen(os.dup(self.slave), "w")
        self._chunks: list[bytes] = []
        self._reader = threading.Thread(target=self._drain, daemon=True)
        self._reader.start()

    def _drain(self) -> None:
        while True:
            try:
                data = os.read(self.master, 4096)
            except OSError:                 # EIO: every writer has closed the terminal
                return
            if not data:
                return
            self._chunks.append(data)

    def close(self) -> None:
        self.file.close()
        os.close(self.slave)
        self._reader.join(timeout=10)
        os.close(self.master)

    @property
    def text(self) -> str:
        return b"".join(self._chunks).decode("utf-8", "replace")


@contextmanager
def terminal():
    tty = _Terminal()
    try:
        yield tty
    finally:
        tty.close()


@contextmanager
def stderr_on(tty: _Terminal):
    saved, sys.stderr = sys.stderr, tty.file
    try:
        yield
    finally:
        sys.stderr = saved


def test_the_bar_is_drawn_on_a_terminal_and_left_out_elsewhere(capsys):
    with terminal() as tty, stderr_on(tty):
        assert list(progress_bar(range(3), "counting", unit="item", scale=False)) == [0, 1, 2]
    assert "counting" in tty.text and "0/3" in tty.text and "item" in tty.text
    assert list(progress_bar(range(3), "counting", unit="item", scale=False)) == [0, 1, 2]
    assert capsys.readouterr().err == ""            # pytest's capture is no terminal


def test_the_demo_counts_each_runs_simulated_seconds_only_when_asked(capsys):
    with terminal() as quiet, stderr_on(quiet):
        D.run_variants(PlantConfig(switching="tick"), 0.005, D.VARIANTS[:2])
    with terminal() as tty, stderr_on(tty):
        D.run_variants(PlantConfig(switching="tick"), 0.005, D.VARIANTS[:2], progress=True)
    assert quiet.text == ""
    for i, (label, _kw) in enumerate(D.VARIANTS[:2], start=1):
        assert f"demo {i}/2: {label}" in tty.text
    assert "0/1 s" in tty.text                      # 230 s * 0.005, in simulated seconds
    D.run_variants(PlantConfig(switching="tick"), 0.005, D.VARIANTS[:1], progress=True)
    assert capsys.readouterr().err == ""


def test_identify_shows_its_folds_and_candidates_only_when_asked(capsys):
    specs = tuple(S.SyntheticTrial(math.radians(a), drive=4.0, coast=2.0) for a in (2.0, 6.0))
    trials = S.record_set(specs, config=PlantConfig(seed=4, switching="tick"))
    lib = C.library(["viscous_drag", "com_offset"], None)
    with terminal() as quiet, stderr_on(quiet):
        identify(trials, library=lib, k_folds=2, analyse_residuals=False)
    with terminal() as tty, stderr_on(tty):
        identify(trials, library=lib, k_folds=2, analyse_residuals=False,
                 progress_bars="identify")
    assert quiet.text == ""
    assert "identify: nominal model" in tty.text and "0/2" in tty.text and "fold" in tty.text
    assert "identify: screening" in tty.text and "candidate" in tty.text
    assert capsys.readouterr().err == ""


def _trials_command(out, stderr) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "hasel_wheel_bringup.cli", "trials",
                           "--out", str(out), "--phi-a-deg", "2", "6", "--drive", "2",
                           "--coast", "1"], stdout=subprocess.PIPE, stderr=stderr,
                          text=True, timeout=120)


def test_the_trials_command_shows_progress_on_a_terminal_and_none_in_a_pipe(tmp_path):
    with terminal() as tty:
        on_tty = _trials_command(tmp_path / "tty", tty.slave)
    piped = _trials_command(tmp_path / "pipe", subprocess.PIPE)
    assert on_tty.returncode == piped.returncode == 0
    assert "trials:" in tty.text and "0/2" in tty.text
    assert piped.stderr == ""
    assert on_tty.stdout.replace("tty", "pipe") == piped.stdout    # stdout as it was
