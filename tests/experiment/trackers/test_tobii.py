"""The Tobii adapter against the real tobii-research package (issue 3, item 4; issue 9,
section 4).

No tracker is attached in CI: the real SDK's search finds none, which must give a clear error.
The stream handling is then exercised with a stand-in for the absent hardware only (an object
with the ``tobii_research.EyeTracker`` methods the adapter calls), fed from a thread at 600 Hz;
its display area is the SDK's own ``DisplayArea``. The SDK's ``ScreenBasedCalibration`` accepts
only a connected ``EyeTracker`` (its calls go straight to the device): the real one is shown to
refuse the stand-in, and the full calibration flow runs with a stand-in for it that returns the
SDK's own result classes.
"""

from __future__ import annotations

import sys
import threading
import time

import numpy as np
import pytest

if sys.version_info[:2] != (3, 10):
    pytest.skip("tobii-research ships Linux wheels for Python 3.10 only", allow_module_level=True)
tr = pytest.importorskip("tobii_research", reason="tobii-research is not installed")

from fovexp import FovexpError  # noqa: E402
from fovexp.experiment.trackers.tobii import TobiiCalibration, TobiiGaze, sample_from_sdk  # noqa: E402

from experiment_helpers import REPO, run_cli  # noqa: E402


class StandInTracker:
    """Replaces only the hardware: the SDK's EyeTracker methods the adapter uses."""

    model = "Tobii Pro Spectrum (stand-in)"
    serial_number = "TEST-0001"
    address = "tobii-prp://TEST-0001"
    device_name = "stand-in"
    firmware_version = "0"
    runtime_version = "0"

    #: the LG OLED55CX's active area (121.8 x 68.5 cm) above a Spectrum, in its user coordinate
    #: system (mm; origin on the tracker, x right, y up, z towards the user)
    AREA = {"top_left": (-609.0, 710.0, 30.0), "top_right": (609.0, 710.0, 30.0),
            "bottom_left": (-609.0, 25.0, 30.0)}
    #: the eyes 71.5 cm in front of the screen's centre
    EYES = ((-31.5, 367.5, 745.0), (31.5, 367.5, 745.0))

    def __init__(self, freqs=(60.0, 120.0, 300.0, 600.0), area=None) -> None:
        self.freqs = freqs
        self.freq = 60.0
        self.subs: dict[str, object] = {}
        self.stop = threading.Event()
        self.area = dict(area or self.AREA)
        self.gaze_at = (0.5, 0.5)  # where the stand-in participant looks

    def get_display_area(self):
        return tr.DisplayArea(self.area)

    def get_all_gaze_output_frequencies(self):
        return self.freqs

    def set_gaze_output_frequency(self, f):
        self.freq = f

    def subscribe_to(self, kind, cb, as_dictionary=False):
        assert as_dictionary
        self.subs[kind] = cb

    def unsubscribe_from(self, kind, cb=None):
        self.subs.pop(kind, None)

    def stream(self, n: int, rate: float, valid=lambda i: (True, True)) -> None:
        cb = self.subs[tr.EYETRACKER_GAZE_DATA]
        t0 = tr.get_system_time_stamp()
        for i in range(n):
            lv, rv = valid(i)
            cb({
                "device_time_stamp": 5_000_000 + int(i * 1e6 / rate),
                "system_time_stamp": t0 + int(i * 1e6 / rate),
                "left_gaze_point_on_display_area": (0.25, 0.75) if lv else (float("nan"),) * 2,
                "left_gaze_point_validity": int(lv),
                "right_gaze_point_on_display_area": (0.26, 0.74) if rv else (float("nan"),) * 2,
                "right_gaze_point_validity": int(rv),
                "left_pupil_diameter": 3.0, "right_pupil_diameter": 3.0,
                "left_gaze_origin_in_user_coordinate_system": self.EYES[0],
                "left_gaze_origin_validity": int(lv),
                "right_gaze_origin_in_user_coordinate_system": self.EYES[1],
                "right_gaze_origin_validity": int(rv),
            })

    def sample(self, t_us: int) -> dict:
        """A sample at the point the stand-in participant looks at."""
        x, y = self.gaze_at
        return {"device_time_stamp": t_us, "system_time_stamp": t_us,
                "left_gaze_point_on_display_area": (x, y), "left_gaze_point_validity": 1,
                "right_gaze_point_on_display_area": (x, y), "right_gaze_point_validity": 1,
                "left_gaze_origin_in_user_coordinate_system": self.EYES[0],
                "left_gaze_origin_validity": 1,
                "right_gaze_origin_in_user_coordinate_system": self.EYES[1],
                "right_gaze_origin_validity": 1}

    def feed_realtime(self) -> None:
        """600 Hz on the SDK's clock until ``stop``: each sample stamped when it is due, and
        the user position guide with it (a thread of its own, as the SDK's)."""
        t0 = tr.get_system_time_stamp()
        sent = 0
        while not self.stop.is_set():
            due = int((tr.get_system_time_stamp() - t0) * 600 / 1e6)
            cb = self.subs.get(tr.EYETRACKER_GAZE_DATA)
            for i in range(sent, due):
                if cb is not None:
                    cb(self.sample(t0 + int(i * 1e6 / 600)))
            sent = max(sent, due)
            guide = self.subs.get(tr.EYETRACKER_USER_POSITION_GUIDE)
            if guide is not None:
                guide({"left_user_position": (0.55, 0.5, 0.5), "left_user_position_validity": 1,
                       "right_user_position": (0.45, 0.5, 0.5),
                       "right_user_position_validity": 1})
            time.sleep(0.002)


class StandInCalibration:
    """Stands in for ``tobii_research.ScreenBasedCalibration`` (which drives the hardware and
    accepts only a connected EyeTracker); its result is made of the SDK's own classes."""

    def __init__(self, tracker) -> None:
        self.points: dict[tuple[float, float], bool] = {}
        self.calls: list[tuple] = []

    def enter_calibration_mode(self):
        self.calls.append(("enter",))

    def leave_calibration_mode(self):
        self.calls.append(("leave",))

    def collect_data(self, x, y):
        time.sleep(0.05)  # the SDK blocks while it collects
        self.calls.append(("collect", x, y))
        self.points[(x, y)] = True
        return tr.CALIBRATION_STATUS_SUCCESS

    def discard_data(self, x, y):
        self.calls.append(("discard", x, y))
        self.points.pop((x, y), None)

    def compute_and_apply(self):
        self.calls.append(("compute",))
        eye = tr.CalibrationEyeData
        pts = tuple(tr.CalibrationPoint((x, y), tuple(
            tr.CalibrationSample(eye((x + 0.002, y), 1), eye((x - 0.002, y), 1))
            for _ in range(4))) for (x, y) in self.points)
        return tr.CalibrationResult(tr.CALIBRATION_STATUS_SUCCESS, pts)


def test_real_sdk_is_importable() -> None:
    assert callable(tr.find_all_eyetrackers)
    assert isinstance(tr.get_system_time_stamp(), int)


def test_no_tracker_gives_a_clear_error() -> None:
    if tr.find_all_eyetrackers():
        pytest.skip("a real Tobii tracker is connected")
    with pytest.raises(FovexpError, match="no Tobii eye tracker found"):
        TobiiGaze()


def test_cli_tobii_without_tracker_stops_before_the_session(tmp_path) -> None:
    if tr.find_all_eyetrackers():
        pytest.skip("a real Tobii tracker is connected")
    r = run_cli(["run", str(REPO / "protocols" / "calibration-fe.yaml"), "--participant", "P01",
                 "--tracker", "tobii", "--results", str(tmp_path), "--window", "480x270"],
                cwd=tmp_path)
    assert r.returncode == 2, r.stderr
    assert "no Tobii eye tracker found" in r.stderr
    assert not list(tmp_path.rglob("session-*.json")) and not list(tmp_path.rglob("*.csv"))
    assert not list(tmp_path.iterdir())  # not even an empty participant folder


def test_sample_conversion_keeps_timestamps_validity_and_origins() -> None:
    s = sample_from_sdk({
        "device_time_stamp": 123, "system_time_stamp": 456,
        "left_gaze_point_on_display_area": (0.1, 0.2), "left_gaze_point_validity": 1,
        "right_gaze_point_on_display_area": (float("nan"), float("nan")),
        "right_gaze_point_validity": 0,
        "left_gaze_origin_in_user_coordinate_system": (-30.0, 350.0, 700.0),
        "left_gaze_origin_validity": 1,
        "right_gaze_origin_in_user_coordinate_system": (float("nan"),) * 3,
        "right_gaze_origin_validity": 0})
    assert (s.device_time_us, s.system_time_us) == (123, 456)
    assert s.left_valid and not s.right_valid and s.point == (0.1, 0.2)
    assert s.left_origin_mm == (-30.0, 350.0, 700.0) and s.right_origin_mm is None


def test_display_area_from_the_sdk_and_the_check() -> None:
    """The SDK's DisplayArea (its own class, corners in mm) against the display profile: the
    stand-in's area is the LG's 121.8 x 68.5 cm; 5 mm narrower is refused with both sizes and
    where to fix it; 2 mm passes."""
    from fovexp import load_display
    from fovexp.experiment.trackers.gaze import check_display_area

    lg = load_display("lg-oled55cx")
    area = TobiiGaze(tracker=StandInTracker()).display_area()
    assert area.source == "tracker" and area.width_mm == pytest.approx(1218.0)
    assert area.height_mm == pytest.approx(685.0)
    assert np.allclose(area.normal, (0, 0, 1)) and area.distance_mm((0, 367.5, 745.0)) == 715.0
    info = check_display_area(area, lg)
    assert info["tracker_mm"] == [1218.0, 685.0] and info["difference_mm"] == [0.0, 0.0]
    narrow = dict(StandInTracker.AREA, top_right=(604.0, 710.0, 30.0))
    with pytest.raises(FovexpError) as err:
        check_display_area(TobiiGaze(tracker=StandInTracker(area=narrow)).display_area(), lg)
    msg = str(err.value)
    assert "1213.0 x 685.0 mm" in msg and "1218.0 x 685.0 mm" in msg
    assert "Eye Tracker Manager" in msg and "\n" not in msg
    close = dict(StandInTracker.AREA, top_right=(607.0, 710.0, 30.0))
    check_display_area(TobiiGaze(tracker=StandInTracker(area=close)).display_area(), lg)


def test_display_area_mismatch_stops_before_any_window(tmp_path) -> None:
    from fovexp.experiment.options import SessionOptions
    from fovexp.experiment.protocol.spec import load_protocol
    from fovexp.experiment.session import Session

    lp = load_protocol(REPO / "protocols" / "calibration-fe.yaml")
    s = Session(lp, SessionOptions(participant="A01", results_root=tmp_path, tracker="tobii",
                                   limit_trials=1, practice_trials=0,
                                   window_size=(480, 270)))  # the scenes the tests generate
    opened = []
    wrong = dict(StandInTracker.AREA, bottom_left=(-609.0, 45.0, 30.0))  # 665 mm high
    with pytest.raises(FovexpError, match=r"665\.0 mm.*685\.0 mm.*displays/lg-oled55cx"):
        s.run(screen_factory=lambda **kw: opened.append(kw),
              gaze=TobiiGaze(frequency_hz=600, tracker=StandInTracker(area=wrong)))
    assert not opened and not list(tmp_path.iterdir())  # no window, nothing written


def test_stream_buffer_rate_and_notifications() -> None:
    dev = StandInTracker()
    # no stall between the streams, however loaded the machine (stalls: the next tests)
    g = TobiiGaze(frequency_hz=600, tracker=dev, stall_s=30.0)
    g.start()
    assert dev.freq == 600 and tr.EYETRACKER_GAZE_DATA in dev.subs
    # 1 s at 600 Hz delivered from another thread while the main thread drains.
    th = threading.Thread(target=dev.stream, args=(600, 600.0, lambda i: (i % 50 != 0, True)))
    th.start()
    got = []
    while th.is_alive():
        got += g.poll()
    th.join()
    got += g.poll()
    assert len(got) == 600
    assert [s.device_time_us for s in got] == sorted(s.device_time_us for s in got)
    assert got[1].device_time_us - got[0].device_time_us == pytest.approx(1e6 / 600, abs=1)
    assert sum(not s.left_valid for s in got) == 12 and all(s.right_valid for s in got)
    assert g.measured_rate_hz() == pytest.approx(600, rel=0.01)
    assert not [e for e in g.poll_events() if e.kind == "rate_deviation"]
    # The tracker drops to 300 Hz: noticed from the timestamps and from the notification.
    dev.subs[tr.EYETRACKER_NOTIFICATION_GAZE_OUTPUT_FREQUENCY_CHANGED](
        {"system_time_stamp": tr.get_system_time_stamp(), "gaze_output_frequency": 300.0})
    dev.stream(600, 300.0)
    g.poll()
    kinds = [e.kind for e in g.poll_events()]
    assert "frequency_changed" in kinds and "rate_deviation" in kinds
    # Connection lost and restored.
    dev.subs[tr.EYETRACKER_NOTIFICATION_CONNECTION_LOST]({"system_time_stamp": 1})
    assert [e.kind for e in g.poll_events()][0] == "connection_lost" and not g.connected
    dev.subs[tr.EYETRACKER_NOTIFICATION_CONNECTION_RESTORED]({"system_time_stamp": 2})
    g.poll_events()
    dev.stream(10, 600.0)
    g.poll()
    assert g.connected
    g.stop()
    assert not dev.subs


def test_stalled_stream_counts_as_disconnected() -> None:
    dev = StandInTracker()
    g = TobiiGaze(frequency_hz=600, tracker=dev, stall_s=0.1)
    g.start()
    dev.stream(10, 600.0)
    g.poll()
    assert g.connected
    time.sleep(0.2)
    assert [e.kind for e in g.poll_events()] == ["stream_stalled"] and not g.connected
    dev.stream(10, 600.0)
    g.poll()
    assert "stream_resumed" in [e.kind for e in g.poll_events()] and g.connected


def test_unsupported_frequency_is_refused() -> None:
    with pytest.raises(FovexpError, match="offers"):
        TobiiGaze(frequency_hz=600, tracker=StandInTracker(freqs=(60.0, 120.0))).start()


def test_session_recovers_from_a_stall_longer_than_the_stall_time(tmp_path) -> None:
    """The tracker stops sending for longer than the stall time, then comes back: the session's
    wait-for-reconnect loop drains the stream, so the real adapter notices the samples again
    and the trial restarts (the samples of the wait go to the gaze log)."""
    from fovexp.experiment.options import SessionOptions
    from fovexp.experiment.protocol.spec import load_protocol
    from fovexp.experiment.records.runlogs import RunLogs
    from fovexp.experiment.session import Session
    from fovexp.experiment.tasks.screens import Screens

    from experiment_helpers import StubScreen

    lp = load_protocol(REPO / "protocols" / "calibration-fe.yaml")
    s = Session(lp, SessionOptions(participant="T01", results_root=tmp_path, tracker="tobii",
                                   limit_trials=1, practice_trials=0, window_size=(480, 270)))
    dev = StandInTracker()
    g = TobiiGaze(frequency_hz=600, tracker=dev, stall_s=0.1)
    g.start()
    t0 = time.monotonic()

    def answer(text, keys, timeout_s):  # the operator would quit after 5 s
        time.sleep(timeout_s or 0)
        return "q" if time.monotonic() - t0 > 5 else None

    s.gaze, s.screen = g, StubScreen((480, 270), answer=answer)
    s.logs = RunLogs(tmp_path, "x", s.fixation)
    dev.stream(60, 600.0)
    g.poll()
    time.sleep(0.4)  # the stream stalls for 4x the stall time
    assert [e.kind for e in g.poll_events()] == ["stream_stalled"] and not g.connected
    stop = threading.Event()

    def feed() -> None:  # the tracker is back after 0.3 s, at 600 Hz
        time.sleep(0.3)
        while not stop.is_set():
            dev.stream(6, 600.0)
            time.sleep(0.01)

    th = threading.Thread(target=feed)
    th.start()
    try:
        # raises Aborted if the stream is never noticed
        Screens(s.screen, s.file, s.live, s._drain_gaze).wait_reconnect(g, s.trials[0].index)
    finally:
        stop.set()
        th.join()
    assert time.monotonic() - t0 < 3 and g.connected
    kinds = [e["event"] for e in s.info["events"]]
    assert kinds[0] == "tracker_disconnected" and kinds[-1] == "tracker_reconnected"
    assert "stream_resumed" in kinds
    s.logs.gaze_log.flush(sync=True)
    rows = (tmp_path / "gaze-x.csv").read_text().splitlines()[1:]
    assert rows and all(r.startswith(",") for r in rows)  # samples between trials
    g.stop()


def test_calibration_error_is_a_failure_the_operator_can_retry(tmp_path) -> None:
    """The real SDK refuses to calibrate the stand-in (it is no EyeTracker): the calibration
    screen shows the failure with the SDK's reason instead of crashing and offers R (calibrate
    again) / S / Q; R once, then Q (confirmed with Y) stops with a message naming the failure,
    and every attempt is in the session file."""
    from fovexp.experiment.options import SessionOptions
    from fovexp.experiment.protocol.spec import load_protocol
    from fovexp.experiment.session import Session
    from fovexp.experiment.trackers.calibration import TextView

    from experiment_helpers import StubScreen

    g = TobiiGaze(frequency_hz=600, tracker=StandInTracker())
    with pytest.raises(ValueError, match="EyeTracker"):
        TobiiCalibration(g).begin()  # the real ScreenBasedCalibration

    lp = load_protocol(REPO / "protocols" / "calibration-fe.yaml")
    s = Session(lp, SessionOptions(participant="C01", results_root=tmp_path, tracker="tobii",
                                   limit_trials=1, practice_trials=0, skip_display_check=True,
                                   window_size=(480, 270)))
    failures: list[str] = []

    def answer(view):
        if isinstance(view, TextView) and view.prompt.startswith("R: calibrate again"):
            failures.append(view.text)
            return ["r"] if len(failures) == 1 else ["q"]  # one retry, then quit
        if isinstance(view, TextView) and view.prompt.startswith("Y: quit"):
            return ["y"]
        return ["space"] if type(view).__name__ == "HeadBoxView" else []

    with pytest.raises(FovexpError, match="calibration failed"):
        s.run(screen_factory=lambda **kw: StubScreen(cal_answer=answer, **kw),
              gaze=TobiiGaze(frequency_hz=600, tracker=StandInTracker()))
    assert len(failures) >= 2 and "ValueError" in failures[0] and "EyeTracker" in failures[0]
    import json

    info = json.loads((s.folder / f"session-{s.session_id}.json").read_text())
    cals = [q["calibration"] for q in info["tracker_quality"]]
    assert len(cals) == 2 and all(c["failed"] and "ValueError" in c["reason"] for c in cals)
    assert info["state"] == "failed" and "calibration failed" in info["failure"]
    assert info["display_area"]["source"] == "tracker"
    assert info["display_area"]["tracker_mm"] == [1218.0, 685.0]


def test_tobii_calibration_validation_and_drift_check(tmp_path) -> None:
    """The whole Tobii path with only the hardware stood in for: the stand-in participant looks
    wherever the calibration screen draws its target, the tracker streams 600 Hz with gaze
    origins from its own thread; the SDK calibration (stand-in, real result classes) collects
    every point on the worker thread, the validation's angles come from the measured origins,
    the session records both and the display area; the operator's D after the first trial
    runs a drift check."""
    import json

    from fovexp.experiment.options import SessionOptions
    from fovexp.experiment.protocol.spec import load_protocol
    from fovexp.experiment.session import Session
    from fovexp.experiment.tasks.trial import Key
    from fovexp.experiment.trackers.calibration import CalibrationTiming, TargetView

    from experiment_helpers import StubScreen

    dev = StandInTracker()
    cals: list[StandInCalibration] = []

    def factory(tracker):
        assert tracker is dev
        cals.append(StandInCalibration(tracker))
        return cals[-1]

    g = TobiiGaze(frequency_hz=600, tracker=dev, calibration_factory=factory)
    lp = load_protocol(REPO / "protocols" / "calibration-fe.yaml")
    fast = CalibrationTiming(move_s_per_width=0.2, shrink_s=0.1, cal_pace_s=0.1,
                             val_pace_s=0.15, collect_s=0.3)  # Titta's take 20 s here
    s = Session(lp, SessionOptions(participant="T02", results_root=tmp_path, tracker="tobii",
                                   limit_trials=2, practice_trials=0, skip_display_check=True,
                                   window_size=(480, 270), calibration_timing=fast))
    targets: list[tuple[float, float]] = []

    def answer(view):
        if isinstance(view, TargetView):
            dev.gaze_at = view.pos  # the participant follows the target
            targets.append(view.pos)
            return []
        dev.gaze_at = (0.5, 0.5)  # ... and the cross otherwise
        if type(view).__name__ == "HeadBoxView":
            if view.distance_mm is None:  # no sample yet
                return []
            assert view.eyes[0] == pytest.approx((0.45, 0.5))  # mirrored: 1 - 0.55
            assert view.distance_mm == pytest.approx(715.0) and view.ok
            return ["space"]
        if type(view).__name__ == "ResultView":
            assert view.passed, view.text
            return ["space"]
        return []

    th = threading.Thread(target=dev.feed_realtime)
    th.start()
    try:
        code = s.run(screen_factory=lambda **kw: StubScreen(
            cal_answer=answer, inputs={3: [Key("return")], 6: [Key("return")]},
            operator_keys={1: {"d"}}, **kw), gaze=g)
    finally:
        dev.stop.set()
        th.join()
    assert code == 0
    cal = cals[0]
    collected = [c[1:] for c in cal.calls if c[0] == "collect"]
    assert sorted(collected) == sorted([
        (0.5, 0.5), (0.3, 0.3), (0.7, 0.3), (0.3, 0.7), (0.7, 0.7),
        (0.5, 0.3), (0.3, 0.5), (0.7, 0.5), (0.5, 0.7)])
    assert cal.calls[0] == ("enter",) and cal.calls[-1] == ("leave",)
    info = json.loads((s.folder / f"session-{s.session_id}.json").read_text())
    q = info["tracker_quality"][0]
    assert q["accepted"] and q["reason"] == "start"
    assert q["calibration"]["status"] == tr.CALIBRATION_STATUS_SUCCESS
    assert len(q["calibration"]["points"]) == 9
    v = q["validation"]
    assert v["passed"] and v["origins"] == "measured gaze origin"
    assert v["central_accuracy_deg"] < 0.05 and v["data_loss"] < 0.1
    assert v["limits"]["max_central_accuracy_deg"] == 0.5
    assert info["display_area"]["source"] == "tracker"
    drift = [e for e in info["events"] if e["event"] == "drift_check"]
    assert len(drift) == 1 and drift[0]["outcome"] == "ok" and drift[0]["why"] == "operator"
    assert drift[0]["checks"][0]["offset_deg"] < 0.05


def test_every_sample_delivered_before_stop_reaches_the_gaze_log(tmp_path) -> None:
    """The tracker streams 600 Hz from its own thread through a whole session, the closing
    "Thank you" screen included: every sample the SDK delivered before the adapter unsubscribed
    is in the gaze log (the buffer is emptied into it when the session ends), in order."""
    import csv

    from fovexp.experiment.options import SessionOptions
    from fovexp.experiment.protocol.spec import load_protocol
    from fovexp.experiment.session import Session
    from fovexp.experiment.tasks.trial import Key

    from experiment_helpers import StubScreen

    class LockedStandIn(StandInTracker):
        """Delivery and unsubscription exclude each other, so 'delivered before stop' is exact."""

        def __init__(self) -> None:
            super().__init__()
            self.lock = threading.Lock()
            self.delivered = 0

        def unsubscribe_from(self, kind, cb=None):
            with self.lock:
                super().unsubscribe_from(kind, cb)

        def feed(self) -> None:
            t0 = tr.get_system_time_stamp()
            while not self.stop.is_set():
                with self.lock:
                    cb = self.subs.get(tr.EYETRACKER_GAZE_DATA)
                    for _ in range(6 if cb else 0):
                        i = self.delivered
                        cb({"device_time_stamp": int(i * 1e6 / 600),
                            "system_time_stamp": t0 + int(i * 1e6 / 600),
                            "left_gaze_point_on_display_area": (0.5, 0.5),
                            "left_gaze_point_validity": 1,
                            "right_gaze_point_on_display_area": (0.5, 0.5),
                            "right_gaze_point_validity": 1})
                        self.delivered += 1
                time.sleep(0.01)

    dev = LockedStandIn()
    g = TobiiGaze(frequency_hz=600, tracker=dev)
    g.validated = False  # no calibration: the stand-in cannot do one (see the test above)
    lp = load_protocol(REPO / "protocols" / "calibration-fe.yaml")
    s = Session(lp, SessionOptions(participant="G01", results_root=tmp_path, tracker="tobii",
                                   limit_trials=1, practice_trials=0, skip_display_check=True,
                                   window_size=(480, 270)))

    def answer(text, keys, timeout_s):  # every message stays up a while (samples keep coming)
        if keys[0] == "q":  # a stall on a busy machine: wait for the stream, do not quit
            time.sleep(timeout_s or 0.0)
            return None
        time.sleep(0.3)
        return keys[0] if keys else None

    th = threading.Thread(target=dev.feed)
    th.start()
    try:
        assert s.run(screen_factory=lambda **kw: StubScreen(
            answer=answer, inputs={3: [Key("return")]}, **kw), gaze=g) == 0
    finally:
        dev.stop.set()
        th.join()
    assert not g._subscribed and dev.delivered > 200
    with open(s.folder / f"gaze-{s.session_id}.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert [int(r["device_time_us"]) for r in rows] == [
        int(i * 1e6 / 600) for i in range(dev.delivered)]
    # the closing screen's samples belong to no trial
    assert rows[-1]["trial_index"] == "" and any(r["trial_index"] == "0" for r in rows)
