"""Gaze-to-flip latency per session and the blanking rule, read from frame logs through
``fovexp.results.frames`` (issues 9 and 18): exact figures on logs written here with known
latencies, each kind of rule violation caught exactly at the decision, and the report's
section."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from fovexp.analysis.latency import session_latency
from fovexp.analysis.report import run_analysis
from fovexp.results import load_results
from fovexp.results.blanking import BlankingRule
from fovexp.results.format import FRAME_COLUMNS, format_value
from fovexp.results.frames import (
    draw_latency_ms,
    gaze_to_flip_ms,
    latency_summary,
    read_frame_log,
    unblanked_violations,
)

from analysis_fixtures import write_study

PERIOD_US = 8333  # 120 Hz
DRAW_US = 1500  # each frame decided this long before its flip


def frame_rows(trial: int, latencies_ms: list[float], t0_us: int = 10_000_000,
               attempt: int = 0, ecc: float = 0.3, blanked: int = 0) -> list[list]:
    """Frames of one attempt, one per refresh period, each decided by a sample
    ``latency`` ms before its flip, :data:`DRAW_US` before the flip."""
    rows = []
    for k, lat in enumerate(latencies_ms):
        flip = t0_us + k * PERIOD_US
        rows.append([trial, attempt, k, flip / 1e6, None if k == 0 else PERIOD_US / 1e6, 0,
                     blanked, 0.2, flip - round(1e3 * lat), ecc, flip, flip - DRAW_US,
                     t0_us - PERIOD_US])
    return rows


def write_frames(path: Path, rows: list[list], torn: str = "") -> Path:
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(FRAME_COLUMNS)
        for r in rows:
            w.writerow([format_value(v) for v in r])
        fh.write(torn)
    return path


def test_latency_summary_is_exact(tmp_path: Path) -> None:
    lat = list(np.linspace(2.0, 21.8, 100))  # 2.0, 2.2, ..., 21.8 ms
    path = write_frames(tmp_path / "frames-s.csv", frame_rows(0, lat), torn="0,0,100,10.9")
    frames = read_frame_log(path)  # the torn last line is dropped
    assert len(frames) == 100 and str(frames["gaze_system_time_us"].dtype) == "Int64"
    got = latency_summary(frames)
    assert got["frames"] == got["with_gaze"] == 100
    assert got["median_ms"] == pytest.approx(np.median(lat), abs=1e-3)
    assert got["p95_ms"] == pytest.approx(np.percentile(lat, 95), abs=1e-3)
    assert got["max_ms"] == pytest.approx(21.8, abs=1e-3)
    assert got["draw_median_ms"] == got["draw_p95_ms"] == pytest.approx(DRAW_US / 1e3)


def test_an_older_log_reads_with_empty_latency_columns(tmp_path: Path) -> None:
    path = tmp_path / "frames-old.csv"
    path.write_text("trial_index,attempt,frame,flip_time_s,interval_s,dropped,blanked,value\n"
                    "0,0,0,1.0,,0,0,0.2\n0,0,1,1.016,0.016,0,1,0.2\n")
    frames = read_frame_log(path)
    assert list(frames.columns) == list(FRAME_COLUMNS)
    assert gaze_to_flip_ms(frames).isna().all() and latency_summary(frames)["with_gaze"] == 0
    assert draw_latency_ms(frames).isna().all()


def test_each_breach_of_the_blanking_rule_is_caught() -> None:
    """Stimulus frames whose newest sample is invalid, outside 1.25 deg, or older than the
    gaze timeout when the frame was decided are flagged; the same frames blanked, or a sample
    just within the limits, are not: exactly, the first frame included."""
    rows = frame_rows(0, [5.0] * 8)
    rows[2][9] = None  # invalid (no eccentricity)
    rows[3][9] = 1.26  # outside
    rows[4][9] = 1.25  # on the radius: allowed
    rows[5][8] = rows[5][11] - 50_000  # 50 ms old when decided: allowed
    rows[6][8] = rows[6][11] - 50_001  # 1 us older: not
    frames = pd.DataFrame(rows, columns=FRAME_COLUMNS)
    rule = BlankingRule(1.25, 0.05)
    bad = unblanked_violations(frames, rule)
    assert sorted(bad["frame"]) == [2, 3, 6]
    frames["blanked"] = 1
    assert unblanked_violations(frames, rule).empty
    # an attempt's first frame: the same rule, no slack for its drawing
    first = pd.DataFrame(frame_rows(1, [50.0 + DRAW_US / 1e3]), columns=FRAME_COLUMNS)
    assert unblanked_violations(first, rule).empty
    first.loc[0, "gaze_system_time_us"] -= 1
    assert len(unblanked_violations(first, rule)) == 1


def test_report_has_the_latency_per_session(tmp_path: Path) -> None:
    """Sessions of a study, each with a frame log of known latencies (one with a frame drawn
    outside the radius): the table per session, the figure, and a note for a session without
    a frame log."""
    root = write_study(tmp_path / "results", n_participants=3, seed=4,
                       experiments=("calibration-fe",))
    data = load_results(root)
    sessions = data.trials.groupby(["participant", "session"])["file"].first()
    expect = {}
    for k, ((pid, sid), file) in enumerate(sessions.items()):
        if pid == "P03":
            continue  # no frame log
        lat = [3.0 + k, 5.0 + k, 7.0 + k, 30.0 + k]
        rows = frame_rows(0, lat)
        if pid == "P02":
            rows[1][9] = 1.7  # drawn with the gaze outside the radius
        write_frames(Path(file).parent / f"frames-{sid}.csv", rows)
        info_path = Path(file).parent / f"session-{sid}.json"
        info = json.loads(info_path.read_text())
        info["display_check"] = {"refresh_hz": 120.0}
        info_path.write_text(json.dumps(info))
        expect[pid] = (np.median(lat), np.percentile(lat, 95), max(lat), int(pid == "P02"))
    table, lat_by_session, notes = session_latency(data)
    assert list(table["participant"]) == ["P01", "P02"]
    for _, r in table.iterrows():
        med, p95, mx, bad = expect[r["participant"]]
        assert (r["median_ms"], r["p95_ms"], r["max_ms"]) == (
            pytest.approx(med, abs=1e-3), pytest.approx(p95, abs=1e-3), pytest.approx(mx))
        assert r["rule_violations"] == bad and r["frames"] == 4
    assert len(notes) == 1 and "P03" in notes[0] and "no frame log" in notes[0]
    ana = run_analysis(root, tmp_path / "report")
    text = ana.report.read_text()
    assert "## Gaze-to-flip latency and blanking" in text and "no frame log" in text
    assert (tmp_path / "report" / "tables" / "latency.csv").is_file()
    assert (tmp_path / "report" / "figures" / "latency.png").is_file()
    assert len(lat_by_session) == 2
