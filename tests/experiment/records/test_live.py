"""The live status file a session publishes (fovexp.experiment.records.live): its figures are those
the analysis will compute from the logs (dropped frames and latency per attempt as
fovexp.results.frames.trial_quality reads them, the blanked share as the trial log's), the gaze
is kept as angles from the cross (the blanking rule's exact angle), it is written a few times a
second from its own thread and never stops a session."""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from fovexp import load_display
from fovexp.experiment.options import SessionOptions
from fovexp.experiment.protocol.spec import load_protocol
from fovexp.experiment.records.live import LivePublisher
from fovexp.experiment.session import Session
from fovexp.experiment.tasks.trial import BlankingLog
from fovexp.experiment.trackers.gaze import FixationGeometry, GazeSample
from fovexp.results.format import FRAME_COLUMNS, read_trials_file
from fovexp.results.frames import read_frame_log, trial_quality
from fovexp.results.live import GAZE_MAX_RATE_HZ, GAZE_WINDOW_S, LIVE_FORMAT, read_live

from experiment_helpers import REPO, StubScreen


@pytest.fixture(scope="module")
def fixation() -> FixationGeometry:
    return FixationGeometry(load_display("lg-oled55cx"))


def _publisher(tmp_path: Path, fixation: FixationGeometry, **kw) -> LivePublisher:
    return LivePublisher(tmp_path, "20261124-101010", {"participant": "P01", **kw}, fixation)


def _frames(trial: int, attempt: int, n: int, rng: np.random.Generator, t0: float = 100.0
            ) -> list[tuple]:
    """Frame log rows: 60 Hz with some dropped frames, blank stretches and latencies."""
    rows, t = [], t0
    for i in range(n):
        dt = 1 / 60 * (2 if rng.random() < 0.04 else 1)
        t += dt
        blank = bool(i % 37 < 6)
        gaze_us = None if rng.random() < 0.1 else int(t * 1e6) - int(rng.uniform(5e3, 40e3))
        row = (trial, attempt, i, round(t, 6), None if i == 0 else round(dt, 6),
               dt > 1.5 / 60, blank, 0.2, gaze_us, None if blank else 0.3, int(t * 1e6))
        rows.append(row + (None,) * (len(FRAME_COLUMNS) - len(row)))
    return rows


def test_an_attempts_figures_are_the_analysis_own(tmp_path: Path, fixation) -> None:
    rng = np.random.default_rng(1)
    pub = _publisher(tmp_path, fixation)
    first, second = _frames(3, 0, 200, rng), _frames(3, 1, 500, rng, t0=200.0)
    pub.begin_attempt(3, 0, position=2, total=10, method="ours")
    pub.frames(first)
    pub.end_attempt("pause")
    pub.begin_attempt(3, 1, position=2, total=10, method="ours")
    pub.frames(second)
    snap = pub.snapshot()
    t = snap["trial"]
    assert (t["index"], t["attempt"], t["position"], t["method"]) == (3, 1, 2, "ours")
    # R12 and R13 as the analysis reads them from the frame log (the trial's last attempt)
    frame = pd.DataFrame(first + second, columns=FRAME_COLUMNS).astype(
        {"gaze_system_time_us": "Int64", "flip_system_time_us": "Int64"})
    q = trial_quality(frame).set_index("trial_index").loc[3]
    assert t["frames"] == q["frames"] == 500
    assert t["dropped_fraction"] == pytest.approx(q["dropped_fraction"], abs=1e-5)
    assert t["latency_ms"]["p95"] == pytest.approx(q["latency_p95_ms"], abs=0.01)
    # R11 as the trial log's blanked_fraction: the runner's own BlankingLog over the frames
    log = BlankingLog()
    for r in second:
        log.frame(r[3] - second[0][3], r[6], "")
    assert t["blanked_fraction"] == pytest.approx(log.fraction, abs=1e-5)
    assert 0.1 < t["blanked_fraction"] < 0.2
    # the paused attempt is listed with its outcome
    (a,) = snap["attempts"]
    assert (a["index"], a["attempt"], a["outcome"], a["frames"]) == (3, 0, "pause", 200)
    totals = snap["totals"]
    assert totals["frames"] == 700
    assert totals["dropped"] == sum(r[5] for r in first + second)
    lat = [(r[10] - r[8]) / 1e3 for r in first + second if r[8] is not None]
    assert totals["latency_ms"]["p95"] == pytest.approx(np.percentile(lat, 95), abs=0.25)
    json.dumps(snap, allow_nan=False)  # what write_live writes


def test_gaze_is_kept_as_angles_from_the_cross(tmp_path: Path, fixation) -> None:
    """The last GAZE_WINDOW_S seconds, at most GAZE_MAX_RATE_HZ samples a second; each
    sample's distance from the cross is the blanking rule's exact angle; an invalid sample is
    a gap."""
    pub = _publisher(tmp_path, fixation)
    rate, seconds = 600, 5.0
    items = []
    for i in range(int(rate * seconds)):
        t_us = int(i * 1e6 / rate)
        ang = 2 * math.pi * i / rate  # a circle of 1 deg radius, once a second
        x, y = fixation.offset_to_norm(math.cos(ang), math.sin(ang))
        valid = not (1.0 <= t_us / 1e6 < 1.1) and i != int(rate * seconds) - 200
        items.append((0, 0, GazeSample(t_us, t_us, x, y, valid, x, y, valid)))
    pub.gaze(items[: len(items) // 2])
    pub.snapshot()
    pub.gaze(items[len(items) // 2:])
    g = pub.snapshot()["gaze"]
    t = np.array(g["t"])
    assert t[-1] == 0 and t[0] >= -GAZE_WINDOW_S and t[0] < -GAZE_WINDOW_S + 0.02
    assert len(t) <= GAZE_WINDOW_S * GAZE_MAX_RATE_HZ + 3  # + the gap's edges
    assert np.all(np.diff(t) > 0) and np.median(np.diff(t)) == pytest.approx(0.01, abs=0.002)
    x = np.array([np.nan if v is None else v for v in g["x_deg"]])
    y = np.array([np.nan if v is None else v for v in g["y_deg"]])
    assert np.isnan(x).sum() == 1  # the one invalid sample among the last 3 s
    # each point's distance from the cross is the blanking rule's exact angle, in the
    # on-screen direction (x right, y down)
    for dx, dy in ((1.0, 0.0), (0.0, -2.0), (5.0, 3.0), (-12.0, 7.0)):
        point = fixation.offset_to_norm(dx, dy)
        ((ox, oy),) = pub._offsets_deg([point])
        assert math.hypot(ox, oy) == pytest.approx(fixation.eccentricity(point), rel=1e-12)
        assert math.atan2(oy, ox) == pytest.approx(math.atan2(dy, dx), abs=0.02)
    assert pub._offsets_deg([None, (1.2, 0.5), (0.5, 0.5)]) == [(None, None), (None, None),
                                                               (0.0, 0.0)]
    assert np.nanmax(np.hypot(x, y)) == pytest.approx(1.0, abs=0.03)  # a 1 deg circle
    assert g["samples_last_s"] == len(items)  # both batches arrived within the last second


def test_states_events_and_quality(tmp_path: Path, fixation) -> None:
    pub = _publisher(tmp_path, fixation)
    pub.set_state("message", "Break. 8 trials to go.\n\nPress Space")
    s = pub.snapshot()
    assert (s["state"], s["text"]) == ("message", "Break. 8 trials to go.")
    for state in ("break", "break", "trial", "paused", "paused", "disconnected"):
        pub.set_state(state)
    s = pub.snapshot()
    assert s["totals"]["breaks"] == 1 and s["totals"]["pauses"] == 1
    assert s["tracker"]["connected"] is False and s["totals"]["disconnections"] == 1
    pub.event("tracker_reconnected")
    pub.set_state("trial")
    assert pub.snapshot()["tracker"]["connected"] is True
    pub.tracker_quality([
        {"time": "a", "reason": "start", "validation": {"accuracy_deg": 2.0, "passed": False}},
        {"time": "b", "reason": "start", "accepted": True,
         "validation": {"accuracy_deg": 0.41, "central_accuracy_deg": 0.3, "data_loss": 0.02,
                        "passed": True, "limits": {"max_accuracy_deg": 1.0}}},
        {"time": "c", "reason": "drift", "validation": {"accuracy_deg": 0.9, "passed": True}},
    ])
    q = pub.snapshot()["tracker"]["quality"]
    assert (q["time"], q["accuracy_deg"], q["accepted"]) == ("b", 0.41, True)
    pub.tracker_quality([{"time": "x", "skipped": "mouse gaze is not calibrated"}])
    assert pub.snapshot()["tracker"]["quality"] == {"skipped": "mouse gaze is not calibrated"}
    pub.set_eta(120.0)
    assert 119 <= pub.snapshot()["eta_s"] <= 120


def test_written_by_its_own_thread_and_never_raises(tmp_path: Path, fixation) -> None:
    folder = tmp_path / "P01"
    folder.mkdir()
    pub = _publisher(folder, fixation).start()
    try:
        first = read_live(pub.path)
        assert first.data is not None and first.data["format"] == LIVE_FORMAT
        time.sleep(1.2)
        later = read_live(pub.path).data
        assert later is not None and later["seq"] >= first.data["seq"] + 3  # every 0.25 s
        # the folder gone (a disk unplugged): counted, the session is not stopped
        for p in folder.iterdir():
            p.unlink()
        folder.rmdir()
        time.sleep(0.6)
        assert pub.write_errors >= 1 and "FileNotFoundError" in (pub.last_error or "")
        folder.mkdir()
    finally:
        pub.stop("aborted")
    assert not pub._thread.is_alive()
    assert read_live(pub.path).data["state"] == "aborted"


def test_a_dry_run_publishes_what_its_logs_say(tmp_path: Path) -> None:
    """A whole dry run (simulated gaze and participant, a window-free screen): the status file
    ends with the run's state, one attempt per trial whose frames, dropped frames and latency
    are the frame log's, and blanked share the trial log's; the validation's quality; and it
    was rewritten all along."""
    lp = load_protocol(REPO / "protocols" / "calibration-fe.yaml")
    opts = SessionOptions(participant="L01", results_root=tmp_path / "results",
                          tracker="simulated", dry_run=True, window_size=(480, 270),
                          practice_trials=1, limit_trials=2, fullscreen=False, sim_speed=8.0)
    s = Session(lp, opts)
    assert s.run(screen_factory=lambda **kw: StubScreen(**kw)) == 0
    live = read_live(s.folder / f"live-{s.session_id}.json").data
    assert live is not None
    assert (live["state"], live["participant"], live["experiment"], live["dry_run"]) == (
        "completed", "L01", "calibration-fe", True)
    assert live["seq"] > 4 and live["totals"]["trials_done"] == 3
    assert live["tracker"]["quality"]["accepted"] is True
    rows = read_trials_file(s.folder / "trials.csv").rows
    frames = read_frame_log(s.folder / f"frames-{s.session_id}.csv")
    q = trial_quality(frames).set_index("trial_index")
    done = {a["index"]: a for a in live["attempts"] if a["outcome"] == "done"}
    assert sorted(done) == sorted(r["trial_index"] for r in rows)
    positions = sorted((a["practice"], a["position"]) for a in done.values())
    assert positions == [(False, 1), (False, 2), (True, 1)]
    for r in rows:
        a = done[r["trial_index"]]
        assert a["frames"] == q.loc[r["trial_index"], "frames"]
        assert a["dropped"] == r["dropped_frames"]
        assert a["latency_ms"]["p95"] == pytest.approx(q.loc[r["trial_index"],
                                                             "latency_p95_ms"], abs=0.01)
        # the trial log's share runs to the trial's end, the live one to its last flip
        assert a["blanked_fraction"] == pytest.approx(r["blanked_fraction"], abs=0.05)
