"""The Tobii adapter against the real tobii-research package (issue 3, item 4).

No tracker is attached in CI: the real SDK's search finds none, which must give a clear error.
The stream handling is then exercised with a stand-in for the absent hardware only (an object
with the ``tobii_research.EyeTracker`` methods the adapter calls), fed from a thread at 600 Hz.
"""

from __future__ import annotations

import sys
import threading
import time

import pytest

if sys.version_info[:2] != (3, 10):
    pytest.skip("tobii-research ships Linux wheels for Python 3.10 only", allow_module_level=True)
tr = pytest.importorskip("tobii_research", reason="tobii-research is not installed")

from fovexp import FovexpError  # noqa: E402
from fovexp.experiment.tobii import TobiiGaze, sample_from_sdk  # noqa: E402

from experiment_helpers import REPO, run_cli  # noqa: E402


class StandInTracker:
    """Replaces only the hardware: the SDK's EyeTracker methods the adapter uses."""

    model = "Tobii Pro Spectrum (stand-in)"
    serial_number = "TEST-0001"
    address = "tobii-prp://TEST-0001"
    device_name = "stand-in"
    firmware_version = "0"
    runtime_version = "0"

    def __init__(self, freqs=(60.0, 120.0, 300.0, 600.0)) -> None:
        self.freqs = freqs
        self.freq = 60.0
        self.subs: dict[str, object] = {}
        self.stop = threading.Event()

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
            })


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


def test_sample_conversion_keeps_timestamps_and_validity() -> None:
    s = sample_from_sdk({
        "device_time_stamp": 123, "system_time_stamp": 456,
        "left_gaze_point_on_display_area": (0.1, 0.2), "left_gaze_point_validity": 1,
        "right_gaze_point_on_display_area": (float("nan"), float("nan")),
        "right_gaze_point_validity": 0})
    assert (s.device_time_us, s.system_time_us) == (123, 456)
    assert s.left_valid and not s.right_valid and s.point == (0.1, 0.2)


def test_stream_buffer_rate_and_notifications() -> None:
    dev = StandInTracker()
    g = TobiiGaze(frequency_hz=600, tracker=dev)
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
    from fovexp.experiment.logs import GAZE_COLUMNS, BatchLog
    from fovexp.experiment.protocol import load_protocol
    from fovexp.experiment.session import Session, SessionOptions

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
    s.gaze_log = BatchLog(tmp_path / "gaze.csv", GAZE_COLUMNS)
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
        s._wait_reconnect(s.trials[0])  # raises Aborted if the stream is never noticed
    finally:
        stop.set()
        th.join()
    assert time.monotonic() - t0 < 3 and g.connected
    kinds = [e["event"] for e in s.info["events"]]
    assert kinds[0] == "tracker_disconnected" and kinds[-1] == "tracker_reconnected"
    assert "stream_resumed" in kinds
    s.gaze_log.flush(sync=True)
    rows = (tmp_path / "gaze.csv").read_text().splitlines()[1:]
    assert rows and all(r.startswith(",") for r in rows)  # samples between trials
    g.stop()


def test_calibration_error_is_a_failure_the_operator_can_retry(tmp_path) -> None:
    """The real SDK refuses a calibration (here: the stand-in is no EyeTracker): the adapter
    reports a failed calibration with the SDK's reason instead of crashing, and the session
    offers R (recalibrate) / Q; Q stops with a message naming the failure."""
    from fovexp.experiment.protocol import load_protocol
    from fovexp.experiment.session import Session, SessionOptions

    from experiment_helpers import StubScreen

    g = TobiiGaze(frequency_hz=600, tracker=StandInTracker())
    cal = g.calibrate([(0.5, 0.5)], lambda x, y: None)
    assert cal["failed"] and "ValueError" in cal["reason"] and "EyeTracker" in cal["reason"]

    lp = load_protocol(REPO / "protocols" / "calibration-fe.yaml")
    s = Session(lp, SessionOptions(participant="C01", results_root=tmp_path, tracker="tobii",
                                   limit_trials=1, practice_trials=0, skip_display_check=True,
                                   window_size=(480, 270)))
    prompts: list[str] = []

    def answer(text, keys, timeout_s):
        if keys == ["r", "q"]:
            prompts.append(text)
            return "r" if len(prompts) == 1 else "q"  # one retry, then quit
        return keys[0] if keys else None

    with pytest.raises(FovexpError, match="calibration failed"):
        s.run(screen_factory=lambda **kw: StubScreen(answer=answer, **kw),
              gaze=TobiiGaze(frequency_hz=600, tracker=StandInTracker()))
    assert len(prompts) == 2 and all("R: recalibrate" in p for p in prompts)
    import json

    info = json.loads((s.folder / f"session-{s.session_id}.json").read_text())
    assert [q["calibration"]["failed"] for q in info["tracker_quality"]] == [True, True]
    assert info["state"] == "failed"


def test_every_sample_delivered_before_stop_reaches_the_gaze_log(tmp_path) -> None:
    """The tracker streams 600 Hz from its own thread through a whole session, the closing
    "Thank you" screen included: every sample the SDK delivered before the adapter unsubscribed
    is in the gaze log (the buffer is emptied into it when the session ends), in order."""
    import csv

    from fovexp.experiment.protocol import load_protocol
    from fovexp.experiment.session import Session, SessionOptions
    from fovexp.experiment.trial import Key

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
        if keys == ["q"]:  # a stall on a busy machine: wait for the stream, do not quit
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
