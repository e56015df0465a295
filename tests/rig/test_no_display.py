"""Without a display, the rig check's error names its own command under Xvfb, and ``fovexp
run``'s its own: one wording (``no_display_hint``), each command naming itself (issue 32)."""

from __future__ import annotations

from pathlib import Path

from experiment_helpers import make_workspace, run_cli


def test_the_no_display_error_names_the_command_run(tmp_path: Path) -> None:
    ws = make_workspace(tmp_path / "ws")
    rig = run_cli(["rig", "check", "--dry-run", "--duration", "1"], cwd=ws, timeout=300,
                  env_update={"DISPLAY": None, "WAYLAND_DISPLAY": None})
    assert rig.returncode == 2, rig.stderr[-2000:]
    last = rig.stderr.strip().splitlines()[-1]
    assert last.startswith("fovexp rig check: error: cannot open a window")
    assert "xvfb-run -a fovexp rig check ..." in last and "fovexp run" not in last
    run = run_cli(["run", "calibration-fe", "--participant", "SIM01", "--dry-run",
                   "--limit-trials", "1"], cwd=ws, timeout=300,
                  env_update={"DISPLAY": None, "WAYLAND_DISPLAY": None})
    assert run.returncode == 2, run.stderr[-2000:]
    assert "xvfb-run -a fovexp run ..." in run.stderr.strip().splitlines()[-1]
