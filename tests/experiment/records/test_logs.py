"""The crash-safe logs (:mod:`fovexp.experiment.records.logs`): round trips, torn tails,
one trials format for the runner and the analysis, older formats upgraded, synced flushes."""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest

from fovexp import FovexpError
from fovexp.experiment.records.logs import TRIAL_COLUMNS, BatchLog, TrialLog, read_trials

# -- logs ------------------------------------------------------------------------------------

def row(i: int, session: str = "20260101-000000") -> dict:
    r = dict.fromkeys(TRIAL_COLUMNS)
    r.update(participant="P01", session=session, experiment="calibration-fe",
             protocol_sha256="ab" * 32, trial_index=i, practice=i == 0, repetition=0,
             image="scene-00", blur_rate=0.34, method="contrast", adjusted_parameter="f_e",
             f_e=0.1 * i, start_value=0.2, final_value=0.1 * i, response_time_s=1.5,
             wheel_events=4, blanked_fraction=0.0, dropped_frames=0, tracker="simulated",
             seed=1, software_version="0.1.0", timestamp="2026-01-01T00:00:00+00:00")
    return r


def test_trial_log_round_trip_and_torn_tail(tmp_path: Path) -> None:
    path = tmp_path / "trials.csv"
    log = TrialLog(path)
    for i in range(3):
        log.append(row(i))
    rows, n = read_trials(path)
    assert [r["trial_index"] for r in rows] == [0, 1, 2] and n == path.stat().st_size
    assert rows[0]["practice"] is True and rows[1]["s_k"] is None
    assert rows[2]["final_value"] == pytest.approx(0.2)
    # Every cut of the last row's bytes reads as the first two rows (torn row dropped).
    full = path.read_bytes()
    last_start = full.rfind(b"\n", 0, len(full) - 1) + 1
    for cut in range(last_start + 1, len(full)):
        path.write_bytes(full[:cut])
        with warnings.catch_warnings(record=True) as w:
            warnings.simplefilter("always")
            rows, n = read_trials(path)
        assert [r["trial_index"] for r in rows] == [0, 1], cut
        assert n == last_start and any("torn" in str(x.message) for x in w)
    # Reopening cuts the torn tail off, so the next row starts on a fresh line.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        log = TrialLog(path)
    log.append(row(2))
    rows, _ = read_trials(path)
    assert [r["trial_index"] for r in rows] == [0, 1, 2]
    assert (tmp_path / "trials.csv.torn").exists()


def test_corrupt_middle_row_is_an_error(tmp_path: Path) -> None:
    path = tmp_path / "trials.csv"
    log = TrialLog(path)
    for i in range(3):
        log.append(row(i))
    lines = path.read_text().splitlines(keepends=True)
    lines[2] = lines[2].replace(",contrast,", ",contrast,extra,")
    path.write_text("".join(lines))
    with pytest.raises(FovexpError, match="line 3: 25 fields, expected 24"):
        read_trials(path)


def test_one_trials_format_for_runner_and_analysis(tmp_path: Path) -> None:
    """The runner and the analysis read trials.csv with the same definition (logformat)."""
    from fovexp.results import format as logformat
    from fovexp.results.loading import COLUMNS, read_trials_file

    assert COLUMNS is logformat.TRIAL_COLUMNS is TRIAL_COLUMNS
    path = tmp_path / "P01" / "trials.csv"
    log = TrialLog(path)
    for i in range(3):
        log.append(row(i))
    with open(path, "ab") as fh:
        fh.write(b"P01,20260101-000000,calibration-fe,ab")  # torn by a kill
    with pytest.warns(UserWarning, match="line 5: torn last row"):
        runner_rows, _ = read_trials(path)
    with pytest.warns(UserWarning, match="line 5: torn last row"):
        frame, excl = read_trials_file(path)
    assert [r["trial_index"] for r in runner_rows] == list(frame["trial_index"]) == [0, 1, 2]
    assert [e.rule for e in excl] == ["R1 torn last row"]


def test_batch_log(tmp_path: Path) -> None:
    path = tmp_path / "gaze.csv"
    log = BatchLog(path, ["a", "b"])
    log.extend([(1, 0.5), (2, None)])
    assert log.flush(sync=True) == 2
    with open(path, "a") as fh:
        fh.write("3,0.")  # torn by a kill
    BatchLog(path, ["a", "b"]).flush()
    assert path.read_text() == "a,b\n1,0.5\n2,\n"


def test_a_resumed_log_of_an_older_format_is_upgraded(tmp_path: Path) -> None:
    """A frame log of version 1 (docs/LOGS.md, "Format versions") reopened by a newer runner:
    its header becomes the current one and its rows get the new column empty, so the rows
    appended after it line up; the reader sees the old rows with the column empty. A file
    whose columns are not an older version's is refused, naming it."""
    from fovexp.results.format import FRAME_COLUMNS, FRAME_LOG_VERSIONS
    from fovexp.results.frames import read_frame_log

    path = tmp_path / "frames-s.csv"
    v1 = FRAME_LOG_VERSIONS[1]
    path.write_text(",".join(v1) + "\n0,0,0,1.0,,0,0,0.2,990000,0.3,1000000\n0,0,1,1.0")
    log = BatchLog(path, FRAME_COLUMNS)
    log.add((0, 0, 1, 1.008, 0.008, 0, 0, 0.2, 999000, 0.3, 1008000, 1007000, 990000))
    log.flush(sync=True)
    frames = read_frame_log(path)
    assert path.read_text().splitlines()[0] == ",".join(FRAME_COLUMNS)
    assert list(frames["frame"]) == [0, 1]  # the torn row cut, then the new one
    assert frames["decide_system_time_us"].isna().tolist() == [True, False]
    assert path.with_name(path.name + ".torn").read_text() == "0,0,1,1.0\n"
    other = tmp_path / "other.csv"
    other.write_text("x,y\n1,2\n")
    with pytest.raises(FovexpError, match="other.csv: its columns are not those"):
        BatchLog(other, FRAME_COLUMNS)


def test_synced_flush_waits_for_a_flush_under_way(tmp_path: Path,
                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """The periodic flusher has taken rows 1 and is writing them when the trial ends: the trial's
    synced flush of rows 2 must not return before rows 1 are on disk, nor write 2 before 1."""
    import threading

    from fovexp.experiment.records import logs

    started, release = threading.Event(), threading.Event()
    real = logs.format_line

    def slow(row):  # the first batch stalls in the middle of its write
        if row == (1, 1):
            started.set()
            assert release.wait(5)
        return real(row)

    monkeypatch.setattr(logs, "format_line", slow)
    path = tmp_path / "gaze.csv"
    log = BatchLog(path, ["a", "b"])
    log.add((1, 1))
    background = threading.Thread(target=log.flush)
    background.start()
    assert started.wait(5)
    log.add((2, 2))
    synced = threading.Thread(target=log.flush, kwargs={"sync": True})
    synced.start()
    # waits for the write under way: it cannot return before release.set(), however slow the
    # machine (0.3 s is only how long a flush that does not wait has to show it)
    synced.join(0.3)
    assert synced.is_alive()
    release.set()
    background.join(5)
    synced.join(5)
    assert path.read_text() == "a,b\n1,1\n2,2\n"
