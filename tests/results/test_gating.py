"""The blanking against the eye, from the logs alone (:mod:`fovexp.results.gating`), on
synthetic gaze and frame logs whose answers are known to the microsecond."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from fovexp import FovexpError
from fovexp.results.blanking import BlankingRule
from fovexp.results.format import FRAME_COLUMNS, GAZE_COLUMNS, format_line
from fovexp.results.frames import read_frame_log
from fovexp.results.gating import (
    delivery_latency_ms,
    excursion_exposure,
    read_gaze_log,
    session_gating,
    stamped_violations,
    stimulus_outside,
    tracker_cost_frames,
)

RULE = BlankingRule(1.25, 0.05)
T0 = 1_000_000  # us


def gaze_log(path: Path, rows: list[dict]) -> pd.DataFrame:
    """A gaze log with samples every ``dt`` us: ``ecc`` (None: invalid), ``lat`` (us) and the
    eye's truth ``true``."""
    lines = [",".join(GAZE_COLUMNS)]
    for r in rows:
        valid = r["ecc"] is not None
        row = dict.fromkeys(GAZE_COLUMNS)
        row.update(trial_index=r.get("trial", 0), attempt=0, device_time_us=r["t"] - T0,
                   system_time_us=r["t"], left_valid=valid, right_valid=valid, valid=valid,
                   eccentricity_deg=r["ecc"], received_system_time_us=r["t"] + r.get("lat", 0),
                   true_ecc_deg=r.get("true"))
        lines.append(format_line([row[c] for c in GAZE_COLUMNS]).rstrip("\n"))
    path.write_text("\n".join(lines) + "\n")
    return read_gaze_log(path)


def frame_log(path: Path, rows: list[tuple[int, int, int]]) -> pd.DataFrame:
    """Frames as (decide_us, flip_us, blanked), one attempt of trial 0."""
    lines = [",".join(FRAME_COLUMNS)]
    for i, (d, f, b) in enumerate(rows):
        row = dict.fromkeys(FRAME_COLUMNS)
        row.update(trial_index=0, attempt=0, frame=i, flip_time_s=f / 1e6, dropped=0, blanked=b,
                   value=0.1, gaze_system_time_us=d - 100, gaze_ecc_deg=0.1,
                   flip_system_time_us=f, decide_system_time_us=d)
        lines.append(format_line([row[c] for c in FRAME_COLUMNS]).rstrip("\n"))
    path.write_text("\n".join(lines) + "\n")
    return read_frame_log(path)


def test_latency_and_the_trackers_cost(tmp_path: Path) -> None:
    """The eye is measured outside from 4 ms on; each sample reaches the runner 3 ms later.
    The frame decided at 5.5 ms had only the samples up to 2 ms, inside: it shows the
    stimulus. The latency let it through (1 frame: samples measured, not received, outside),
    and the newest sample measured by then (5 ms) says so. With instant delivery the same
    logged frame is a plain violation: no tracker's cost, still flagged."""
    samples = [{"t": T0 + k * 1000, "ecc": 3.0 if 4 <= k <= 6 else 0.2, "lat": 3000}
               for k in range(12)]
    frames = frame_log(tmp_path / "f.csv", [(T0 + 5500, T0 + 8000, 0),
                                            (T0 + 11_000, T0 + 14_000, 1)])
    g = gaze_log(tmp_path / "g.csv", samples)
    assert delivery_latency_ms(g) == pytest.approx(np.full(12, 3.0))
    assert tracker_cost_frames(frames, g, RULE) == 1
    assert stamped_violations(frames, g, RULE) == 1
    instant = gaze_log(tmp_path / "g0.csv", [{**s, "lat": 0} for s in samples])
    assert tracker_cost_frames(frames, instant, RULE) == 0
    assert stamped_violations(frames, instant, RULE) == 1
    inside = gaze_log(tmp_path / "g1.csv", [{**s, "ecc": 0.2} for s in samples])
    assert tracker_cost_frames(frames, inside, RULE) == 0
    assert stamped_violations(frames, inside, RULE) == 0


def test_an_invalid_or_old_sample_counts(tmp_path: Path) -> None:
    samples = [{"t": T0, "ecc": 0.2}, {"t": T0 + 1000, "ecc": None}]
    g = gaze_log(tmp_path / "g.csv", samples)
    frames = frame_log(tmp_path / "f.csv", [(T0 + 500, T0 + 600, 0),      # on sample 0: fine
                                            (T0 + 1500, T0 + 1600, 0),    # invalid: flagged
                                            (T0 + 49_000, T0 + 49_500, 0)])  # invalid still
    assert stamped_violations(frames, g, RULE) == 2
    old = gaze_log(tmp_path / "g2.csv", [{"t": T0, "ecc": 0.2}])
    f2 = frame_log(tmp_path / "f2.csv", [(T0 + 50_000, T0 + 50_100, 0),  # exactly the timeout
                                         (T0 + 50_001, T0 + 50_200, 0)])  # 1 us older
    assert stamped_violations(f2, old, RULE) == 1


def test_the_stimulus_time_outside_against_the_truth(tmp_path: Path) -> None:
    """The true eye is outside from 10 to 30 ms (samples every ms); stimulus frames flip at 0,
    8, 16, 24 and 32 ms, the one at 16 ms blanked: outside while shown = 10-16 and 24-30 ms,
    12 ms of 32 ms of stimulus; one excursion, exposed 12 ms."""
    samples = [{"t": T0 + k * 1000, "ecc": 0.2, "true": 2.0 if 10 <= k < 30 else 0.3}
               for k in range(50)]
    g = gaze_log(tmp_path / "g.csv", samples)
    flips = [0, 8, 16, 24, 32]
    frames = frame_log(tmp_path / "f.csv", [(T0 + f * 1000 - 500, T0 + f * 1000,
                                             int(f == 16)) for f in flips])
    per = stimulus_outside(frames, g, RULE)
    assert len(per) == 1
    # the last frame lasts the median interval (8 ms): 0-16 and 24-40 ms of stimulus
    assert per["stimulus_ms"].iloc[0] == pytest.approx(32.0)
    assert per["outside_ms"].iloc[0] == pytest.approx(12.0)
    assert per["outside_fraction"].iloc[0] == pytest.approx(12 / 32)
    assert excursion_exposure(frames, g, RULE) == pytest.approx([12.0])
    fig = session_gating(frames, g, RULE)
    assert fig["outside_ms"] == pytest.approx(12.0) and fig["excursion_max_ms"] == 12.0
    # a real eye: no truth, no such figures
    real = gaze_log(tmp_path / "r.csv", [{**s, "true": None} for s in samples])
    assert stimulus_outside(frames, real, RULE).empty
    assert np.isnan(session_gating(frames, real, RULE)["outside_ms"])


def test_an_older_gaze_log_reads_with_the_new_columns_empty(tmp_path: Path) -> None:
    old = GAZE_COLUMNS[: GAZE_COLUMNS.index("received_system_time_us")]
    p = tmp_path / "gaze.csv"
    p.write_text(",".join(old) + "\n" + ",".join(["0", "0", "5", "7"] + [""] * (len(old) - 4))
                 + "\n")
    g = read_gaze_log(p)
    assert g["received_system_time_us"].isna().all() and delivery_latency_ms(g).size == 0
    p.write_text("a,b\n1,2\n")
    with pytest.raises(FovexpError, match="not a gaze log"):
        read_gaze_log(p)
