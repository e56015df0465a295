"""The calibration screen and the drift check as state machines (issue 9, section 4), driven
by simulated gaze on a clock the test sets (Titta's real durations cost no wall time here), and
their hooks in a session (a stub screen; the drawing is tested in test_calibration_window.py)."""

from __future__ import annotations

import json
import re
import threading
import time
from pathlib import Path

import pytest
import yaml

from fovexp import load_display
from fovexp.experiment.options import SessionOptions
from fovexp.experiment.protocol.defaults import QualityLimits
from fovexp.experiment.protocol.spec import load_protocol
from fovexp.experiment.session import Session
from fovexp.experiment.trackers.calibration import (
    CalibrationFlow,
    CalibrationOutcome,
    CalibrationTiming,
    DriftCheck,
    HeadBoxView,
    ResultView,
    SimulatedCalibration,
    TargetStyle,
    TargetView,
    TextView,
    _Animator,
    head_box_view,
)
from fovexp.experiment.trackers.gaze import DisplayArea, FixationGeometry
from fovexp.experiment.trackers.quality import CENTRE, target_points
from fovexp.experiment.trackers.simulated import SimGazeParams, SimulatedGaze

from experiment_helpers import StubScreen, make_workspace, use_enhancer

LG = load_display("lg-oled55cx")
FIX = FixationGeometry(LG)
AREA = DisplayArea.nominal(LG)
SIZE = (3840, 2160)
CAL, VAL = target_points(9), target_points(5)
FRAME_US = 1e6 / 120


class RecordingCalibration(SimulatedCalibration):
    """The simulated tracker's calibration, recording the calls the flow makes."""

    def __init__(self, gaze) -> None:
        super().__init__(gaze)
        self.calls: list[tuple] = []

    def collect(self, x, y):
        self.calls.append(("collect", x, y))
        return True

    def discard(self, x, y):
        self.calls.append(("discard", x, y))

    def compute(self):
        self.calls.append(("compute",))
        return super().compute()


class Rig:
    """A flow (or drift check) fed by simulated gaze on a test clock, 120 frames per second."""

    def __init__(self, params: SimGazeParams | None = None, auto: bool = False,
                 timing: CalibrationTiming | None = None) -> None:
        self.clock = [0]
        self.gaze = SimulatedGaze(FIX, seed=3, params=params, clock_us=lambda: self.clock[0])
        self.gaze.start()
        self.backend = RecordingCalibration(self.gaze)
        self.records: list[tuple[dict, bool]] = []
        self.timing = timing or CalibrationTiming()
        self.auto = auto
        self.views: list = []

    def flow(self, backend=None) -> CalibrationFlow:
        return CalibrationFlow(
            backend or self.backend, CAL, VAL, QualityLimits(), AREA, 715.0, 600.0, SIZE,
            FIX.ppd_centre, 1.25, timing=self.timing, look_at=self.gaze.look_at,
            on_record=lambda rec, new: self.records.append((json.loads(json.dumps(rec)), new)),
            auto=self.auto)

    def drift(self, limit_deg: float = 0.5) -> DriftCheck:
        return DriftCheck(AREA, 715.0, 600.0, SIZE, FIX.ppd_centre, limit_deg, 0.2,
                          timing=self.timing, look_at=self.gaze.look_at, auto=self.auto)

    def run(self, flow, answer, max_frames: int = 20000):
        flow.start(self.clock[0])
        try:
            for _ in range(max_frames):
                if flow.finished:
                    return flow
                view = flow.view()
                self.views.append(view)
                keys = list(answer(view))
                self.clock[0] += int(FRAME_US)
                flow.feed(self.gaze.poll())
                flow.step(keys, self.clock[0])
                if getattr(flow, "_job", None) is not None:
                    time.sleep(0.0002)  # the worker thread's turn
            raise AssertionError(f"no outcome after {max_frames} frames ({flow.phase})")
        finally:
            flow.close()


def accept_all(view):
    if isinstance(view, HeadBoxView):
        return ["space"]
    if isinstance(view, ResultView):
        return ["space"]
    return []


def test_target_animation_is_tittas() -> None:
    """Move (accelerating, then decelerating: halfway at half the time), shrink from 1.2 to
    0.35 deg in 0.5 s, then pulse between 0.35 and 0.85 deg with a 1.5 s period; always drawn
    exactly at the point once there."""
    tm = CalibrationTiming()
    ppd = FIX.ppd_centre
    a = _Animator(SIZE, ppd, tm, TargetStyle())
    a.go((0.7, 0.7), 0.0)
    assert a.arrived(0.0) and a.view(0.0).pos == (0.7, 0.7)  # the first point appears there
    a.go((0.3, 0.7), 1.0)
    move_s = 0.4  # 0.4 of the screen's width at 1 s per width
    assert a.move_s == pytest.approx(move_s)
    mid = a.view(1.0 + move_s / 2)
    assert mid.pos == pytest.approx((0.5, 0.7)) and mid.back_px == pytest.approx(1.2 * ppd)
    assert not a.arrived(1.0 + 0.9 * move_s) and a.arrived(1.0 + move_s)
    t0 = 1.0 + move_s
    assert a.view(t0).pos == (0.3, 0.7)
    assert a.view(t0 + 0.25).back_px == pytest.approx((1.2 + 0.35) / 2 * ppd)
    assert a.view(t0 + 0.5).back_px == pytest.approx(0.35 * ppd)
    assert a.view(t0 + 0.5 + 0.75).back_px == pytest.approx(0.85 * ppd)  # half a period
    sizes = [a.view(t0 + 0.5 + k / 100).back_px for k in range(300)]
    assert min(sizes) >= 0.35 * ppd - 1e-9 and max(sizes) <= 0.85 * ppd + 1e-9
    assert a.view(t0 + 2).front_px == pytest.approx(0.12 * ppd)


def test_head_box_says_where_the_eyes_are() -> None:
    ok = head_box_view(((0.55, 0.5, 0.5), (0.45, 0.5, 0.5)), 712.0, 715.0, "Space")
    assert ok.ok and ok.eyes[0] == pytest.approx((0.45, 0.5))  # as in a mirror
    assert ok.eyes[1] == pytest.approx((0.55, 0.5))
    assert "71.2 cm, right (should be 71.5 +/- 3 cm)" in ok.text
    far = head_box_view(((0.55, 0.5, 0.5), (0.45, 0.5, 0.5)), 760.0, 715.0, "Space")
    assert not far.ok and "too far" in far.text and far.scale == pytest.approx(715 / 760)
    edge = head_box_view(((0.97, 0.5, 0.5), (0.9, 0.5, 0.5)), 715.0, 715.0, "Space")
    assert not edge.ok and "edge" in edge.text
    one = head_box_view((None, (0.45, 0.5, 0.5)), 715.0, 715.0, "Space")
    assert not one.ok and "Only the right eye" in one.text
    none = head_box_view((None, None), None, 715.0, "Space")
    assert not none.ok and "No eyes found" in none.text and "not measured" in none.text


def test_simulated_head_position_and_distance() -> None:
    """The simulated eyes 60 mm farther and 34 mm to the participant's right: the position guide
    says so (Tobii's track box: x towards the participant's left) and the gaze origins put the
    eyes 775 mm from the screen; without a position guide the gaze origins place the eyes."""
    rig = Rig(SimGazeParams(head_offset_mm=(34.0, 0.0, 60.0)))
    flow = rig.flow()
    flow.start(0)
    for _ in range(20):
        rig.clock[0] += int(FRAME_US)
        flow.feed(rig.gaze.poll())
        flow.step([], rig.clock[0])
    view = flow.view()
    flow.close()
    assert isinstance(view, HeadBoxView) and not view.ok
    assert view.distance_mm == pytest.approx(775.0) and "too far" in view.text
    left, right = SimulatedCalibration(rig.gaze).user_position()
    assert left == pytest.approx((0.5 + (31.5 - 34) / 340, 0.5, 0.7))
    assert right == pytest.approx((0.5 - (31.5 + 34) / 340, 0.5, 0.7))
    assert view.eyes[0] == pytest.approx((1 - left[0], 0.5))  # drawn as in a mirror

    class NoGuide(RecordingCalibration):  # a tracker model without the position guide
        def user_position(self):
            return None, None

    flow = rig.flow(NoGuide(rig.gaze))
    flow.start(rig.clock[0])
    for _ in range(20):
        rig.clock[0] += int(FRAME_US)
        flow.feed(rig.gaze.poll())
        flow.step([], rig.clock[0])
    fallback = flow.view()
    flow.close()
    assert fallback.eyes[0] == pytest.approx(view.eyes[0])  # from the gaze origins instead
    assert fallback.eyes[1] == pytest.approx(view.eyes[1])


def test_calibration_then_validation_on_the_stream() -> None:
    """Space on the head box; nine calibration points collected by the tracker's calibration
    (in a random order, each once), then five validation targets whose samples come from the
    gaze stream by their timestamps: 0.5 s at 600 Hz expected at each, the simulated 1 % loss;
    Space accepts; the record is written, then updated as accepted."""
    rig = Rig()
    flow = rig.run(rig.flow(), accept_all)
    assert flow.outcome == "accepted" and flow.result.passed
    collects = [c[1:] for c in rig.backend.calls if c[0] == "collect"]
    assert sorted(collects) == sorted(CAL) and collects != CAL  # shuffled, as Titta
    assert rig.backend.calls[-1] == ("compute",)
    res = flow.result
    for q in res.left.targets + res.right.targets:
        assert q.n_expected == 300 and 295 <= q.n_received <= 301
        assert q.data_loss < 0.05 and q.accuracy_deg < 0.05
    assert res.origins == "measured gaze origin"
    assert [new for _, new in rig.records] == [True, False]
    rec = rig.records[-1][0]
    assert rec["accepted"] and rec["validation"]["passed"] and rec["calibration"]["status"]
    # every target was drawn exactly at its point while the data were collected
    drawn = {v.pos for v in rig.views if isinstance(v, TargetView)}
    assert set(CAL) | set(VAL) <= drawn


def test_redo_one_validation_point() -> None:
    """On the result screen, 3 collects validation target 3 again and only it; the other
    targets keep their data."""
    rig = Rig()
    answers = iter([["3"], ["space"]])
    flow = rig.run(rig.flow(), lambda v: next(answers) if isinstance(v, ResultView)
                   else accept_all(v))
    assert flow.outcome == "accepted"
    first, second = rig.records[0][0], rig.records[-1][0]  # the last: the update
    assert [new for _, new in rig.records] == [True, True, False]
    assert second["redone"] == ["validation point 3"] and second["accepted"]
    t1, t2 = first["validation"]["left"]["targets"], second["validation"]["left"]["targets"]
    assert [t1[i] == t2[i] for i in range(5)] == [True, True, False, True, True]
    i_result = next(i for i, v in enumerate(rig.views) if isinstance(v, ResultView))
    redo = {v.pos for v in rig.views[i_result:] if isinstance(v, TargetView)}
    assert redo == {VAL[2]}
    assert len([c for c in rig.backend.calls if c[0] == "compute"]) == 1


def test_redo_one_calibration_point_then_validate_again() -> None:
    """T shows the calibration's points; 2 discards point 2's data, collects it again,
    recomputes, and validates all targets again (the old validation described the old
    calibration)."""
    rig = Rig()
    answers = iter([["t"], ["2"], ["space"]])
    modes: list[str] = []

    def answer(v):
        if isinstance(v, ResultView):
            modes.append(v.mode)
            return next(answers)
        return accept_all(v)

    flow = rig.run(rig.flow(), answer)
    assert flow.outcome == "accepted" and modes == ["validation", "calibration", "validation"]
    calls = rig.backend.calls
    k = calls.index(("discard", *CAL[1]))
    assert calls[k:] == [("discard", *CAL[1]), ("collect", *CAL[1]), ("compute",)]
    assert rig.records[-1][0]["redone"] == ["calibration point 2"]
    second = [i for i, v in enumerate(rig.views) if isinstance(v, ResultView)][1]
    assert {v.pos for v in rig.views[:second] if isinstance(v, TargetView)
            } >= set(VAL)


def test_a_failed_validation_cannot_be_accepted_and_quit_asks_first() -> None:
    """Simulated gaze 0.7 deg off every target: the central limit (0.5) fails; Space is
    refused with the reason; Q asks for confirmation, N goes back, Q then Y quits."""
    rig = Rig(SimGazeParams(target_offset_deg=(0.7, 0.0)))
    answers = iter([["space"], ["q"], ["n"], ["q"], ["y"]])
    seen: list = []

    def answer(v):
        if isinstance(v, ResultView) or (isinstance(v, TextView) and v.behind is not None):
            if not seen or seen[-1] is not v:
                seen.append(v)
                return next(answers)
            return []
        return accept_all(v)

    flow = rig.run(rig.flow(), answer)
    assert flow.outcome == "quit"
    assert not flow.result.passed and "central accuracy 0.70 deg" in flow.result.failure
    texts = [v.text for v in seen]
    assert "Cannot accept: central accuracy 0.70 deg" in texts[1]
    assert isinstance(seen[2], TextView) and seen[2].prompt == "Y: quit    N: go back"
    assert isinstance(seen[3], ResultView) and isinstance(seen[4], TextView)
    assert not rig.records[-1][0]["accepted"]


def test_dry_run_answers_every_screen_itself() -> None:
    """auto: accepted without a key when the validation passes; when it cannot pass,
    recalibrates twice, then gives up with the reason."""
    fast = CalibrationTiming.dry_run()
    rig = Rig(auto=True, timing=fast)
    assert rig.run(rig.flow(), lambda v: []).outcome == "accepted"
    bad = Rig(SimGazeParams(target_offset_deg=(0.0, 0.9)), auto=True, timing=fast)
    flow = bad.run(bad.flow(), lambda v: [])
    assert flow.outcome == "failed" and len(bad.records) == 3
    # the simulated 0.9 deg offset, measured through the simulation's per-sample noise (0.09
    # deg per axis): the mean of the validation's samples lands within a few hundredths
    found = re.match(r"eye-tracker validation failed: central accuracy (\d+\.\d+) deg",
                     flow.failure)
    assert found and abs(float(found.group(1)) - 0.9) <= 0.05, flow.failure
    assert [r["redone"] for r, _ in bad.records] == [[], ["all"], ["all"]]


def test_the_target_keeps_moving_while_the_tracker_collects() -> None:
    """The tracker's collect blocks (the SDK's does, about a second): the flow keeps drawing the
    pulsing target meanwhile; a Q pressed then waits until the point is collected."""
    release = threading.Event()

    class Blocking(RecordingCalibration):
        def collect(self, x, y):
            if len(self.calls) == 0:
                release.wait(5)
            return super().collect(x, y)

    rig = Rig()
    flow = rig.flow(Blocking(rig.gaze))
    flow.start(0)
    flow.step(["space"], 0)
    sizes = []
    quit_sent = False
    for _ in range(400):  # 3.3 s on the test clock
        rig.clock[0] += int(FRAME_US)
        flow.feed(rig.gaze.poll())
        keys = []
        if flow._job is not None and not quit_sent:
            keys, quit_sent = ["q"], True
        flow.step(keys, rig.clock[0])
        v = flow.view()
        if isinstance(v, TargetView):
            sizes.append(v.back_px)
    assert flow.phase == "targets" and flow._job is not None and not flow._job.done()
    assert max(sizes[-150:]) - min(sizes[-150:]) > 0.3 * FIX.ppd_centre  # still pulsing
    release.set()
    for _ in range(200):
        rig.clock[0] += int(FRAME_US)
        flow.step([], rig.clock[0])
        if flow.phase == "confirm_quit":
            break
        time.sleep(0.001)
    assert flow.phase == "confirm_quit"
    flow.step(["n"], rig.clock[0])  # back: the interrupted point starts again
    assert flow.phase == "targets"
    flow.close()


def test_an_sdk_error_is_a_failed_calibration_to_retry() -> None:
    class Flaky(RecordingCalibration):
        def compute(self):
            if not any(c == ("compute",) for c in self.calls):
                self.calls.append(("compute",))
                raise RuntimeError("the tracker went away")
            return super().compute()

    rig = Rig()
    prompts = []

    def answer(v):
        if isinstance(v, TextView) and v.prompt.startswith("R: calibrate again"):
            prompts.append(v.text)
            return ["r"]
        return accept_all(v)

    flow = rig.run(rig.flow(Flaky(rig.gaze)), answer)
    assert flow.outcome == "accepted"
    assert prompts and "calibration failed (RuntimeError: the tracker went away)" in prompts[0]
    assert rig.records[0][0]["calibration"]["failed"]
    assert rig.records[-1][0]["redone"] == ["all"]


def test_a_failed_sdk_calibration_outcome_is_recorded() -> None:
    class Refusing(RecordingCalibration):
        def compute(self):
            return CalibrationOutcome(failed=True, status="calibration_status_failure",
                                      reason="the tracker could not compute a calibration")

    rig = Rig(auto=True, timing=CalibrationTiming.dry_run())
    flow = rig.run(rig.flow(Refusing(rig.gaze)), lambda v: [])
    assert flow.outcome == "failed" and "could not compute" in flow.failure
    assert len(rig.records) == 3 and all(r["calibration"]["failed"] for r, _ in rig.records)


def test_quit_during_the_targets_asks_and_n_restarts_the_point() -> None:
    rig = Rig()
    state = {"sent": False}

    def answer(v):
        if isinstance(v, TextView) and v.prompt.startswith("Y: quit"):
            return ["n"]
        if (isinstance(v, TargetView) and not state["sent"]
                and len([x for x in rig.views if isinstance(x, TargetView)]) > 300):
            state["sent"] = True
            return ["q"]
        return accept_all(v)

    flow = rig.run(rig.flow(), answer)
    assert flow.outcome == "accepted" and state["sent"]
    assert any(isinstance(v, TextView) and v.prompt.startswith("Y: quit") for v in rig.views)
    collects = [c[1:] for c in rig.backend.calls if c[0] == "collect"]
    assert sorted(collects) == sorted(CAL)  # each point once: none lost, none twice


def test_drift_check() -> None:
    """The central target, then the offset of the mean gaze: within the limit it just ends;
    0.8 deg of drift offers continue / recalibrate / check again / quit; a dry run
    recalibrates."""
    rig = Rig()
    ok = rig.run(rig.drift(), lambda v: [])
    assert ok.outcome == "ok" and ok.result.offset_deg < 0.05
    assert ok.result.left.n_expected == 300 and {v.pos for v in rig.views} == {CENTRE}
    rig.gaze.calibration_error_deg = (0.8, 0.0)
    for keys, outcome, n in ((["space"], "continued", 1), (["c"], "recalibrate", 1)):
        check = rig.run(rig.drift(), lambda v, k=keys: k if isinstance(v, TextView) else [])
        assert check.outcome == outcome and len(check.results) == n
        assert check.result.failure == f"drift {check.result.offset_deg:.2f} deg at the centre " \
                                       "exceeds 0.5 deg"
        assert check.result.offset_deg == pytest.approx(0.8, abs=0.02)
    again = iter([["d"], ["space"]])
    check = rig.run(rig.drift(), lambda v: next(again) if isinstance(v, TextView) else [])
    assert check.outcome == "continued" and len(check.results) == 2
    quit_keys = iter([["q"], ["y"]])
    check = rig.run(rig.drift(), lambda v: next(quit_keys) if isinstance(v, TextView) else [])
    assert check.outcome == "quit"
    auto = Rig(auto=True, timing=CalibrationTiming.dry_run())
    auto.gaze.calibration_error_deg = (0.0, 0.8)
    assert auto.run(auto.drift(), lambda v: []).outcome == "recalibrate"


# -- in a session ---------------------------------------------------------------------------

def dry_session(tmp_path: Path, monkeypatch, n: int, **tracker) -> Session:
    use_enhancer(monkeypatch)
    ws = make_workspace(tmp_path / "ws")
    path = ws / "protocols" / "calibration-fe.yaml"
    d = yaml.safe_load(path.read_text())
    d["tracker"].update(tracker)
    path.write_text(yaml.safe_dump(d))
    return Session(load_protocol(path), SessionOptions(
        participant="D01", results_root=tmp_path / "results", tracker="simulated",
        dry_run=True, limit_trials=n, practice_trials=0, window_size=(480, 270),
        sim_speed=20.0))


def test_session_drift_checks_and_recalibration_between_trials(tmp_path: Path,
                                                               monkeypatch) -> None:
    """C pressed during trial 0 recalibrates after it (the count of trials restarts); a drift
    check follows every 2 main trials since; none after the last trial. All logged: events with
    their numbers, every calibration and validation with its reason."""
    s = dry_session(tmp_path, monkeypatch, 6, drift_check_every=2)
    screens: list[StubScreen] = []

    def factory(**kw):
        screens.append(StubScreen(operator_keys={1: {"c"}}, **kw))
        return screens[-1]

    assert s.run(screen_factory=factory) == 0
    info = json.loads((s.folder / f"session-{s.session_id}.json").read_text())
    ev = [(e["event"], e.get("after_trial")) for e in info["events"]
          if e["event"] in ("recalibration", "drift_check")]
    assert ev == [("recalibration", 0), ("drift_check", 2), ("drift_check", 4)]
    drift = [e for e in info["events"] if e["event"] == "drift_check"]
    assert all(e["outcome"] == "ok" and e["why"] == "scheduled" for e in drift)
    assert drift[0]["checks"][0]["left"]["n_expected"] == 60  # 0.1 s at 600 Hz (dry run)
    q = info["tracker_quality"]
    assert [r["reason"] for r in q] == ["start", "operator"] and all(r["accepted"] for r in q)
    assert info["display_area"] == {"source": "profile",
                                    "display_area": DisplayArea.nominal(LG).to_dict()}


def test_session_drift_fails_and_a_recalibration_fixes_it(tmp_path: Path, monkeypatch) -> None:
    """After the first calibration the simulated gaze drifts 0.8 deg; the operator's D after
    trial 0 finds it; the dry run recalibrates (which removes it) and goes on."""
    s = dry_session(tmp_path, monkeypatch, 2)

    def cal_answer(view):
        if isinstance(view, ResultView) and view.passed:
            s.gaze.calibration_error_deg = (0.8, 0.0)  # drift, after this calibration
            return ["space"]
        return ["space"] if isinstance(view, HeadBoxView) else []

    assert s.run(screen_factory=lambda **kw: StubScreen(
        cal_answer=cal_answer, operator_keys={1: {"d"}}, **kw)) == 0
    info = json.loads((s.folder / f"session-{s.session_id}.json").read_text())
    drift = [e for e in info["events"] if e["event"] == "drift_check"]
    assert len(drift) == 1 and drift[0]["outcome"] == "recalibrate"
    assert drift[0]["checks"][0]["offset_deg"] == pytest.approx(0.8, abs=0.05)
    assert [e["reason"] for e in info["events"] if e["event"] == "recalibration"] == ["drift"]
    assert [r["reason"] for r in info["tracker_quality"]] == ["start", "drift"]


def test_session_quit_in_the_drift_check_saves_progress(tmp_path: Path, monkeypatch) -> None:
    s = dry_session(tmp_path, monkeypatch, 3)

    def cal_answer(view):
        if isinstance(view, TextView) and view.prompt.startswith("Y: quit"):
            return ["y"]
        q = s.info["tracker_quality"]
        if isinstance(view, TargetView) and q and q[-1].get("accepted"):
            return ["q"]  # in the drift check (the calibration was accepted)
        return accept_all(view)

    code = s.run(screen_factory=lambda **kw: StubScreen(
        cal_answer=cal_answer, operator_keys={1: {"d"}}, **kw))
    assert code == 3
    info = json.loads((s.folder / f"session-{s.session_id}.json").read_text())
    assert info["state"] == "aborted" and info["n_completed"] == 1
    assert any(e["event"] == "aborted" and e.get("during") == "drift check"
               for e in info["events"])


def test_quit_before_any_validation_is_an_abort_not_a_failure(tmp_path: Path,
                                                               monkeypatch) -> None:
    s = dry_session(tmp_path, monkeypatch, 1)
    answers = {"HeadBoxView": ["q"], "TextView": ["y"]}
    code = s.run(screen_factory=lambda **kw: StubScreen(
        cal_answer=lambda v: answers.get(type(v).__name__, []), **kw))
    assert code == 3
    info = json.loads((s.folder / f"session-{s.session_id}.json").read_text())
    assert info["state"] == "aborted" and info["tracker_quality"] == []
