"""The results disk (issue 18, section 7): a session that cannot fit is refused before its first
trial with the figures (a stand-in for the free-space query); one that fills a real, small disk
(a tmpfs: needs root, skipped otherwise) stops with one line, no thread's traceback, every log
whole and nothing logged lost, and after space is freed ``--resume`` finishes it with no trial
repeated."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest

from fovexp import FovexpError
from fovexp.experiment import session as session_module
from fovexp.experiment.options import SessionOptions
from fovexp.experiment.protocol.spec import load_protocol
from fovexp.experiment.records import diskspace
from fovexp.experiment.records.diskspace import (
    check_space,
    disk_full_message,
    estimate_log_bytes,
    is_disk_full,
)
from fovexp.experiment.records.logs import BatchLog, TrialLog, read_trials
from fovexp.experiment.session import Session
from fovexp.experiment.tasks.trial import Key
from fovexp.results.frames import read_frame_log

from experiment_helpers import REPO, GreyEnhancer, ScriptedGaze, StubScreen, use_enhancer

W, H = 480, 270


class FakeEnhancer(GreyEnhancer):
    delay_s = 0.005


def test_the_estimate_and_the_refusal(tmp_path: Path, monkeypatch) -> None:
    est = estimate_log_bytes(22, 600.0, 120.0)  # the validation protocol at the paper's rates
    assert est.seconds == 22 * 45.0
    assert est.gaze_bytes_per_s == pytest.approx(0.114e6)  # the issue's ~0.1 MB/s
    assert est.total_bytes == pytest.approx(990 * (114_000 + 11_400) + 1e6)
    monkeypatch.setattr(diskspace, "disk_usage", lambda path: (50_000_000, 64_000_000_000))
    with pytest.raises(FovexpError) as err:
        check_space(tmp_path / "not" / "yet", est)
    msg = str(err.value)
    assert "\n" not in msg and "50.0 MB free" in msg and "about 125 MB for 22 trial(s)" in msg
    assert "--results" in msg
    monkeypatch.setattr(diskspace, "disk_usage", lambda path: (10**9, 64 * 10**9))
    assert check_space(tmp_path, est) == {"free_mb": 1000.0, "total_mb": 64000.0,
                                          "estimated_mb": 125.1}
    # the real query walks up to the nearest folder that exists
    monkeypatch.undo()
    free, total = diskspace.disk_usage(tmp_path / "a" / "b")
    assert 0 < free <= total


def make_session(root: Path, monkeypatch, resume: bool = False, limit: int = 6) -> Session:
    use_enhancer(monkeypatch, FakeEnhancer)
    lp = load_protocol(REPO / "protocols" / "calibration-fe.yaml")
    opts = SessionOptions(participant="D01", results_root=root, tracker="mouse", dry_run=False,
                          window_size=(W, H), practice_trials=0, limit_trials=limit,
                          skip_display_check=True, fullscreen=False, resume=resume,
                          console=lambda t: None)
    return Session(lp, opts)


def run(s: Session, every: int) -> int:
    enter = {i: [Key("return")] for i in range(every, 100_000, every)}
    return s.run(screen_factory=lambda **kw: StubScreen(inputs=enter, **kw),
                 gaze=ScriptedGaze(lambda t: (0.5, 0.5)))


def test_a_session_that_cannot_fit_is_refused_before_anything(tmp_path: Path,
                                                              monkeypatch) -> None:
    monkeypatch.setattr(diskspace, "disk_usage", lambda path: (2_000_000, 8_000_000))
    s = make_session(tmp_path / "results", monkeypatch)
    with pytest.raises(FovexpError, match=r"the results disk has 2.0 MB free .* need about"):
        run(s, 20)
    assert not (tmp_path / "results" / "calibration-fe" / "D01").exists()  # nothing written


def test_a_failed_write_leaves_the_log_whole(tmp_path: Path, monkeypatch) -> None:
    """A write cut short by a full disk: the file is cut back to its last whole row, the rows
    stay pending (the next flush writes them), and a trial row is not half there."""
    log = BatchLog(tmp_path / "g.csv", ["a", "b"])
    log.add((1, 2))
    log.flush()
    real_open = open

    class Full:
        def __init__(self, fh) -> None:
            self.fh = fh

        def __enter__(self):
            return self

        def __exit__(self, *exc) -> None:
            self.fh.close()

        def write(self, text: str) -> None:
            self.fh.write(text[:3])  # part of it reaches the file
            self.fh.flush()
            raise OSError(28, "No space left on device")

    import fovexp.experiment.records.logs as logs

    monkeypatch.setattr(logs, "open", lambda *a, **k: Full(real_open(*a, **k)), raising=False)
    log.add((3, 4))
    with pytest.raises(OSError) as err:
        log.flush()
    assert is_disk_full(err.value)
    assert (tmp_path / "g.csv").read_text() == "a,b\n1,2\n"
    trials = TrialLog.__new__(TrialLog)
    trials.path = tmp_path / "t.csv"
    trials.path.write_text("x\n")
    with pytest.raises(OSError):
        trials._write("a whole row\n")
    assert trials.path.read_text() == "x\n"
    monkeypatch.undo()
    assert log.flush() == 1
    assert (tmp_path / "g.csv").read_text() == "a,b\n1,2\n3,4\n"


@pytest.fixture()
def small_disk(tmp_path: Path):
    """A 400 kB tmpfs (mounting needs root); yields (folder, resize(size))."""
    folder = tmp_path / "disk"
    folder.mkdir()
    if os.geteuid() != 0 or shutil.which("mount") is None:
        pytest.skip("mounting a small tmpfs needs root")
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=400k", "tmpfs", str(folder)],
                       capture_output=True, text=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {r.stderr.strip()}")

    def resize(size: str) -> None:
        subprocess.run(["mount", "-o", f"remount,size={size}", str(folder)], check=True)

    try:
        yield folder, resize
    finally:
        subprocess.run(["umount", "-l", str(folder)], check=False)


def test_a_full_disk_mid_session_then_resume(small_disk, monkeypatch, capfd) -> None:
    folder, resize = small_disk
    root = folder / "results"
    # the estimate (tens of MB) would refuse this disk up front: let the session start
    monkeypatch.setattr(session_module, "check_space", lambda folder, estimate: {})
    s = make_session(root, monkeypatch, limit=12)
    with pytest.raises(FovexpError) as err:
        run(s, 120)
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith("the results disk is full")
    assert "MB free of 0.4 MB" in msg
    assert f"fovexp run {s.protocol.path} --participant D01 --results {root} --resume" in msg
    printed = capfd.readouterr().err
    assert "Traceback" not in printed and "Exception in thread" not in printed, printed
    part = root / "calibration-fe" / "D01"
    rows, _ = read_trials(part / "trials.csv")  # whole: no torn row to drop
    assert 0 < len(rows) < 12
    info = json.loads((part / f"session-{s.session_id}.json").read_text())  # valid JSON
    assert info["completed"] is False
    assert not list(part.glob("*.tmp"))
    for log in part.glob("*.csv"):
        assert log.read_bytes().endswith(b"\n"), log  # every log cut back to a whole row
    done_before = [r["trial_index"] for r in rows]
    # free space, then --resume: the session finishes, no trial twice
    resize("50m")
    s2 = make_session(root, monkeypatch, resume=True, limit=12)
    assert s2.session_id == s.session_id
    assert run(s2, 120) == 0
    rows, _ = read_trials(part / "trials.csv")
    indices = [r["trial_index"] for r in rows]
    assert sorted(indices) == list(range(12)) and indices[:len(done_before)] == done_before
    frames = read_frame_log(part / f"frames-{s.session_id}.csv")
    assert set(frames["trial_index"]) == set(range(12))
    info = json.loads((part / f"session-{s.session_id}.json").read_text())
    assert info["completed"] is True


def test_the_message_names_what_to_do(tmp_path: Path) -> None:
    msg = disk_full_message(tmp_path, "fovexp run p.yaml --participant P01 --resume")
    assert msg.startswith("the results disk is full (") and "MB free of" in msg
    assert msg.endswith("fovexp run p.yaml --participant P01 --resume") and "\n" not in msg
