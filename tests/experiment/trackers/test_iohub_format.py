"""ioHub eye trackers without a server (issue 22): the families and their extras, the lab's
ioHub configuration in both of ioHub's forms, samples and times turned into the runner's gaze
samples (with the event classes' real field lists), monocular validation, and the tracker's
own set-up in the calibration flow. The server itself: test_iohub.py."""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest

from fovexp import FovexpError, load_display
from fovexp.experiment.protocol.defaults import QualityLimits
from fovexp.experiment.trackers.calibration import (
    CalibrationFlow,
    CalibrationOutcome,
    CalibrationTiming,
    HeadBoxView,
    ResultView,
    TargetView,
    TextView,
)
from fovexp.experiment.trackers.families import (
    FAMILIES,
    OTHER,
    check_plugin,
    family_of,
    hub_config,
    parse_iohub_config,
)
from fovexp.experiment.trackers.gaze import DisplayArea, FixationGeometry, GazeSample
from fovexp.experiment.trackers.iohub import (
    LEFT_EYE,
    RIGHT_EYE,
    IoHubCalibration,
    PixelMap,
    RateMeter,
    SampleLayout,
    device_time_us,
    eyes_of,
    sample_from_event,
    system_time_us,
)
from fovexp.experiment.trackers.quality import TargetData, target_points, validation_result

LG = load_display("lg-oled55cx")

BUILDER = """\
# PsychoPy Builder's ioConfig for an EyeLink, as YAML
eyetracker.hw.sr_research.eyelink.EyeTracker:
  name: tracker
  model_name: EYELINK 1000 DESKTOP
  simulation_mode: false
  network_settings: 100.1.1.1
  runtime_settings:
    sampling_rate: 1000
    track_eyes: RIGHT_EYE
Keyboard: {use_keymap: psychopy}
"""

IOHUB_FILE = """\
monitor_devices:
  - Display:
      name: display
      reporting_unit_type: deg
  - Keyboard: {}
  - eyetracker.hw.tobii.EyeTracker:
      name: et
      runtime_settings: {sampling_rate: 600, track_eyes: BINOCULAR}
data_store:
  enable: true
"""


@pytest.mark.parametrize("path, family", [
    ("eyetracker.hw.sr_research.eyelink.EyeTracker", "eyelink"),
    ("eyetracker.eyelink.EyeTracker", "eyelink"),
    ("eyetracker.hw.tobii.EyeTracker", "tobii"),
    ("eyetracker.hw.gazepoint.gp3.EyeTracker", "gazepoint"),
    ("eyetracker.hw.pupil_labs.pupil_core.EyeTracker", "pupil-labs"),
    ("eyetracker.hw.pupil_labs.neon.EyeTracker", "pupil-labs"),
    ("eyetracker.eyelogic.psychopy.eyetracker.EyeTracker", "eyelogic"),
    ("eyetracker.hw.mouse.EyeTracker", "mousegaze"),
    ("eyetracker.hw.acme.EyeTracker", "other"),
])
def test_family_of_every_plugin_class_path(path: str, family: str) -> None:
    """The class paths PsychoPy Builder and the plugins' own YAML files use."""
    assert family_of(path).key == family


def _pyproject_extras() -> dict[str, list[str]]:
    try:
        import tomllib
    except ImportError:  # Python 3.10
        import tomli as tomllib
    root = Path(__file__).resolve().parents[3]
    return tomllib.loads((root / "pyproject.toml").read_text())["project"][
        "optional-dependencies"]


@pytest.mark.parametrize("fam", [f for f in FAMILIES if f.extra], ids=lambda f: f.key)
def test_missing_plugin_names_its_extra(fam) -> None:
    extras = _pyproject_extras()
    assert any(d.startswith(fam.distribution) for d in extras[fam.extra]), extras[fam.extra]
    with pytest.raises(FovexpError) as e:
        check_plugin(fam, find=lambda name: None)
    msg = str(e.value)
    assert f"pip install 'fovexp[{fam.extra}]'" in msg and fam.distribution in msg
    assert "\n" not in msg


def test_mousegaze_and_unknown_trackers_need_no_plugin() -> None:
    mouse = family_of("eyetracker.hw.mouse.EyeTracker")
    assert check_plugin(mouse, find=lambda name: None) is None and mouse.pilot
    assert check_plugin(OTHER, find=lambda name: None) is None and not OTHER.pilot


def test_builder_form_of_the_configuration() -> None:
    cfg = parse_iohub_config(BUILDER, Path("lab/eyelink.yaml"))
    assert cfg.device_class == "eyetracker.hw.sr_research.eyelink.EyeTracker"
    assert cfg.family.key == "eyelink" and cfg.name == "tracker"
    assert cfg.sampling_hz == 1000.0 and cfg.track_eyes == "RIGHT_EYE"
    assert cfg.devices == {"Keyboard": {"use_keymap": "psychopy"}} and cfg.ignored == ()
    assert re.fullmatch(r"[0-9a-f]{64}", cfg.sha256)
    rec = cfg.to_dict()
    assert rec["family"] == "eyelink" and rec["settings"]["network_settings"] == "100.1.1.1"


def test_iohub_config_file_form_and_what_fovexp_replaces() -> None:
    """``monitor_devices`` as a list (and as a mapping); its Display and data_store are left
    out (recorded): the Display is the display profile's, in pixels, on the session's screen."""
    cfg = parse_iohub_config(IOHUB_FILE, Path("iohub_config.yaml"))
    assert cfg.family.key == "tobii" and cfg.name == "et" and cfg.sampling_hz == 600.0
    assert cfg.devices == {"Keyboard": {}} and cfg.ignored == ("Display", "data_store")
    as_map = IOHUB_FILE.replace("  - Display:", "  Display:").replace("  - Keyboard", "  Keyboard")
    as_map = as_map.replace("  - eyetracker", "  eyetracker")
    assert parse_iohub_config(as_map, Path("m.yaml")).devices == {"Keyboard": {}}
    hub = hub_config(cfg, LG, 1, overrides={"runtime_settings": {"sampling_rate": 300}})
    devs = hub["monitor_devices"]
    display = devs[0]["Display"]
    assert display["reporting_unit_type"] == "pix" and display["device_number"] == 1
    assert display["physical_dimensions"] == {"width": 10 * LG.width_cm,
                                              "height": 10 * LG.height_cm, "unit_type": "mm"}
    assert display["default_eye_distance"]["surface_center"] == 10 * LG.distance_cm
    tracker = devs[-1]["eyetracker.hw.tobii.EyeTracker"]
    assert tracker["runtime_settings"] == {"sampling_rate": 300, "track_eyes": "BINOCULAR"}
    assert len([d for d in devs if "Display" in d]) == 1
    # the window reads keys through ioHub's keyboard while a server runs: PsychoPy's names
    assert {"Keyboard": {"use_keymap": "psychopy"}} in devs
    builder = hub_config(parse_iohub_config(BUILDER, Path("b.yaml")), LG, 0)
    assert {"Keyboard": {"use_keymap": "psychopy"}} in builder["monitor_devices"]


@pytest.mark.parametrize("text, problem", [
    ("Keyboard: {}\n", "found none"),
    ("eyetracker.hw.mouse.EyeTracker: {}\neyetracker.hw.tobii.EyeTracker: {}\n",
     "found eyetracker.hw.mouse.EyeTracker, eyetracker.hw.tobii.EyeTracker"),
    ("eyetracker.hw.mouse.EyeTracker: [1, 2]\n", "must be a mapping"),
    ("eyetracker.hw.mouse.EyeTracker: {enable: false}\n", "enable: false"),
    ("eyetracker.hw.mouse.EyeTracker: {}\neyetracker.hw.mouse.EyeTracker: {}\n", "given twice"),
    ("monitor_devices: [{a: 1, b: 2}]\n", "one 'DeviceClass: {settings}' mapping"),
    ("- 1\n", "expected a mapping"),
])
def test_bad_configurations_are_one_line_naming_the_file(text: str, problem: str) -> None:
    with pytest.raises(FovexpError) as e:
        parse_iohub_config(text, Path("lab/bad.yaml"))
    assert "lab/bad.yaml" in str(e.value) and problem in str(e.value)
    assert "\n" not in str(e.value)


def test_pixels_to_window_coordinates() -> None:
    """ioHub's pixels (from the screen's centre, y up) -> normalised over the window (origin
    top-left, y down); a full-screen window is the whole screen; and back, for the pointer."""
    whole = PixelMap.whole((3840, 2160))
    assert whole.to_norm(0.0, 0.0) == (0.5, 0.5)
    assert whole.to_norm(-1920.0, 1080.0) == (0.0, 0.0)
    assert whole.to_norm(960.0, -540.0) == (0.75, 0.75)
    win = PixelMap((1280, 720), (400.0, 225.0, 480.0, 270.0))  # a dry run's window, centred
    assert win.to_norm(0.0, 0.0) == (0.5, 0.5)
    assert win.to_norm(-240.0, 135.0) == (0.0, 0.0)
    x, y = win.to_screen_px(0.25, 0.75)
    assert (x, y) == (520.0, 427.5)
    assert win.to_norm(x - 640.0, 360.0 - y) == (0.25, 0.75)


def _names(kind: str) -> list[str]:
    """The real event class's field list (PsychoPy's ioHub), else skip."""
    pytest.importorskip("psychopy", reason="PsychoPy is not installed (fovexp[experiment])")
    # the classes ioHub registers (EventConstants.getClass) once a device uses them
    import psychopy.iohub.devices.eyetracker.eye_events as ev

    cls = {"mono": ev.MonocularEyeSampleEvent, "bino": ev.BinocularEyeSampleEvent,
           "gazepoint": ev.GazepointSampleEvent}[kind]
    return list(cls.CLASS_ATTRIBUTE_NAMES)


def _event(names: list[str], **fields) -> list:
    ev = [0] * len(names)
    for k, v in fields.items():
        ev[names.index(k)] = v
    return ev


WHOLE = PixelMap.whole((1920, 1080))


def test_sample_times_are_the_logs_microseconds() -> None:
    """``time`` (s, PsychoPy's clock) -> system_time_us, ``device_time`` (s, the tracker's
    clock) -> device_time_us, rounded to the microsecond; the frame log's latency is then the
    difference of two such numbers."""
    names = _names("mono")
    ev = _event(names, device_time=1234.5678904, logged_time=12.0031, time=12.0021496,
                delay=0.001, eye=RIGHT_EYE, gaze_x=0.0, gaze_y=0.0, status=0)
    s = sample_from_event(ev, SampleLayout.of(names), WHOLE)
    assert (s.system_time_us, s.device_time_us) == (12_002_150, 1_234_567_890)
    assert system_time_us(12.0021496) == 12_002_150 and device_time_us(0.0000004) == 0
    # a flip read on the same clock 9.8 ms later: 9.8 ms gaze-to-flip
    assert system_time_us(12.0119496) - s.system_time_us == 9_800


def test_monocular_samples() -> None:
    names = _names("mono")
    layout = SampleLayout.of(names)
    right = sample_from_event(_event(names, time=1.0, eye=RIGHT_EYE, gaze_x=480.0, gaze_y=-270.0,
                                     status=0), layout, WHOLE)
    assert (right.right_valid, right.left_valid) == (True, False)
    assert (right.right_x, right.right_y) == (0.75, 0.75) and right.point == (0.75, 0.75)
    assert math.isnan(right.left_x)
    left = sample_from_event(_event(names, time=1.0, eye=LEFT_EYE, gaze_x=0.0, gaze_y=0.0),
                             layout, WHOLE)
    assert (left.left_valid, left.right_valid) == (True, False) and left.point == (0.5, 0.5)
    averaged = sample_from_event(_event(names, time=1.0, eye=27, gaze_x=0.0, gaze_y=0.0),
                                 layout, WHOLE)  # BINOCULAR_AVERAGED: one point for both
    assert averaged.left_valid and averaged.right_valid
    # missing (MouseGaze's blink: status 2, position UNDEFINED = 0: the centre!) and NaN
    for bad in (dict(status=2, gaze_x=0.0, gaze_y=0.0), dict(status=0, gaze_x=float("nan"))):
        s = sample_from_event(_event(names, time=1.0, eye=RIGHT_EYE, **bad), layout, WHOLE)
        assert not s.valid and s.point is None


@pytest.mark.parametrize("kind", ["bino", "gazepoint"])
@pytest.mark.parametrize("status, valid", [(0, (True, True)), (2, (True, False)),
                                           (20, (False, True)), (22, (False, False))])
def test_binocular_samples_and_ioHubs_status_flags(kind: str, status: int, valid) -> None:
    names = _names(kind)
    ev = _event(names, time=2.0, status=status, left_gaze_x=-96.0, left_gaze_y=0.0,
                right_gaze_x=96.0, right_gaze_y=0.0)
    s = sample_from_event(ev, SampleLayout.of(names), WHOLE)
    assert (s.left_valid, s.right_valid) == valid
    if valid == (True, True):
        assert (s.left_x, s.right_x) == (0.45, 0.55) and s.point == pytest.approx((0.5, 0.5))
    if valid == (False, False):
        assert s.point is None


def test_eyes_recorded() -> None:
    assert eyes_of("RIGHT_EYE", False) == ("right",)
    assert eyes_of("LEFT_EYE", False) == ("left",)
    assert eyes_of("BOTH", False) == eyes_of("BINOCULAR", False) == eyes_of(None, False) \
        == ("left", "right")
    assert eyes_of("BINOCULAR", True) == ("right",)  # MouseGaze's samples: the right eye


def test_rate_meter_leaves_gaps_out() -> None:
    m = RateMeter(500.0)
    m.add([i * 2000 for i in range(501)])  # one second at 500 Hz
    m.add([5_000_000 + i * 2000 for i in range(251)])  # a gap (a lost tracker), then 0.5 s
    assert m.rate_hz == pytest.approx(500.0) and m.gaps == 1 and m.samples == 752
    assert m.to_dict()["seconds"] == pytest.approx(1.5)
    slow = RateMeter(500.0)
    slow.add([i * 2040 for i in range(500)])  # 2 % slow
    assert slow.rate_hz == pytest.approx(1e6 / 2040)


FIX = FixationGeometry(LG)
AREA = DisplayArea.nominal(LG)


def _right_eye_at(target, n=300, rate=600.0) -> TargetData:
    samples = [GazeSample(i, i, math.nan, math.nan, False, target[0], target[1], True)
               for i in range(n)]
    return TargetData(target, samples, n / rate, rate)


def test_a_monocular_tracker_is_validated_on_its_eye() -> None:
    """A right-eye tracker: its eye's figures decide; judged on both eyes it could never pass
    (no valid left-eye sample anywhere)."""
    data = [_right_eye_at(t) for t in target_points(5)]
    both = validation_result(AREA, 715.0, data, QualityLimits())
    assert not both.passed and "no valid left-eye samples" in both.failure
    mono = validation_result(AREA, 715.0, data, QualityLimits(), eyes=("right",))
    assert mono.passed and mono.accuracy_deg == pytest.approx(0.0, abs=1e-9)
    assert mono.data_loss == 0.0 and mono.to_dict()["eyes"] == ["right"]
    assert mono.summary().startswith("right eye:") and "left" not in mono.summary()


class OwnSetup:
    """A tracker whose set-up is its own (an ioHub tracker's runSetupProcedure)."""

    own_procedure = "the tracker's own calibration"

    def __init__(self, fail_first: bool = False) -> None:
        self.calls: list[str] = []
        self.fail_first = fail_first

    def begin(self):
        self.calls.append("begin")

    def collect(self, x, y):
        raise AssertionError("no fovexp calibration point for a tracker with its own set-up")

    def discard(self, x, y):
        raise AssertionError("no point to discard")

    def compute(self):
        self.calls.append("setup")
        if self.fail_first and self.calls.count("setup") == 1:
            return CalibrationOutcome(failed=True, status="CALIBRATION_ABORTED",
                                      reason="aborted at the host PC")
        return CalibrationOutcome(failed=False, status="CALIBRATION_OK")

    def end(self):
        self.calls.append("end")

    def user_position(self):
        return None, None


def _run(flow: CalibrationFlow, eye_at, answer, clock=None, frames=20000):
    clock = clock or [0]
    flow.start(clock[0])
    views = []
    try:
        for _ in range(frames):
            if flow.finished:
                return views
            v = flow.view()
            views.append(v)
            clock[0] += 8333
            target = v.pos if isinstance(v, TargetView) else (0.5, 0.5)
            flow.feed([GazeSample(clock[0], clock[0], math.nan, math.nan, False, *eye_at(target),
                                  True)] * 5)
            flow.step(list(answer(v)), clock[0])
        raise AssertionError(f"no outcome ({flow.phase})")
    finally:
        flow.close()


def test_own_setup_then_fovexps_validation() -> None:
    """No head box and no fovexp calibration points: the tracker's set-up runs (on the worker
    thread, a text on screen meanwhile), then fovexp's validation targets, judged on the
    tracker's eye; R runs the tracker's set-up again; a failed set-up says why."""
    backend = OwnSetup(fail_first=True)
    records = []
    flow = CalibrationFlow(backend, target_points(9), target_points(5), QualityLimits(), AREA,
                           715.0, 600.0, (1920, 1080), FIX.ppd_centre / 2, 1.25,
                           timing=CalibrationTiming.dry_run(), eyes=("right",),
                           on_record=lambda rec, new: records.append(rec), auto=False)
    on_result = iter([["r"], ["space"]])

    def answer(v):
        if isinstance(v, TextView) and "R: calibrate again" in v.prompt:
            return ["r"]
        if isinstance(v, ResultView):
            return next(on_result)
        return []

    views = _run(flow, lambda t: t, answer)
    assert flow.outcome == "accepted" and flow.result.passed
    assert not any(isinstance(v, HeadBoxView) for v in views)
    texts = [v.text for v in views if isinstance(v, TextView)]
    assert any(t.startswith("Calibrating: the tracker's own calibration") for t in texts)
    assert records[0]["calibration"]["reason"] == "aborted at the host PC"
    assert backend.calls.count("setup") == 3 and backend.calls[-1] == "end"
    assert set(target_points(5)) <= {v.pos for v in views if isinstance(v, TargetView)}
    assert records[0]["calibration"]["failed"] and records[-1]["accepted"]
    assert records[-1]["calibration"]["status"] == "CALIBRATION_OK"
    assert records[-1]["validation"]["eyes"] == ["right"]


def test_iohub_calibration_reads_runSetupProcedures_result() -> None:
    class Gaze:
        family = family_of("eyetracker.hw.sr_research.eyelink.EyeTracker")

        def __init__(self, result):
            self.result = result

        def run_setup(self):
            return self.result

    ok = IoHubCalibration(Gaze({"RESULT": "CALIBRATION_OK"}))
    assert "camera set-up" in ok.own_procedure and not ok.compute().failed
    aborted = IoHubCalibration(Gaze({"RESULT": "CALIBRATION_ABORTED"})).compute()
    assert aborted.failed and "CALIBRATION_ABORTED" in aborted.reason
    none = IoHubCalibration(Gaze({"result": 202})).compute()  # no set-up through ioHub
    assert not none.failed and none.status == "not offered through ioHub"


def test_the_protocol_names_the_iohub_configuration(tmp_path: Path) -> None:
    """``tracker.iohub_config`` in the protocol, relative to its file; ``--tracker-config``
    overrides it; neither: one line saying both ways."""
    import yaml

    from fovexp.experiment.options import SessionOptions
    from fovexp.experiment.protocol.spec import load_protocol
    from fovexp.experiment.session import Session

    from experiment_helpers import make_workspace

    ws = make_workspace(tmp_path / "w")
    path = ws / "protocols" / "calibration-fe.yaml"
    data = yaml.safe_load(path.read_text())
    data.setdefault("tracker", {})["iohub_config"] = "lab/eyelink.yaml"
    path.write_text(yaml.safe_dump(data))
    lp = load_protocol(path, results_root=ws / "results")

    def session(**kw) -> Session:
        return Session(lp, SessionOptions(participant="P01", results_root=ws / "results",
                                          tracker="iohub", dry_run=True,
                                          window_size=(480, 270), **kw))

    s = session()
    assert s.iohub_config_path() == ws / "protocols" / "lab" / "eyelink.yaml"
    s.release()
    s = session(tracker_config=Path("other.yaml"))
    assert s.iohub_config_path() == Path("other.yaml")
    s.release()
    plain = load_protocol(REPO_PROTOCOLS / "calibration-fe.yaml", results_root=ws / "results")
    s = Session(plain, SessionOptions(participant="P02", results_root=ws / "results",
                                      tracker="iohub", dry_run=True, window_size=(480, 270)))
    with pytest.raises(FovexpError, match="--tracker-config FILE .* or tracker.iohub_config"):
        s.iohub_config_path()
    s.release()


REPO_PROTOCOLS = Path(__file__).resolve().parents[3] / "protocols"


def test_tracker_config_only_with_iohub(tmp_path: Path) -> None:
    from experiment_helpers import make_workspace, run_cli

    ws = make_workspace(tmp_path / "c")
    r = run_cli(["run", "calibration-fe", "--participant", "P01", "--dry-run",
                 "--tracker-config", "x.yaml"], cwd=ws)
    assert r.returncode == 2 and "--tracker-config is for --tracker iohub" in r.stderr
