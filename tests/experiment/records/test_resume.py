"""SIGKILL mid-session, then ``--resume``: no completed trial lost, none repeated, and a row torn
by the kill never makes a file unreadable (issue 3, item 7); and, without a window, the choice
of the session a run continues (:mod:`fovexp.experiment.records.resume`)."""

from __future__ import annotations

import csv
import json
import signal
import warnings
from pathlib import Path

import pytest

from fovexp import FovexpError
from fovexp.experiment.options import SessionOptions
from fovexp.experiment.protocol.spec import load_protocol
from fovexp.experiment.records.logs import GAZE_COLUMNS, read_trials
from fovexp.experiment.records.resume import (
    attempts_so_far,
    choose_session,
    done_trials,
    find_sessions,
    incomplete_sessions,
    new_session_id,
)
from fovexp.experiment.session import Session

from experiment_helpers import (  # noqa: F401
    REPO,
    make_workspace,
    popen_cli,
    run_cli,
    wait_for_trials,
    xvfb_display,
)


@pytest.mark.gui
@pytest.mark.slow
def test_sigkill_then_resume(tmp_path: Path, xvfb_display) -> None:  # noqa: F811
    ws = make_workspace(tmp_path / "ws")
    args = ["run", "protocols/calibration-fe.yaml", "--participant", "K01", "--dry-run",
            "--practice", "1", "--limit-trials", "8", "--sim-speed", "4"]
    folder = ws / "results" / "calibration-fe" / "K01"
    proc = popen_cli(args, ws)
    try:
        n = wait_for_trials(proc, folder / "trials.csv", 3, timeout_s=180)
        assert proc.poll() is None, proc.communicate()[1][-2000:]
        assert n >= 3
        # While it runs, a second run of the same session (another process's lock) is refused:
        # it would log every trial twice. (In this process: a second CLI would take longer to
        # start than the first needs to finish.)
        with pytest.raises(FovexpError, match="in use by another fovexp run"):
            Session(load_protocol(ws / "protocols" / "calibration-fe.yaml",
                                  results_root=ws / "results"),
                    SessionOptions(participant="K01", results_root=ws / "results",
                                   tracker="simulated", dry_run=True, resume=True,
                                   window_size=(480, 270)))  # the CLI's dry-run window
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


# -- the choice of the session, without a window ---------------------------------------------------
def write_session(folder: Path, sid: str, **info) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"session-{sid}.json").write_text(json.dumps({"session": sid, **info}))


def test_incomplete_sessions_and_their_order(tmp_path: Path) -> None:
    """Sessions in the order of their ids; an unreadable file is left out; a session that
    failed before its first trial blocks nothing, one that failed later can be resumed."""
    write_session(tmp_path, "20260102-000000", completed=False, state="failed", n_completed=0)
    write_session(tmp_path, "20260101-000000", completed=True, state="completed")
    write_session(tmp_path, "20260103-000000", completed=False, state="failed", n_completed=2)
    write_session(tmp_path, "20260104-000000", completed=False, state="aborted")
    (tmp_path / "session-20260105-000000.json").write_text("{torn")
    found = find_sessions(tmp_path)
    assert [s["session"] for s in found] == ["20260101-000000", "20260102-000000",
                                             "20260103-000000", "20260104-000000"]
    assert all(s["_path"].endswith(f"session-{s['session']}.json") for s in found)
    assert [s["session"] for s in incomplete_sessions(found)] == ["20260103-000000",
                                                                  "20260104-000000"]
    sid = new_session_id(tmp_path)
    assert len(sid) == 15 and not (tmp_path / f"session-{sid}.json").exists()


def test_choose_session_refusals_and_resume(tmp_path: Path) -> None:
    lp = load_protocol(REPO / "protocols" / "calibration-fe.yaml")
    kw = dict(resume=False, new_session=False, dry_run=True, tracker="simulated",
              limit_trials=3, practice_trials=1)
    new = choose_session(tmp_path, lp, "P01", **kw)
    assert not new.resumed and (new.limit_trials, new.practice_trials) == (3, 1)
    with pytest.raises(FovexpError, match="--resume: no incomplete session of calibration-fe"):
        choose_session(tmp_path, lp, "P01", **{**kw, "resume": True})
    runs = [{"dry_run": True, "tracker": "simulated"}]
    write_session(tmp_path, "20260101-000000", completed=False, state="aborted",
                  protocol_sha256=lp.sha256, runs=runs, derived=lp.derived,
                  plan={"limit_trials": 5, "practice_trials": 0})
    with pytest.raises(FovexpError, match="add --resume to continue it, or --new-session"):
        choose_session(tmp_path, lp, "P01", **kw)
    assert not choose_session(tmp_path, lp, "P01", **{**kw, "new_session": True}).resumed
    # resumed: the limits it started with, not this run's
    got = choose_session(tmp_path, lp, "P01", **{**kw, "resume": True})
    assert got.resumed and got.session_id == "20260101-000000"
    assert (got.limit_trials, got.practice_trials) == (5, 0) and "_path" not in got.info
    # never by a real session, nor another gaze source
    with pytest.raises(FovexpError, match="started as a dry run with --tracker simulated"):
        choose_session(tmp_path, lp, "P01", **{**kw, "resume": True, "dry_run": False})
    with pytest.raises(FovexpError, match="resume it the same way"):
        choose_session(tmp_path, lp, "P01", **{**kw, "resume": True, "tracker": "mouse"})
    write_session(tmp_path, "20260101-000000", completed=False, state="aborted",
                  protocol_sha256="0" * 64, runs=runs)
    with pytest.raises(FovexpError, match="changed since session 20260101-000000 started"):
        choose_session(tmp_path, lp, "P01", **{**kw, "resume": True})


def test_done_trials_and_attempts_from_the_logs(tmp_path: Path) -> None:
    """Trials done: the rows of this session only. Attempts: the session file's count, or
    more where the frame or blanking log saw a later attempt (its start killed before the
    session file said so); a torn last line is skipped."""
    from fovexp.experiment.records.logs import TRIAL_COLUMNS, TrialLog

    log = TrialLog(tmp_path / "trials.csv")
    for sid, i in (("A", 0), ("A", 2), ("B", 1)):
        r = dict.fromkeys(TRIAL_COLUMNS)
        r.update(participant="P01", session=sid, experiment="calibration-fe",
                 protocol_sha256="ab" * 32, trial_index=i, practice=False, repetition=0,
                 image="scene-00", blur_rate=0.34, method="contrast", adjusted_parameter="f_e",
                 f_e=0.1, start_value=0.2, final_value=0.1, response_time_s=1.5,
                 wheel_events=4, blanked_fraction=0.0, dropped_frames=0, tracker="simulated",
                 seed=1, software_version="0.1.0", timestamp="2026-01-01T00:00:00+00:00")
        log.append(r)
    assert done_trials(tmp_path / "trials.csv", "A") == {0, 2}
    assert done_trials(tmp_path / "missing.csv", "A") == set()
    (tmp_path / "frames-A.csv").write_text("trial_index,attempt,frame\n0,0,0\n3,1,0\n3,")
    (tmp_path / "blanking-A.csv").write_text("trial_index,attempt,start_s\n4,2,0.1\n")
    got = attempts_so_far(tmp_path, "A", {"attempts": {"0": 1, "3": 1}})
    assert got == {0: 1, 3: 2, 4: 3}
    assert attempts_so_far(tmp_path, "B", {}) == {}
