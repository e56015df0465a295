"""``fovexp run --monitor``: the monitor beside a dry run, in a process of its own, for as long
as the run lasts."""

from __future__ import annotations

import socket
import time
from pathlib import Path

import pytest

from experiment_helpers import make_workspace, popen_cli, xvfb_display  # noqa: F401

pytestmark = [pytest.mark.gui, pytest.mark.slow]
httpx = pytest.importorskip("httpx2", reason="httpx2 is not installed (the test extra)")
pytest.importorskip("uvicorn", reason="the monitor extra is not installed")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_the_monitor_runs_beside_the_session(tmp_path: Path, xvfb_display: str) -> None:  # noqa: F811
    ws = make_workspace(tmp_path / "ws")
    port = _free_port()
    run = popen_cli(["run", "protocols/calibration-fe.yaml", "--participant", "SIM02",
                     "--dry-run", "--limit-trials", "3", "--practice", "0", "--sim-speed", "4",
                     "--monitor", "--monitor-port", str(port)], cwd=ws)
    seen = []
    try:
        t_end = time.monotonic() + 120
        while run.poll() is None and time.monotonic() < t_end:
            try:
                sessions = httpx.get(f"http://127.0.0.1:{port}/api/sessions",
                                     timeout=2).json()["sessions"]
                seen += [(s["participant"], s["status"]) for s in sessions]
            except httpx.TransportError:
                pass  # not started yet, or already stopped
            time.sleep(0.3)
        out, err = run.communicate(timeout=60)
    finally:
        if run.poll() is None:
            run.kill()
    assert run.returncode == 0, err[-2000:]
    assert ("SIM02", "running") in seen
    assert f"http://127.0.0.1:{port}/" in err  # the monitor's address on the console
    # it stopped with the run
    with pytest.raises(httpx.TransportError):
        httpx.get(f"http://127.0.0.1:{port}/", timeout=2)
