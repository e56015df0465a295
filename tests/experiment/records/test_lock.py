"""One run at a time in a participant's folder (:mod:`fovexp.experiment.records.lock`), without a
window: a second holder is refused while the first holds it (another process, through the operating
system's lock), and folders a run created and wrote nothing to are removed again."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from fovexp import FovexpError
from fovexp.experiment.records.lock import LOCK_FILE, FolderLock


def test_created_folders_are_removed_when_nothing_was_written(tmp_path: Path) -> None:
    folder = tmp_path / "results" / "calibration-fe" / "P01"
    lock = FolderLock(folder, "participant P01, calibration-fe", tmp_path / "results")
    assert lock.held and (folder / LOCK_FILE).exists()
    lock.release()
    lock.release()  # a second release does nothing
    assert not lock.held and not (tmp_path / "results").exists() and tmp_path.exists()


def test_a_folder_with_logs_is_kept(tmp_path: Path) -> None:
    folder = tmp_path / "P01"
    lock = FolderLock(folder, "P01", tmp_path)
    (folder / "trials.csv").write_text("x\n")
    lock.release()
    assert (folder / "trials.csv").exists()


def test_another_process_holding_it_is_refused(tmp_path: Path) -> None:
    """The lock is the operating system's: held by another process, refused here with the
    folder and its owner named; free again once that process is gone."""
    folder = tmp_path / "P01"
    folder.mkdir()
    code = textwrap.dedent(f"""
        import sys, time
        from filelock import FileLock
        lock = FileLock({str(folder / LOCK_FILE)!r})
        lock.acquire()
        print("held", flush=True)
        sys.stdin.readline()
    """)
    proc = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "held"
        with pytest.raises(FovexpError, match=r"P01 is in use by another fovexp run "
                                              r"\(participant P01, validation\)"):
            FolderLock(folder, "participant P01, validation", tmp_path)
    finally:
        proc.communicate("\n", timeout=10)
    lock = FolderLock(folder, "participant P01, validation", tmp_path)
    lock.release()
    assert folder.exists()  # it was there before: not this run's to remove


def test_an_uncreatable_folder_is_one_line(tmp_path: Path) -> None:
    (tmp_path / "file").write_text("")
    with pytest.raises(FovexpError, match=r"--results .*: cannot create .*file/P01"):
        FolderLock(tmp_path / "file" / "P01", "P01", tmp_path)
