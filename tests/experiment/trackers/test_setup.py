"""The tracker's set-up around the trials (:mod:`fovexp.experiment.trackers.setup`), without a
window: simulated eyes (the real calibration flow and quality measures) on a window-free screen;
every calibration and validation recorded with its reason; drift checks when due and never
after the last trial; the mouse skips it all; the tracker's display area checked against the
profile."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from fovexp import FovexpError, load_display
from fovexp.experiment.protocol.spec import load_protocol
from fovexp.experiment.records.sessionfile import SessionFile
from fovexp.experiment.trackers.calibration import CalibrationTiming
from fovexp.experiment.trackers.gaze import DisplayArea, FixationGeometry
from fovexp.experiment.trackers.mouse import MouseGaze
from fovexp.experiment.trackers.setup import (
    Aborted,
    TrackerSetup,
    calibration_timing,
    display_area,
    window_ppd,
)
from fovexp.experiment.trackers.simulated import SimulatedGaze

from experiment_helpers import REPO, StubScreen

SIZE = (480, 270)


def make(tmp_path: Path, gaze, drift_every: int = 2, **screen_kw) -> TrackerSetup:
    lp = load_protocol(REPO / "protocols" / "calibration-fe.yaml")
    spec = lp.spec.model_copy(update={"tracker": lp.spec.tracker.model_copy(
        update={"drift_check_every": drift_every})})
    display = load_display(lp.display_name)
    fixation = FixationGeometry(display)
    file = SessionFile(tmp_path / "session-x.json", {"tracker_quality": [], "events": []})
    sink: list = []
    gaze.start()
    area, _ = display_area(gaze, display, lp.display_name)
    setup = TrackerSetup(
        gaze=gaze, screen=StubScreen(SIZE, **screen_kw), protocol_spec=spec, area=area,
        distance_mm=10.0 * display.distance_cm, ppd_px=window_ppd(fixation, display, SIZE[0]),
        timing=CalibrationTiming.dry_run(), auto=True, seed=3, file=file, gaze_sink=sink.extend)
    setup.sink = sink
    return setup


def trials(n: int):
    lp = load_protocol(REPO / "protocols" / "calibration-fe.yaml")
    return lp.plan("P01", limit=n, practice=0)[1]


def test_calibration_then_drift_checks_when_due(tmp_path: Path) -> None:
    display = load_display("lg-oled55cx")
    s = make(tmp_path, SimulatedGaze(FixationGeometry(display), seed=1))
    s.setup("start")
    q = s.file.info["tracker_quality"]
    assert [r["reason"] for r in q] == ["start"] and q[-1]["accepted"]
    assert q[-1]["validation"]["passed"] and len(s.sink) > 0  # the gaze went to the log
    ts = trials(5)
    for t in ts:
        s.between_trials(t, more_trials=t is not ts[-1])
    drift = [e for e in s.file.info["events"] if e["event"] == "drift_check"]
    # after the 2nd and the 4th trial; the 5th is the last: none after it
    assert [(e["after_trial"], e["why"], e["outcome"]) for e in drift] == [
        (1, "scheduled", "ok"), (3, "scheduled", "ok")]
    assert json.loads(s.file.path.read_text())["tracker_quality"][0]["accepted"]


def test_operator_keys_recalibrate_or_check(tmp_path: Path) -> None:
    display = load_display("lg-oled55cx")
    s = make(tmp_path, SimulatedGaze(FixationGeometry(display), seed=2), drift_every=0,
             operator_keys={1: {"c"}, 2: {"d"}})
    s.setup()
    t0, t1, t2 = trials(3)
    s.between_trials(t0, True)
    s.between_trials(t1, True)
    s.between_trials(t2, False)
    assert [r["reason"] for r in s.file.info["tracker_quality"]] == ["start", "operator"]
    kinds = [(e["event"], e.get("why", e.get("reason"))) for e in s.file.info["events"]]
    assert kinds == [("recalibration", "operator"), ("drift_check", "operator")]


def test_quit_in_the_calibration_is_an_abort(tmp_path: Path) -> None:
    display = load_display("lg-oled55cx")
    from fovexp.experiment.trackers.calibration import HeadBoxView, TextView

    def answer(view):
        if isinstance(view, TextView) and view.prompt.startswith("Y: quit"):
            return ["y"]
        return ["q"] if isinstance(view, HeadBoxView) else []

    s = make(tmp_path, SimulatedGaze(FixationGeometry(display), seed=2), cal_answer=answer)
    s.auto = False
    with pytest.raises(Aborted):
        s.setup()
    assert s.file.info["events"][-1] == {**s.file.info["events"][-1], "event": "aborted",
                                         "during": "eye-tracker calibration (start)"}


def test_the_mouse_is_not_calibrated(tmp_path: Path) -> None:
    s = make(tmp_path, MouseGaze(), operator_keys={1: {"d"}})
    s.setup()
    assert s.file.info["tracker_quality"][0]["skipped"] == "mouse"
    s.between_trials(trials(2)[0], True)
    assert s.screen.cal_views == [] and s.file.info["events"] == []


def test_display_area_of_a_tracker_against_the_profile() -> None:
    display = load_display("lg-oled55cx")
    nominal = DisplayArea.nominal(display)

    class Tracker:
        def __init__(self, scale: float) -> None:
            c = nominal
            self.area = DisplayArea(c.top_left, tuple(scale * v for v in c.top_right),
                                    c.bottom_left, source="tracker")

        def display_area(self) -> DisplayArea:
            return self.area

    area, info = display_area(MouseGaze(), display, "lg-oled55cx")
    assert info["source"] == "profile" and area == nominal
    area, info = display_area(Tracker(1.0), display, "lg-oled55cx")
    assert info["source"] == "tracker"
    with pytest.raises(FovexpError, match=r"\(lg-oled55cx\)$"):
        display_area(Tracker(1.2), display, "lg-oled55cx")
    assert calibration_timing(None, True) == CalibrationTiming.dry_run()
    assert calibration_timing(None, False) == CalibrationTiming()
