"""The live status file's format and reader (fovexp.results.live), the exclusion rules'
predicates the monitor shares with the analysis (TrialLimits), and the lenient reading of a
``trials.csv`` being written."""

from __future__ import annotations

import json
import math
import os
import threading
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from fovexp.results.format import TRIAL_COLUMNS, format_line, read_trials_file
from fovexp.results.limits import R11, R12, R13, TrialLimits
from fovexp.results.live import LIVE_FORMAT, MAX_LIVE_BYTES, live_path, read_live, write_live


def test_round_trip_and_the_name(tmp_path: Path) -> None:
    path = live_path(tmp_path, "20261124-101010")
    assert path.name == "live-20261124-101010.json"
    write_live(path, {"format": LIVE_FORMAT, "state": "trial", "x": [1, 2]})
    got = read_live(path)
    assert got.problem is None and got.data == {"format": LIVE_FORMAT, "state": "trial",
                                                "x": [1, 2]}
    assert got.mtime == pytest.approx(path.stat().st_mtime)
    assert not list(tmp_path.glob(".*tmp"))  # the temporary file was renamed


@pytest.mark.parametrize(("content", "problem"), [
    (b"", "empty"),
    (b'{"format": "fovexp-live/1", "sta', "not JSON"),
    (b"\xff\xfe", "not JSON"),
    (b"[1, 2]", "not a JSON object"),
    (b'{"format": "other/9"}', "format 'other/9'"),
    (b'{"state": "trial"}', "format 'None'"),
])
def test_what_is_not_a_status_file_is_named(tmp_path: Path, content: bytes,
                                            problem: str) -> None:
    path = tmp_path / "live-x.json"
    path.write_bytes(content)
    got = read_live(path)
    assert got.data is None and got.problem is not None and got.problem.startswith(problem)


def test_missing_and_too_large(tmp_path: Path) -> None:
    assert read_live(tmp_path / "none.json").problem == "no status file"
    big = tmp_path / "big.json"
    big.write_bytes(b" " * (MAX_LIVE_BYTES + 1))
    assert "more than a status file's" in (read_live(big).problem or "")


def test_nan_is_refused_when_writing(tmp_path: Path) -> None:
    """JSON has no NaN (a browser's JSON.parse refuses it): the writer says so at once."""
    with pytest.raises(ValueError):
        write_live(tmp_path / "live-x.json", {"format": LIVE_FORMAT, "eta_s": math.nan})


def test_a_reader_never_sees_half_a_write(tmp_path: Path) -> None:
    """Writes replace the file whole: a reader polling meanwhile sees one of them, complete."""
    path = tmp_path / "live-x.json"
    stop = threading.Event()
    seen: list[int] = []
    problems: list[str] = []

    def writer() -> None:
        i = 0
        while not stop.is_set():
            i += 1
            write_live(path, {"format": LIVE_FORMAT, "seq": i, "pad": "x" * (1000 + i % 5000)})

    t = threading.Thread(target=writer)
    t.start()
    t_end = time.monotonic() + 20
    try:
        while len(set(seen)) < 30 and time.monotonic() < t_end:
            got = read_live(path)
            if got.data is not None:
                seen.append(got.data["seq"])
            elif got.problem != "no status file":
                problems.append(got.problem or "")
    finally:
        stop.set()
        t.join()
    assert problems == []
    assert len(set(seen)) >= 30 and seen == sorted(seen)


def test_the_rules_predicates_on_numbers_and_series() -> None:
    lim = TrialLimits(max_blanked_fraction=0.5, max_dropped_fraction=0.05,
                      max_latency_p95_ms=60.0)
    assert lim.exceeded(blanked_fraction=0.5, dropped_fraction=0.05, latency_p95_ms=60.0) == {
        R11: False, R12: False, R13: False}  # at the limit: kept (">" as in the rules' text)
    assert lim.exceeded(blanked_fraction=0.51, dropped_fraction=0.06, latency_p95_ms=61.0) == {
        R11: True, R12: True, R13: True}
    # a figure not known yet breaks nothing
    assert lim.exceeded() == {R11: False, R12: False, R13: False}
    s = pd.Series([0.1, 0.7, np.nan])
    assert lim.blanked_excluded(s).tolist() == [False, True, False]
    assert set(lim.rules()) == {R11, R12, R13}


def _row(i: int, **kw: object) -> dict:
    row = {"participant": "P01", "session": "s1", "experiment": "calibration-fe",
           "protocol_sha256": "ab" * 32, "trial_index": i, "practice": 0, "repetition": 0,
           "image": "scene-00", "blur_rate": 0.34, "method": "contrast",
           "adjusted_parameter": "f_e", "f_e": 0.2, "s_k": None, "s_f": None,
           "start_value": 0.0, "final_value": 0.2, "response_time_s": 3.2, "wheel_events": 5,
           "blanked_fraction": 0.01, "dropped_frames": 0, "tracker": "simulated", "seed": 1,
           "software_version": "0.1", "timestamp": "2026-11-24T10:00:00+00:00"}
    row.update(kw)
    return row


def test_a_lenient_read_skips_bad_rows_anywhere_and_names_them(tmp_path: Path) -> None:
    path = tmp_path / "trials.csv"
    lines = [format_line(TRIAL_COLUMNS)]
    lines += [format_line([_row(i).get(c) for c in TRIAL_COLUMNS]) for i in range(3)]
    lines[2] = lines[2].replace("0.34", "abc", 1)  # a damaged row in the middle
    text = "".join(lines) + format_line([_row(3).get(c) for c in TRIAL_COLUMNS])[:40]  # torn
    path.write_text(text)
    tf = read_trials_file(path, strict=False)
    assert [r["trial_index"] for r in tf.rows] == [0, 2]
    assert [line for line, _ in tf.skipped] == [3, 5]
    assert "blur_rate" in tf.skipped[0][1] and "no final newline" in tf.skipped[1][1]
    # the analysis' strict read still refuses the damaged middle row
    from fovexp import FovexpError

    with pytest.raises(FovexpError, match="line 3"):
        read_trials_file(path)


def test_a_status_file_is_small(tmp_path: Path) -> None:
    """A full window of gaze (300 samples) and 400 attempts stay far below the reader's cap."""
    attempt = {"index": 1, "attempt": 0, "frames": 2000, "latency_ms": {"p95": 12.3},
               "blanked_fraction": 0.01234, "method": "ours", "outcome": "done"}
    data = {"format": LIVE_FORMAT, "attempts": [attempt] * 400,
            "gaze": {"t": [-1.234] * 300, "x_deg": [0.123] * 300, "y_deg": [0.123] * 300}}
    write_live(tmp_path / "l.json", data)
    assert os.path.getsize(tmp_path / "l.json") < MAX_LIVE_BYTES / 10
    assert json.loads((tmp_path / "l.json").read_text()) == data
