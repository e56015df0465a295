"""Issue 32: progress of long steps on stderr, a bar in a terminal and one line per update in a
log (fovexp.progress), as the commands use it."""

from __future__ import annotations

import io
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fovexp.progress import Steps, progress_bar


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


@pytest.fixture(autouse=True)
def _on(monkeypatch):
    monkeypatch.setenv("FOVEXP_PROGRESS", "1")


def test_a_log_gets_lines_and_a_terminal_one_redrawn_line() -> None:
    log = io.StringIO()
    for _ in progress_bar(range(4), desc="work", unit="scene", stream=log):
        pass
    lines = log.getvalue().splitlines()
    assert "\r" not in log.getvalue() and lines  # no redraws piled into one line
    assert lines[-1].startswith("work: 100%") and "4/4" in lines[-1]
    assert len(lines) <= 3  # the first, the last, and at most one every LOG_INTERVAL_S
    term = _Terminal()
    for _ in progress_bar(range(4), desc="work", stream=term):
        pass
    assert "\r" in term.getvalue() and term.getvalue().count("\n") <= 1


def test_steps_say_each_step_by_name_as_it_starts() -> None:
    log = io.StringIO()
    with Steps(["read", "enhance", "maps"], desc="fovexp enhance", stream=log) as step:
        step("read")
        step("enhance")
        step("maps")
        step("maps", "writing noise")
        with pytest.raises(ValueError, match="not one of"):
            step("nope")
    lines = log.getvalue().splitlines()
    assert [ln for ln in lines if ln.endswith((", read", ", enhance", ", maps",
                                               ", maps: writing noise", ", done"))] == [
        "fovexp enhance: 0/3 steps [00:00], read",
        "fovexp enhance: 1/3 steps [00:00], enhance",
        "fovexp enhance: 2/3 steps [00:00], maps",
        "fovexp enhance: 2/3 steps [00:00], maps: writing noise",
        "fovexp enhance: 3/3 steps [00:00], done"]


def test_off_says_nothing(monkeypatch) -> None:
    monkeypatch.setenv("FOVEXP_PROGRESS", "0")
    log = io.StringIO()
    for _ in progress_bar(range(3), desc="work", stream=log):
        pass
    assert log.getvalue() == ""


def test_enhance_with_maps_shows_its_steps_in_a_log(tmp_path: Path) -> None:
    """``fovexp enhance --dump-maps`` as a lab runs it, its stderr a file: each step and each
    map named on a line of its own; stdout keeps only the result's line."""
    import imageio.v3 as iio

    src = tmp_path / "in.png"
    rng = np.random.default_rng(0)
    iio.imwrite(src, (rng.random((90, 160, 3)) * 255).astype(np.uint8))
    proc = subprocess.run([sys.executable, "-m", "fovexp", "enhance", str(src),
                           str(tmp_path / "out.png"), "--impulses", "4",
                           "--dump-maps", str(tmp_path / "maps")],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.count("\n") == 1 and proc.stdout.startswith("wrote ")
    err = proc.stderr.splitlines()
    for part in ("read", "enhance", "write", "maps: computing noise", "maps: writing output",
                 "done"):
        assert any(line.startswith("fovexp enhance: ") and line.endswith(", " + part)
                   for line in err), (part, err)
