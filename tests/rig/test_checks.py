"""The rig check's figures and verdicts without a window (issue 22, section 2): frame
statistics, the refresh rate with dropped frames, the clock fit, the photodiode pattern, each
check against its threshold, the report on disk, and what a session records of it."""

from __future__ import annotations

import datetime as dt
import hashlib
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from fovexp.results.rigcheck import newest_report, session_rig_record
from fovexp.rig import checks as C
from fovexp.rig.report import build_report, check_line, markdown, value_text, write_report


def test_interval_stats_and_dropped_frames() -> None:
    """120 Hz flips with two frames dropped (one 2-period, one 3-period interval): the frame
    log's rule, an interval over 1.5 periods."""
    t = list(np.arange(100) / 120.0)
    t = t[:40] + [x + 1 / 120 for x in t[40:70]] + [x + 3 / 120 for x in t[70:]]
    s = C.interval_stats(t, 120.0)
    assert s["dropped"] == 2 and s["dropped_fraction"] == pytest.approx(2 / 99)
    assert s["p50_ms"] == pytest.approx(1e3 / 120) and s["max_ms"] == pytest.approx(3e3 / 120)
    assert C.refresh_rate_hz(t) == pytest.approx(120.0)  # drops do not bias it
    assert C.refresh_rate_hz([0.0, 1.0]) is None


def test_refresh_check_thresholds() -> None:
    ok = C.refresh_check(120.4, 120.0, 10.0, "lg", virtual=False)
    assert ok.passed and ok.advice == ""
    off = C.refresh_check(119.0, 120.0, 10.0, "lg", virtual=False)  # 0.8 % off
    assert off.passed is False and "set the display" in off.advice
    short = C.refresh_check(120.0, 120.0, 3.0, "lg", virtual=True)
    assert short.passed is None and "3.0 s only" in short.note and C.VIRTUAL in short.note
    assert C.refresh_check(None, 120.0, 10.0, "lg", False).passed is False


@pytest.mark.parametrize("make, good, bad", [
    (lambda v: C.dropped_check({"dropped_fraction": v}, False), 0.01, 0.0101),
    (lambda v: C.wheel_step_check(v, 100.0, "gpu", False), 100.0, 100.5),
    (lambda v: C.gpu_frame_check(v, 120.0, (1920, 2160), False), 8.33, 8.34),
    (lambda v: C.handover_check(v, 120.0, "texture", False), 2.08, 2.09),
    (lambda v: C.rate_check(v, 600.0, False), 612.0, 612.1),
    (lambda v: C.loss_check(v, False), 0.02, 0.021),
    (lambda v: C.latency_check(v, False), C.MAX_LATENCY_P95_MS, C.MAX_LATENCY_P95_MS + 0.1),
])
def test_each_check_at_its_threshold(make, good, bad) -> None:
    """Pass at the threshold, fail just past it, with advice only when failed."""
    assert make(good).passed is True and make(good).advice == ""
    failed = make(bad)
    assert failed.passed is False and failed.advice


def test_not_measured_is_not_judged() -> None:
    assert C.gpu_frame_check(None, 120.0, (8, 8), False, "not measured: no GL").passed is None
    assert "no GL" in C.gpu_frame_check(None, 120.0, (8, 8), False, "not measured: no GL").note
    assert C.latency_check(None, False).passed is None
    assert C.rate_check(None, 600.0, True).passed is None


def test_auto_backend_check() -> None:
    assert C.auto_backend_check({"backend": "gpu"}, False).passed
    cpu = C.auto_backend_check({"backend": "cpu", "fallback": "software renderer"}, True)
    assert cpu.passed is False and "software renderer" in cpu.advice and cpu.note == C.VIRTUAL


def test_clock_fit_offset_drift_jitter() -> None:
    """A clock 250 ppm fast, 3.2 ms ahead, with one 0.5 ms jump: the fit says so."""
    x = np.linspace(100.0, 110.0, 1001)
    y = (x + 0.0032 + 250e-6 * (x - 100.0)) * 1e6
    y[500] += 500.0
    fit = C.clock_fit(x, y)
    assert fit["offset_ms"] == pytest.approx(3.2, abs=1e-6)
    assert fit["drift_ppm"] == pytest.approx(250.0, abs=0.5)
    assert fit["jitter_ms"] == pytest.approx(0.5, abs=0.01)
    check = C.clock_check(fit, False)
    assert check.passed is False  # 250 ppm
    good = C.clock_fit(x, (x + 0.0032) * 1e6)
    assert C.clock_check(good, False).passed and abs(good["drift_ppm"]) < 1e-3
    assert math.isnan(C.clock_fit([1.0], [1.0])["drift_ppm"])


def test_photodiode_pattern_is_a_maximal_length_sequence() -> None:
    """Period 31, 16 white and 15 black frames, every window of 5 frames unique (the trace
    aligns within 31 frames), runs at most 5 frames long."""
    p = C.photodiode_pattern(62)
    assert p[:31] == p[31:] and sum(p[:31]) == 16
    windows = {tuple(p[i:i + 5]) for i in range(31)}
    assert len(windows) == 31
    runs, n = [], 1
    for a, b in zip(p, p[1:], strict=False):
        n = n + 1 if a == b else (runs.append(n), 1)[1]
    assert max(runs) <= 5


def _report(passed: bool, dry_run: bool = False) -> dict:
    checks = [C.refresh_check(120.0, 120.0, 10.0, "lg", dry_run),
              C.latency_check(10.0 if passed else 80.0, dry_run)]
    return build_report(checks, {"display": {"window_size": [3840, 2160]}}, dry_run=dry_run,
                        command="fovexp rig check", versions={"fovexp": "x"},
                        created=dt.datetime(2026, 11, 25, 9, 0, tzinfo=dt.timezone.utc),
                        duration_s=10.0)


def test_report_on_disk(tmp_path: Path) -> None:
    """JSON and Markdown under rig/, NaN written as null; the Markdown says what to change and
    keeps the table whole; the photodiode log beside them."""
    rep = _report(passed=False)
    rep["display"]["nan"] = float("nan")
    created = dt.datetime(2026, 11, 25, 9, 0, 0)
    path = write_report(tmp_path, rep, created, [(0, 1, 1.0, 1000000), (1, 0, 1.0083, 1008333)])
    assert path == tmp_path / "rig" / "rig-20261125-090000.json"
    data = json.loads(path.read_text())
    assert data["passed"] is False and data["display"]["nan"] is None
    assert [c["id"] for c in data["checks"]] == ["display.refresh", "tracker.latency"]
    md = path.with_suffix(".md").read_text()
    assert "FAILED" in md and "## What to change" in md and "rule R13" in md
    table = [line for line in md.splitlines() if line.startswith("| ")]
    assert all(line.count(" | ") == 3 for line in table[2:]), table
    pd = (tmp_path / "rig" / "rig-20261125-090000-photodiode.csv").read_text().splitlines()
    assert pd[0] == "frame,patch_white,flip_time_s,flip_system_time_us" and len(pd) == 3
    assert data["photodiode"]["log"] == "rig-20261125-090000-photodiode.csv"
    assert markdown(_report(True)).startswith("# Rig check 2026-11-25T09:00:00+00:00: PASSED")


def test_newest_report_and_what_a_session_records(tmp_path: Path) -> None:
    """The newest by name; its sha256 is the file's; a session warns when there is none, it
    failed, it is not from today, or (for a participant) it was a dry run's."""
    rec, warn = session_rig_record(tmp_path, "2026-11-25", dry_run=False)
    assert rec == {"report": None} and "no rig check" in warn
    write_report(tmp_path, _report(True), dt.datetime(2026, 11, 24, 9, 0))
    newest = write_report(tmp_path, _report(True), dt.datetime(2026, 11, 25, 8, 0))
    ref = newest_report(tmp_path)
    assert ref.path == newest and ref.sha256 == hashlib.sha256(newest.read_bytes()).hexdigest()
    rec, warn = session_rig_record(tmp_path, "2026-11-25", dry_run=False)
    assert warn is None and rec["report"]["name"] == newest.name and rec["report"]["passed"]
    rec, warn = session_rig_record(tmp_path, "2026-11-26", dry_run=False)
    assert "no rig check today" in warn
    write_report(tmp_path, _report(False), dt.datetime(2026, 11, 25, 10, 0))
    rec, warn = session_rig_record(tmp_path, "2026-11-25", dry_run=False)
    assert "failed" in warn and "tracker.latency" in warn
    write_report(tmp_path, _report(True, dry_run=True), dt.datetime(2026, 11, 25, 11, 0))
    assert "dry run" in session_rig_record(tmp_path, "2026-11-25", dry_run=False)[1]
    assert session_rig_record(tmp_path, "2026-11-25", dry_run=True)[1] is None
    (tmp_path / "rig" / "rig-20261125-120000.json").write_text("{torn")
    assert newest_report(tmp_path).path.name == "rig-20261125-110000.json"  # unreadable: skipped


# -- the report's text: a value in its threshold's unit (issue 32) -----------------------------
def _row(check: C.Check) -> str:
    """The Markdown table's row of ``check`` alone."""
    rep = build_report([check], {}, dry_run=False, command="fovexp rig check",
                       versions={}, created=dt.datetime(2026, 11, 25, 9, 0), duration_s=10.0)
    (row,) = [line for line in markdown(rep).splitlines()
              if line.startswith("| ") and not line.startswith("| check |")]
    return row


def test_a_share_is_shown_in_percent_against_its_percent_limit() -> None:
    """The issue's "0.5417 fraction" against "at most 1 %": the same figure as a percentage,
    in the Markdown and on the console."""
    dropped = C.dropped_check({"dropped_fraction": 0.005417}, virtual=False)
    assert _row(dropped) == ("| dropped frames under the session's load | 0.5417 % | at most "
                             "1 % of the frames | pass |")
    assert check_line(dropped.to_dict()) == ("dropped frames under the session's load: "
                                             "0.5417 %; threshold: at most 1 % of the frames; "
                                             "pass")
    assert dropped.to_dict()["unit"] == "%" and dropped.passed is True
    loss = C.loss_check(0.5417, simulated=False)
    assert _row(loss) == ("| samples missing (never delivered) | 54.17 % | at most 2 % of the "
                          "samples the nominal rate promises | **FAIL** |")
    assert C.loss_check(None, False).value is None and value_text(
        C.loss_check(None, False).to_dict()) == "-"


def test_rates_are_judged_against_a_band_in_hz() -> None:
    assert _row(C.refresh_check(120.2, 120.0, 10.0, "lg", False)) == (
        "| refresh rate | 120.2 Hz | 119.4 to 120.6 Hz (120 Hz +/- 0.5 %), measured over at "
        "least 10 s | pass |")
    assert _row(C.rate_check(612.1, 600.0, False)) == (
        "| sampling rate (device clock) | 612.1 Hz | 588 to 612 Hz (600 Hz +/- 2 %) | "
        "**FAIL** |")


def test_every_value_is_in_its_thresholds_unit() -> None:
    """Each check with a numeric value states its limit in the value's own unit; the clock's
    drift (ppm) and jitter (ms) are two checks, each against its own limit."""
    fit = C.clock_fit(np.linspace(0, 10, 101), (np.linspace(0, 10, 101) + 0.001) * 1e6)
    checks = [C.refresh_check(120.0, 120.0, 10.0, "lg", False),
              C.dropped_check({"dropped_fraction": 0.002}, False),
              C.wheel_step_check(12.0, 100.0, "gpu", False),
              C.gpu_frame_check(3.0, 120.0, (1920, 2160), False),
              C.handover_check(0.5, 120.0, "texture", False),
              C.rate_check(600.0, 600.0, False), C.loss_check(0.001, False),
              C.latency_check(9.0, False), C.clock_check(fit, False),
              C.clock_jitter_check(fit, False)]
    units = {"Hz", "%", "ms", "ppm"}
    for c in checks:
        assert isinstance(c.value, float) and c.unit in units, c
        stated = c.threshold.split("(")[0]  # the limit; a tolerance may follow in brackets
        assert re.search(rf"\d {re.escape(c.unit)}(?!\w)", stated), c
        assert not any(re.search(rf"\d {re.escape(u)}(?!\w)", stated)
                       for u in units - {c.unit}), c
    jump = C.clock_jitter_check({**fit, "jitter_ms": 1.5}, False)
    assert jump.passed is False and jump.advice and C.clock_check(fit, False).passed


def test_the_tracker_is_named_once() -> None:
    """The issue's "tracker found: simulated: simulated"."""
    assert C.source_name("simulated", "simulated") == "simulated"
    assert C.source_name("iohub", "mouse") == "iohub (mouse)"
    found = C.tracker_found_check(True, C.source_name("simulated", "simulated"), "")
    assert _row(found) == ("| tracker found | simulated | the gaze source starts and sends "
                           "samples | pass |")
    md = markdown(_report(passed=False))
    assert not re.search(r"\b(\w+): \1\b", md)  # no word said twice in a row
