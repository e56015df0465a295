"""The frame log's checkers (:mod:`fovexp.results.frames`) on synthetic logs with known answers:
the blanking rule (no frame drawn with the stimulus without a recent valid sample within
1.25 deg) and the ``final_value`` rule (the last frame before Enter shows the logged answer).
Each is shown to pass a log that keeps the rule and to name every kind of break of it."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
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


def test_reading_a_log_torn_unreadable_or_not_csv(tmp_path: Path) -> None:
    """A kill mid-write leaves a partial last line: dropped (complete lines are kept, the last
    one included); an unreadable path or bytes that are no CSV: one error naming the file."""
    path = tmp_path / "f.csv"
    write(path, GOOD)
    whole = path.read_bytes().replace(b"\r\n", b"\n")  # the runner's line ends
    path.write_bytes(whole + b"1,0,3,20.02")  # torn
    torn = read_frame_log(path)
    assert len(torn) == len(GOOD) and torn["frame"].iloc[-1] == 2
    last = GOOD[-1]  # every field of the last complete line kept, to its last character
    assert torn["flip_system_time_us"].iloc[-1] == last["flip_system_time_us"]
    assert torn["value"].iloc[-1] == last["value"]
    path.write_bytes(whole)
    pd.testing.assert_frame_equal(torn, read_frame_log(path))
    with pytest.raises(FovexpError, match=r"f.csv: not a frame log"):
        path.write_bytes(b'trial_index,attempt,frame,blanked\n"1,2\n')
        read_frame_log(path)
    with pytest.raises(FovexpError, match="cannot read"):
        read_frame_log(tmp_path)  # a folder
    old = tmp_path / "old.csv"  # a log written before the gaze columns existed
    old.write_text("trial_index,attempt,frame,blanked\n0,0,0,1\n")
    got = read_frame_log(old)
    assert got["gaze_ecc_deg"].isna().all() and str(got["frame"].dtype) == "Int64"


def test_latency_summary_and_trial_quality_by_hand(tmp_path: Path) -> None:
    """Latencies 1..20 ms over 20 frames of trial 0 (one frame without a sample, two dropped):
    median, 95th percentile (linear, NumPy's default), maximum; per trial of its last attempt;
    NaN where no frame had a sample, and for no frames at all."""
    from fovexp.results.frames import trial_quality

    rows = [frame(0, n, 10.0 + n * PERIOD_S, 0.0, age_s=(n + 1) / 1000) for n in range(20)]
    rows.append(frame(0, 20, 10.0 + 20 * PERIOD_S, 0.0, ecc=None, age_s=None))
    rows[3]["dropped"] = rows[7]["dropped"] = 1
    rows[9]["dropped"] = rows[10]["dropped"] = ""  # not recorded: not counted as dropped
    rows += [frame(1, n, 30.0 + n * PERIOD_S, 0.0, ecc=None, age_s=None, attempt=1)
             for n in range(4)]
    rows += [frame(1, n, 20.0 + n * PERIOD_S, 0.0, age_s=0.5, attempt=0) for n in range(3)]
    frames = write(tmp_path / "f.csv", rows)
    lat = [n + 1.0 for n in range(20)]
    s = latency_summary(frames[frames["trial_index"] == 0])
    assert (s["frames"], s["with_gaze"]) == (21, 20)
    assert s["median_ms"] == pytest.approx(10.5) and s["max_ms"] == pytest.approx(20.0)
    assert s["p95_ms"] == pytest.approx(19.05)  # 1 + 0.95 * 19
    assert s["dropped_fraction"] == pytest.approx(2 / 21)
    empty = latency_summary(frames.iloc[:0])
    assert empty["frames"] == 0 and all(np.isnan(empty[k]) for k in
                                        ("median_ms", "p95_ms", "max_ms", "dropped_fraction"))
    q = trial_quality(frames).set_index("trial_index")
    assert q.loc[0, "frames"] == 21 and q.loc[0, "dropped_fraction"] == pytest.approx(2 / 21)
    assert q.loc[0, "latency_p95_ms"] == pytest.approx(np.percentile(lat, 95))
    assert q.loc[1, "frames"] == 4 and np.isnan(q.loc[1, "latency_p95_ms"])  # attempt 1 only
    assert q.loc[1, "dropped_fraction"] == 0.0
    assert list(trial_quality(frames.iloc[:0]).columns) == [
        "trial_index", "frames", "dropped_fraction", "latency_p95_ms"]


def test_the_blanking_rule_reads_the_previous_flip_and_a_missing_flag(tmp_path: Path) -> None:
    """'Recent' is measured from the previous flip of the same attempt (not the one before
    it): a sample exactly the timeout (2 s here) older than the previous flip keeps the rule,
    one a microsecond older breaks it; a frame whose blanked flag is missing counts as
    shown."""
    base = [frame(0, n, 10.0 + n * 0.02, 0.0) for n in range(3)]
    edge = [dict(r) for r in base]
    edge[2]["gaze_system_time_us"] = edge[1]["flip_system_time_us"] - 2_000_000  # just recent
    frames = write(tmp_path / "a.csv", edge)
    assert unblanked_violations(frames, RADIUS_DEG, 2.0, 0.0).empty
    edge[2]["gaze_system_time_us"] -= 1  # 1 us too old
    frames = write(tmp_path / "b.csv", edge)
    assert unblanked_violations(frames, RADIUS_DEG, 2.0, 0.0)["frame"].tolist() == [2]
    unflagged = [dict(r) for r in base]
    unflagged[1]["blanked"] = ""
    unflagged[1]["gaze_ecc_deg"] = 2.0
    frames = write(tmp_path / "c.csv", unflagged)
    assert unblanked_violations(frames, RADIUS_DEG, TIMEOUT_S, 0.0)["frame"].tolist() == [1]


def test_final_value_at_the_edges_of_enter(tmp_path: Path) -> None:
    """A frame flipped exactly at Enter (+ the slack) is before it; one later is after; the
    logged values must match to value_tol; a trial row without frames does not stop the
    others being checked; the first frame named as shown."""
    rows = trial(0, 10.0, [0.0, 0.0, 0.02])
    enter = 2 * PERIOD_S  # the last frame's flip, exactly
    log = [{"trial_index": 7, "start_value": 0, "final_value": 0, "response_time_s": 1},
           {"trial_index": 0, "start_value": 0.0, "final_value": 0.02, "response_time_s": enter}]
    bad = final_value_violations(write(tmp_path / "f.csv", rows), log)
    assert bad["problem"].tolist() == ["no frames"]
    wrong = [log[0], dict(log[1], start_value=0.5)]  # checked after a trial without frames
    assert final_value_violations(write(tmp_path / "f.csv", rows), wrong)["problem"].tolist() == [
        "no frames", "first frame shows 0, start_value is 0.5"]
    # the tolerance itself is within it: values 0.5 apart with value_tol = 0.5 (exact binary)
    halves = trial(0, 10.0, [0.25, 0.25, 0.25])
    ok = [{"trial_index": 0, "start_value": 0.75, "final_value": 0.75, "response_time_s": enter}]
    assert final_value_violations(write(tmp_path / "h.csv", halves), ok, value_tol=0.5).empty
    assert len(final_value_violations(write(tmp_path / "h.csv", halves), ok,
                                      value_tol=0.4999)) == 2
    log[1]["final_value"] = 0.02 + 1e-9  # within value_tol = 1e-9 of the frame's
    assert final_value_violations(write(tmp_path / "f.csv", rows), log[1:]).empty
    log[1]["response_time_s"] = enter - 2e-4  # the last frame now after Enter
    bad = final_value_violations(write(tmp_path / "f.csv", rows), log[1:])
    assert bad["problem"].tolist() == ["1 frame(s) flipped after Enter",
                                       "the last frame before Enter shows 0, final_value is 0.02"]
    rows = trial(0, 10.0, [0.5, 0.0, 0.02])
    log[1]["response_time_s"] = enter
    bad = final_value_violations(write(tmp_path / "f.csv", rows), log[1:])
    assert bad["problem"].tolist() == ["first frame shows 0.5, start_value is 0"]


def test_a_frame_flipped_exactly_at_enter_plus_the_slack_is_before_it(tmp_path: Path) -> None:
    from fovexp.results.frames import ENTER_SLACK_S

    rows = trial(0, 10.0, [0.0, 0.0, 0.02])
    frames = write(tmp_path / "f.csv", rows)
    t = frames["flip_time_s"].to_numpy(float)
    r = (t[2] - ENTER_SLACK_S) - t[0]
    for _ in range(8):  # the response time whose Enter + slack lands on the flip exactly
        if t[0] + r + ENTER_SLACK_S == t[2]:
            break
        r = np.nextafter(r, np.inf if t[0] + r + ENTER_SLACK_S < t[2] else -np.inf)
    assert t[0] + r + ENTER_SLACK_S == t[2]
    log = [{"trial_index": 0, "start_value": 0.0, "final_value": 0.02, "response_time_s": r}]
    assert final_value_violations(frames, log).empty
