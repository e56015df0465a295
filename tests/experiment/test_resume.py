"""SIGKILL mid-session, then ``--resume``: no completed trial lost, none repeated, and a row torn
by the kill never makes a file unreadable (issue 3, item 7)."""

from __future__ import annotations

import csv
import json
import signal
import time
import warnings
from pathlib import Path

import pytest

from fovexp import FovexpError
from fovexp.experiment.logs import GAZE_COLUMNS, read_trials
from fovexp.experiment.protocol import load_protocol
from fovexp.experiment.session import Session, SessionOptions

from experiment_helpers import make_workspace, popen_cli, run_cli, xvfb_display  # noqa: F401

pytestmark = [pytest.mark.gui, pytest.mark.slow]


def test_sigkill_then_resume(tmp_path: Path, xvfb_display) -> None:  # noqa: F811
    ws = make_workspace(tmp_path / "ws")
    args = ["run", "protocols/calibration-fe.yaml", "--participant", "K01", "--dry-run",
            "--practice", "1", "--limit-trials", "8", "--sim-speed", "4"]
    folder = ws / "results" / "calibration-fe" / "K01"
    proc = popen_cli(args, ws)
    try:
        deadline = time.monotonic() + 180
        n = 0
        while time.monotonic() < deadline and proc.poll() is None:
            if (folder / "trials.csv").exists():
                n = len(read_trials(folder / "trials.csv")[0])
                if n >= 3:
                    break
            time.sleep(0.05)
        assert proc.poll() is None, proc.communicate()[1][-2000:]
        assert n >= 3
        # While it runs, a second run of the same session (another process's lock) is refused:
        # it would log every trial twice. (In this process: a second CLI would take longer to
        # start than the first needs to finish.)
        with pytest.raises(FovexpError, match="in use by another fovexp run"):
            Session(load_protocol(ws / "protocols" / "calibration-fe.yaml",
                                  results_root=ws / "results"),
                    SessionOptions(participant="K01", results_root=ws / "results",
                                   tracker="simulated", dry_run=True, resume=True))
        assert proc.poll() is None
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == -signal.SIGKILL
    before = (folder / "trials.csv").read_bytes()
    rows_before, _ = read_trials(folder / "trials.csv")
    assert 3 <= len(rows_before) < 9
    (session_file,) = folder.glob("session-*.json")
    info = killed_info = json.loads(session_file.read_text())
    assert info["completed"] is False and info["state"] == "running"
    # A write cut off mid-row, as a kill during the write would leave it.
    torn = before.splitlines(keepends=True)[-1][:37]
    with open(folder / "trials.csv", "ab") as fh:
        fh.write(torn)
    with open(next(folder.glob("gaze-*.csv")), "ab") as fh:
        fh.write(b"5,12345,678")
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        assert read_trials(folder / "trials.csv")[0] == rows_before
        assert any("torn" in str(x.message) for x in w)

    # Without --resume the runner refuses to start over silently.
    r = run_cli(args, ws)
    assert r.returncode == 2 and "--resume" in r.stderr

    r = run_cli([*args, "--resume"], ws, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]
    after = (folder / "trials.csv").read_bytes()
    assert after.startswith(before)  # nothing already logged was rewritten
    rows, _ = read_trials(folder / "trials.csv")
    idx = [r["trial_index"] for r in rows]
    assert sorted(idx) == list(range(9)) and len(idx) == len(set(idx))
    assert {r["session"] for r in rows} == {info["session"]}
    # The resumed part continues the same seeded order and start values.
    _, plan = load_protocol(ws / "protocols" / "calibration-fe.yaml").plan("K01", 8, 1)
    for r in rows:
        t = plan[r["trial_index"]]
        assert (r["image"], r["blur_rate"], r["practice"]) == (t.image, t.blur_rate, t.practice)
        assert r["start_value"] == pytest.approx(t.start_value)
    info = json.loads(session_file.read_text())
    assert info["completed"] is True and len(info["runs"]) == 2
    assert info["runs"][1]["remaining_trials"] == 9 - len(rows_before)
    gaze = next(folder.glob("gaze-*.csv")).read_text().splitlines()
    assert all(len(line.split(",")) == len(GAZE_COLUMNS) for line in gaze)  # no torn row
    # Attempts number on across the kill: the trial cut off by it was begun again as a new
    # attempt, never a second attempt 0 (frames and gaze rows of both are kept apart).
    with open(next(folder.glob("frames-*.csv"))) as fh:
        frames = list(csv.DictReader(fh))
    keys = [(f["trial_index"], f["attempt"], f["frame"]) for f in frames]
    assert len(keys) == len(set(keys))
    cut = str(len(rows_before))  # the trial under way at the kill (the plan's order)
    begun = killed_info["attempts"][cut]  # recorded before its first frame
    assert begun >= 1
    attempts = sorted({int(f["attempt"]) for f in frames if f["trial_index"] == cut})
    assert attempts and attempts[-1] == begun and info["attempts"][cut] == begun + 1, attempts
    assert all(a < begun for a in attempts[:-1])  # the killed run's, if any reached the disk
    # Running again has nothing left to do.
    r = run_cli([*args, "--resume"], ws)
    assert r.returncode == 2 and "no incomplete session" in r.stderr
