"""Shared helpers of the experiment-runner tests: a private Xvfb, a scratch project layout, and
running ``python -m fovexp.experiment`` in a subprocess."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
PYTHON = sys.executable


def _free_display() -> int:
    for n in range(99, 160):
        if not Path(f"/tmp/.X11-unix/X{n}").exists() and not Path(f"/tmp/.X{n}-lock").exists():
            return n
    raise RuntimeError("no free X display number")


@pytest.fixture(scope="session")
def xvfb_display():
    """A DISPLAY for PsychoPy windows: the existing one, or a private ``Xvfb`` started here."""
    pytest.importorskip("psychopy", reason="PsychoPy is not installed (fovexp[experiment])")
    if os.environ.get("DISPLAY"):
        yield os.environ["DISPLAY"]
        return
    exe = shutil.which("Xvfb")
    if exe is None:
        pytest.skip("Xvfb is not installed (apt-get install xvfb) and DISPLAY is unset")
    n = _free_display()
    proc = subprocess.Popen([exe, f":{n}", "-screen", "0", "1280x720x24", "-nolisten", "tcp"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    sock = Path(f"/tmp/.X11-unix/X{n}")
    for _ in range(100):
        if sock.exists() or proc.poll() is not None:
            break
        time.sleep(0.05)
    if proc.poll() is not None or not sock.exists():
        proc.kill()
        pytest.fail(f"Xvfb :{n} did not start")
    os.environ["DISPLAY"] = f":{n}"
    try:
        yield f":{n}"
    finally:
        del os.environ["DISPLAY"]
        proc.terminate()
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()


def make_workspace(root: Path) -> Path:
    """A scratch project: ``protocols/`` (copied, editable), ``stimuli/`` (linked), ``results/``.

    The shipped protocols name ``../results/<experiment>`` as their dependencies, so inside the
    scratch project they find the dry runs' own results.
    """
    (root / "protocols").mkdir(parents=True)
    for p in (REPO / "protocols").glob("*.yaml"):
        shutil.copy(p, root / "protocols" / p.name)
    shutil.copytree(REPO / "protocols" / "displays", root / "protocols" / "displays")
    (root / "stimuli").symlink_to(REPO / "stimuli")
    (root / "results").mkdir()
    return root


def run_cli(args: list[str], cwd: Path, timeout: float = 300) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    return subprocess.run([PYTHON, "-m", "fovexp.experiment", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=timeout)


def popen_cli(args: list[str], cwd: Path) -> subprocess.Popen:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    return subprocess.Popen([PYTHON, "-m", "fovexp.experiment", *args], cwd=cwd, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
