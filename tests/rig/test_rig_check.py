"""``fovexp rig check --dry-run`` under Xvfb (issue 22, section 2): with the simulated tracker
and the photodiode pattern, and with ioHub's MouseGaze; the report's fields, every figure
labelled as a virtual display's, the photodiode log against the pattern, and a session
recording the newest report."""

from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path

import pytest

from fovexp.rig.checks import VIRTUAL, photodiode_pattern

from experiment_helpers import make_workspace, run_cli, xvfb_display  # noqa: F401

pytestmark = [pytest.mark.gui, pytest.mark.slow]

CHECK_IDS = ["tracker.found", "display.keyboard", "display.refresh", "render.wheel_step",
             "gpu.auto", "display.dropped", "gpu.handover", "gpu.stages", "tracker.rate",
             "tracker.loss", "tracker.latency", "tracker.clock", "tracker.clock_jitter"]
MOUSEGAZE = """\
eyetracker.hw.mouse.EyeTracker:
  name: tracker
  runtime_settings: {sampling_rate: 250}
  device_timer: {interval: 0.004}
"""


def _check(ws: Path, *extra: str) -> tuple[dict, Path]:
    r = run_cli(["rig", "check", "--dry-run", "--duration", "2", "--results",
                 str(ws / "results"), *extra], cwd=ws, timeout=600)
    assert r.returncode in (0, 1), r.stderr[-3000:]
    last = r.stderr.strip().splitlines()[-1]
    assert last.startswith("fovexp rig check: ") and "dry run: a virtual display's" in last
    reports = sorted((ws / "results" / "rig").glob("rig-*.json"))
    assert reports
    rep = json.loads(reports[-1].read_text())
    assert r.returncode == (1 if rep["passed"] is False else 0)
    return rep, reports[-1]


def _common(rep: dict) -> None:
    assert rep["dry_run"] and rep["virtual_display"] == VIRTUAL
    # outside a study folder: the validation, ./protocols' before the shipped one (issue 32)
    assert rep["protocol"]["experiment"] == "validation"
    assert rep["protocol"]["chosen"] == "the default outside a study folder"
    assert [c["id"] for c in rep["checks"]] == CHECK_IDS
    for c in rep["checks"]:
        assert c["threshold"] and c["passed"] in (True, False, None)
        assert (c["passed"] is False) == bool(c["advice"])
        if c["group"] in ("display", "gpu") or c["id"] in ("tracker.latency", "tracker.clock",
                                                           "tracker.clock_jitter"):
            assert VIRTUAL in c["note"], c  # every figure of the virtual display says so
    refresh = next(c for c in rep["checks"] if c["id"] == "display.refresh")
    assert refresh["passed"] is None and re.search(r"measured over 2\.\d s only", refresh["note"])
    d = rep["display"]
    assert d["window_size"] == [480, 270] and d["profile"] == "lg-oled55cx"
    assert d["refresh"]["measured_hz"] == pytest.approx(60.0, rel=0.01)  # the paced rate
    assert d["load"]["frames"] > 30 and d["load"]["wheel_steps"] > 0
    # paced at 60 Hz: no interval shorter than a period (a loaded machine drops frames)
    assert d["load"]["p50_ms"] >= 0.95e3 / 60 and d["load"]["max_ms"] >= d["load"]["p50_ms"]
    g = rep["gpu"]
    assert g["renderer"]["backend"] in ("cpu", "gpu") and g["gl_version"]["version"]
    assert g["wheel_step"]["step_ms"] > 0 and g["wheel_step"]["max_step_ms"] == 100.0
    assert g["handover_ms"]["n"] > 0
    assert "stages_ms" in g["stages"] or "not_measured" in g["stages"]
    t = rep["tracker"]
    assert t["found"] and t["samples"] > 0 and t["gaze_to_flip_ms"]["frames"] > 0
    assert t["gaze_to_flip_ms"]["p95"] > 0
    assert abs(t["clock_vs_psychopy"]["drift_ppm"]) < 1000


def test_rig_check_dry_run_with_the_photodiode(tmp_path, xvfb_display) -> None:  # noqa: F811
    ws = make_workspace(tmp_path / "r")
    rep, path = _check(ws, "--photodiode")
    _common(rep)
    t = rep["tracker"]
    assert t["kind"] == "simulated" and t["rate"]["rate_hz"] == pytest.approx(600.0, rel=0.02)
    # the photodiode log: the pattern from frame 0, flips in order, on both clocks
    log = (path.parent / rep["photodiode"]["log"]).read_text().splitlines()
    rows = [line.split(",") for line in log[1:]]
    assert len(rows) == rep["photodiode"]["frames"] > 60
    assert [r[1] == "1" for r in rows] == photodiode_pattern(len(rows))
    flips = [float(r[2]) for r in rows]
    us = [int(r[3]) for r in rows]
    assert all(b > a for a, b in zip(flips, flips[1:], strict=False))
    assert all(b > a for a, b in zip(us, us[1:], strict=False))
    # and a session started after it records it, name and sha256
    r = run_cli(["run", "calibration-fe", "--participant", "S01", "--dry-run", "--practice",
                 "0", "--limit-trials", "1", "--sim-speed", "12", "--results",
                 str(ws / "results")], cwd=ws, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    info = json.loads(next((ws / "results" / "calibration-fe" / "S01").glob(
        "session-*.json")).read_text())
    rec = info["runs"][-1]["rig_check"]["report"]
    assert rec["name"] == path.name and rec["dry_run"] is True
    assert rec["sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()


def test_rig_check_dry_run_with_iohub_mousegaze(tmp_path, xvfb_display) -> None:  # noqa: F811
    ws = make_workspace(tmp_path / "m")
    cfg = ws / "mousegaze.yaml"
    cfg.write_text(MOUSEGAZE)
    rep, _ = _check(ws, "--tracker", "iohub", "--tracker-config", str(cfg))
    _common(rep)
    t = rep["tracker"]
    assert t["kind"] == "iohub" and t["info"]["family"] == "mousegaze"
    assert t["nominal_rate_hz"] == 250.0
    assert t["rate"]["rate_hz"] == pytest.approx(250.0, rel=0.02)
    rate = next(c for c in rep["checks"] if c["id"] == "tracker.rate")
    assert rate["passed"] is True
