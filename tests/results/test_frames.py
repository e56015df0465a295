"""The frame log's checkers (:mod:`fovexp.results.frames`) on synthetic logs with known answers:
the blanking rule (no frame drawn with the stimulus without a recent valid sample within
1.25 deg) and the ``final_value`` rule (the last frame before Enter shows the logged answer).
Each is shown to pass a log that keeps the rule and to name every kind of break of it."""

from __future__ import annotations

import csv
from pathlib import Path

import pandas as pd
import pytest

from fovexp import FovexpError
from fovexp.results.format import FRAME_COLUMNS
from fovexp.results.frames import (
    final_value_violations,
    latency_summary,
    read_frame_log,
    unblanked_violations,
)

PERIOD_S = 1 / 120
RADIUS_DEG, TIMEOUT_S = 1.25, 0.05


def frame(i: int, frame_no: int, t_s: float, value: float, blanked: int = 0,
          ecc: float | None = 0.3, age_s: float = 0.004, attempt: int = 0) -> dict:
    """A frame flipped at ``t_s``, decided by a sample ``age_s`` older than its flip."""
    flip_us = round(t_s * 1e6)
    return {"trial_index": i, "attempt": attempt, "frame": frame_no, "flip_time_s": t_s,
            "interval_s": PERIOD_S if frame_no else "", "dropped": 0, "blanked": blanked,
            "value": value, "gaze_system_time_us": "" if ecc is None and age_s is None
            else flip_us - round(age_s * 1e6), "gaze_ecc_deg": "" if ecc is None else ecc,
            "flip_system_time_us": flip_us}


def write(path: Path, rows: list[dict]) -> pd.DataFrame:
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, FRAME_COLUMNS)
        w.writeheader()
        w.writerows(rows)
    return read_frame_log(path)


def trial(i: int, t0: float, values: list[float], **kw) -> list[dict]:
    return [frame(i, n, t0 + n * PERIOD_S, v, **kw) for n, v in enumerate(values)]


GOOD = trial(0, 10.0, [0.0, 0.0, 0.02, 0.02, 0.04]) + trial(1, 20.0, [0.1, 0.12, 0.12])
ROWS = [{"trial_index": 0, "start_value": 0.0, "final_value": 0.04,
         "response_time_s": round(4 * PERIOD_S + 0.003, 4)},
        {"trial_index": 1, "start_value": 0.1, "final_value": 0.12,
         "response_time_s": round(2 * PERIOD_S + 0.005, 4)}]


def test_a_log_that_keeps_the_rules(tmp_path: Path) -> None:
    frames = write(tmp_path / "f.csv", GOOD)
    assert unblanked_violations(frames, RADIUS_DEG, TIMEOUT_S, 2 * PERIOD_S).empty
    assert final_value_violations(frames, ROWS).empty
    assert latency_summary(frames)["median_ms"] == pytest.approx(4.0)


@pytest.mark.parametrize("change, expected", [
    ({"ecc": 1.3}, "outside"),                # a valid sample beyond 1.25 deg
    ({"ecc": None}, "invalid"),               # no valid sample (no eccentricity)
    ({"ecc": None, "age_s": None}, "none"),   # no sample at all
    ({"age_s": 0.07}, "old"),                 # older than the previous flip minus 50 ms
])
def test_unblanked_frames_that_break_the_rule(tmp_path: Path, change: dict,
                                              expected: str) -> None:
    rows = [dict(r) for r in GOOD]
    rows[2] = frame(0, 2, 10.0 + 2 * PERIOD_S, 0.02, **change)
    frames = write(tmp_path / "f.csv", rows)
    bad = unblanked_violations(frames, RADIUS_DEG, TIMEOUT_S, 2 * PERIOD_S)
    assert list(zip(bad["trial_index"], bad["frame"], strict=True)) == [(0, 2)], expected
    # the same frame blanked keeps the rule
    rows[2] = frame(0, 2, 10.0 + 2 * PERIOD_S, 0.02, blanked=1, **change)
    assert unblanked_violations(write(tmp_path / "g.csv", rows), RADIUS_DEG, TIMEOUT_S,
                                2 * PERIOD_S).empty


def test_the_first_frame_of_an_attempt_gets_the_slack(tmp_path: Path) -> None:
    """No previous flip: its sample may be the timeout plus the slack older than its flip."""
    ok = write(tmp_path / "a.csv", [frame(0, 0, 10.0, 0.0, age_s=0.06)])
    assert unblanked_violations(ok, RADIUS_DEG, TIMEOUT_S, 2 * PERIOD_S).empty
    old = write(tmp_path / "b.csv", [frame(0, 0, 10.0, 0.0, age_s=0.07)])
    assert len(unblanked_violations(old, RADIUS_DEG, TIMEOUT_S, 2 * PERIOD_S)) == 1


@pytest.mark.parametrize("doctor, problem", [
    (lambda rows, log: log[0].update(final_value=0.02), "the last frame before Enter shows"),
    (lambda rows, log: rows.__setitem__(4, {**rows[4], "value": 0.06}),
     "the last frame before Enter shows 0.06"),
    (lambda rows, log: rows.insert(5, frame(0, 5, 10.0 + 5 * PERIOD_S, 0.04)),
     "1 frame(s) flipped after Enter"),
    (lambda rows, log: log[0].update(start_value=0.2), "first frame shows 0"),
    (lambda rows, log: log.append({"trial_index": 5, "start_value": 0, "final_value": 0,
                                   "response_time_s": 1}), "no frames"),
])
def test_final_value_violations(tmp_path: Path, doctor, problem: str) -> None:
    rows, log = [dict(r) for r in GOOD], [dict(r) for r in ROWS]
    doctor(rows, log)
    bad = final_value_violations(write(tmp_path / "f.csv", rows), log)
    assert len(bad) == 1 and bad["problem"].iloc[0].startswith(problem), bad.to_string()


def test_final_value_uses_the_confirmed_attempt(tmp_path: Path) -> None:
    """An attempt paused and restarted: the rule holds on the last one, whatever the first
    showed."""
    rows = trial(0, 5.0, [0.0, 0.3, 0.3]) + trial(0, 10.0, [0.0, 0.0, 0.02, 0.02, 0.04],
                                                  attempt=1)
    frames = write(tmp_path / "f.csv", rows)
    assert final_value_violations(frames, ROWS[:1]).empty
    assert not final_value_violations(frames[frames["attempt"] == 0], ROWS[:1]).empty


def test_a_file_that_is_not_a_frame_log(tmp_path: Path) -> None:
    (tmp_path / "x.csv").write_text("a,b\n1,2\n")
    with pytest.raises(FovexpError, match="not a frame log"):
        read_frame_log(tmp_path / "x.csv")
