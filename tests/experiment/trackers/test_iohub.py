"""ioHub for real (issue 22): its server process with the MouseGaze tracker under Xvfb (the
shipped example configuration, issue 32), the pointer moved by the test with xdotool. Samples
follow the pointer on PsychoPy's clock; a killed server is a lost tracker, started again (or
one clear line); a session through it keeps the blanking rule and logs what was on screen; a
missing plugin and a tracker that is not there stop before any window. The conversions
without a server: test_iohub_format.py; the examples and the checks before the server:
test_iohub_examples.py."""

from __future__ import annotations

import csv
import json
import os
import shutil
import signal
import subprocess
import time
from pathlib import Path

import pytest

from fovexp import FovexpError, load_display
from fovexp.results.blanking import BlankingRule
from fovexp.results.frames import final_value_violations, read_frame_log, unblanked_violations

from experiment_helpers import make_workspace, popen_cli, run_cli, xvfb_display  # noqa: F401

pytestmark = [pytest.mark.gui]

LG = load_display("lg-oled55cx")
#: the MouseGaze configuration: the shipped example (``fovexp tracker example mousegaze``), in
#: PsychoPy Builder's form (its ioConfig as YAML), so that these tests run it through ioHub
MOUSEGAZE = "example:mousegaze"


def _example_rates() -> tuple[float, float]:
    from fovexp.experiment.trackers.families import load_iohub_config

    cfg = load_iohub_config(MOUSEGAZE)
    assert cfg.sampling_hz is not None
    return cfg.sampling_hz, float(cfg.tracker["device_timer"]["interval"])


#: the example's nominal rate (Hz) and the server's polling interval of the pointer (s)
RATE_HZ, TIMER_S = _example_rates()


def xdotool(*args: str) -> None:
    if shutil.which("xdotool") is None:
        pytest.skip("xdotool is not installed (apt-get install xdotool; .ci/run installs it)")
    subprocess.run(["xdotool", *args], check=True, timeout=10)


@pytest.fixture
def mousegaze(xvfb_display):  # noqa: F811
    from fovexp.experiment.trackers.families import load_iohub_config
    from fovexp.experiment.trackers.iohub import IoHubGaze

    made = []

    def make(**kw):
        g = IoHubGaze(load_iohub_config(MOUSEGAZE), LG, 0, **kw)
        made.append(g)
        return g

    yield make
    for g in made:
        g.stop()


def wait_for(gaze, pred, timeout_s=3.0):
    """Samples until one satisfies ``pred``; all those polled, and the first that did."""
    got = []
    t_end = time.monotonic() + timeout_s
    while time.monotonic() < t_end:
        for s in gaze.poll():
            got.append(s)
            if pred(s):
                return got, s
        time.sleep(0.002)
    raise AssertionError(f"no such sample in {timeout_s} s ({len(got)} others)")


@pytest.mark.slow
def test_samples_follow_the_pointer_on_psychopys_clock(mousegaze) -> None:
    """The pointer moved to known pixels: the samples say where, normalised (the whole 1280x720
    screen: no window attached); their system_time_us is PsychoPy's clock in microseconds (the
    first sample at the new place is stamped after the move and at most one sample period plus
    the server's polling interval after it, never after it was read); device time equals it
    (MouseGaze's clock is PsychoPy's); 250 Hz measured within 2 %."""
    from psychopy import core

    from fovexp.experiment.trackers.iohub import system_time_us

    g = mousegaze()
    assert g.display_px == (1280, 720) and g.eyes == ("right",) and g.name == "mouse"
    g.start()
    # the pointer away from every target first: a pointer already at one (the screen's
    # centre, where an earlier test may have left it) would match a sample from before the move
    xdotool("mousemove", "100", "100")
    wait_for(g, lambda s: s.right_valid and abs(s.right_x - 100 / 1280) < 1e-9)
    for px, py in ((640, 360), (960, 180), (320, 540)):
        t_move = system_time_us(core.monotonicClock.getTime())
        xdotool("mousemove", str(px), str(py))
        _, s = wait_for(g, lambda s, px=px, py=py: s.right_valid
                        and abs(s.right_x - px / 1280) < 1e-9 and abs(s.right_y - py / 720) < 1e-9)
        t_read = g.now_us()
        assert (s.right_x, s.right_y) == pytest.approx((px / 1280, py / 720), abs=1e-12)
        assert not s.left_valid and s.point == (s.right_x, s.right_y)
        assert s.device_time_us == s.system_time_us
        assert t_move - 1e6 / RATE_HZ <= s.system_time_us <= t_read
        # xdotool's own start-up is in the gap; the sample period and polling bound the rest
        assert s.system_time_us - t_move <= 1e6 * (1 / RATE_HZ + TIMER_S) + 60_000
    g.poll()
    t0 = time.monotonic()
    samples = []
    while time.monotonic() - t0 < 1.0:
        samples += g.poll()
        time.sleep(0.01)
    m = g.measured()
    assert m["rate_hz"] == pytest.approx(RATE_HZ, rel=0.02) and m["gaps"] == 0
    assert len(samples) == pytest.approx(RATE_HZ, rel=0.1)
    assert g.connected and g.poll_events() == []
    info = g.info()
    assert info["family"] == "mousegaze" and info["model"] == "MouseGaze"
    assert info["plugin"] == "psychopy (built in)" and info["nominal_rate_hz"] == RATE_HZ


@pytest.mark.slow
def test_killed_server_is_a_lost_tracker_then_started_again(mousegaze) -> None:
    """SIGKILL to the server: the source says disconnected within 0.5 s (one unanswered
    request, 0.1 s, plus a loaded machine's scheduling; the frame loop then blanks and ends
    the attempt; the gaze timeout has blanked the stimulus already), with the reason; the
    server is started again and samples flow again (the trial restarts)."""
    g = mousegaze()
    g.start()
    wait_for(g, lambda s: True)
    pid = g.server_pid
    t_kill = time.monotonic()
    os.kill(pid, signal.SIGKILL)
    events = []
    while g.connected:
        events += g.poll_events()
        assert time.monotonic() - t_kill < 0.5, "the lost server was not noticed in 0.5 s"
        time.sleep(0.002)
    t_end = time.monotonic() + 5  # the reader thread notes why (the frame loop saw it first)
    while not any(e.kind == "connection_lost" for e in events) and time.monotonic() < t_end:
        events += g.poll_events()
        time.sleep(0.005)
    lost = [e for e in events if e.kind == "connection_lost"]
    assert lost and f"(pid {pid}) exited (killed by signal 9)" in lost[0].detail["reason"]
    t_end = time.monotonic() + 30
    while not g.connected and time.monotonic() < t_end:
        events += g.poll_events()
        time.sleep(0.01)
    assert g.connected, [e.kind for e in events]
    assert [e.kind for e in events][-1] == "connection_restored" and g.server_pid != pid
    wait_for(g, lambda s: True)  # samples again
    assert g.measured()["server_restarts"] == 1


@pytest.mark.slow
def test_the_trackers_own_status_is_a_lost_tracker(mousegaze) -> None:
    """The tracker says it is not connected (MouseGaze's connection to ioHub's mouse cut, as a
    tracker's own status would say): lost, with the reason; connected again: back."""
    g = mousegaze()
    g.start()
    wait_for(g, lambda s: True)
    with g._lock:
        g.tracker.setConnectionState(False)
    events: list = []
    t_end = time.monotonic() + 5
    while g.connected and time.monotonic() < t_end:
        events += g.poll_events()
        time.sleep(0.005)
    assert not g.connected
    lost = [e for e in events if e.kind == "connection_lost"]
    assert lost and lost[0].detail["reason"] == "the tracker reports it is not connected"
    with g._lock:
        g.tracker.setConnectionState(True)
    t_end = time.monotonic() + 5
    while not g.connected and time.monotonic() < t_end:
        events += g.poll_events()
        g.poll()
        time.sleep(0.005)
    assert g.connected and events[-1].kind in ("connection_restored", "stream_resumed")


@pytest.mark.slow
def test_killed_server_that_does_not_come_back_is_one_line(mousegaze) -> None:
    g = mousegaze(restarts=0)
    g.start()
    wait_for(g, lambda s: True)
    pid = g.server_pid
    os.kill(pid, signal.SIGKILL)
    t_end = time.monotonic() + 5
    with pytest.raises(FovexpError) as e:
        while time.monotonic() < t_end:
            g.poll_events()
            time.sleep(0.01)
    msg = str(e.value)
    assert f"the ioHub server (pid {pid}) exited (killed by signal 9)" in msg
    assert "did not start again" in msg and "saved" in msg and "\n" not in msg


def _write(ws: Path, name: str, text: str) -> Path:
    p = ws / name
    p.write_text(text)
    return p


def test_missing_plugin_stops_before_any_window(tmp_path) -> None:
    """A Pupil Labs configuration without its plugin: exit 2, one line naming the extra, no
    window, nothing written."""
    import importlib.util

    if importlib.util.find_spec("psychopy_eyetracker_pupil_labs") is not None:
        pytest.skip("the Pupil Labs plugin is installed here")
    ws = make_workspace(tmp_path / "p")
    cfg = _write(ws, "pupil.yaml", "eyetracker.hw.pupil_labs.pupil_core.EyeTracker: "
                 "{name: tracker}\n")
    r = run_cli(["run", "calibration-fe", "--participant", "P01", "--tracker", "iohub",
                 "--tracker-config", str(cfg), "--results", str(ws / "results"),
                 "--window", "480x270"], cwd=ws, env_update={"DISPLAY": None})
    assert r.returncode == 2
    line = r.stderr.strip().splitlines()[-1]
    assert "pip install 'fovexp[pupil-labs]'" in line and "psychopy-eyetracker-pupil-labs" in line
    assert not any((ws / "results").iterdir())


@pytest.mark.slow
def test_a_tracker_that_is_not_there_is_one_clear_line(tmp_path, xvfb_display) -> None:  # noqa: F811
    """A Gazepoint configuration with its plugin installed but no Gazepoint Control running:
    the server cannot create the tracker; exit 2, one line, before any window."""
    import importlib.util

    if importlib.util.find_spec("psychopy_eyetracker_gazepoint") is None:
        pytest.skip("the Gazepoint plugin is not installed (pip install 'fovexp[gazepoint]')")
    ws = make_workspace(tmp_path / "g")
    cfg = _write(ws, "gp3.yaml", "eyetracker.hw.gazepoint.gp3.EyeTracker: {name: tracker}\n")
    r = run_cli(["run", "calibration-fe", "--participant", "P01", "--tracker", "iohub",
                 "--tracker-config", str(cfg), "--results", str(ws / "results"),
                 "--window", "480x270"], cwd=ws)
    assert r.returncode == 2, r.stderr[-2000:]
    line = [x for x in r.stderr.splitlines() if x.startswith("fovexp run: error:")]
    assert len(line) == 1 and "could not create the Gazepoint GP3" in line[0]
    assert not any((ws / "results").iterdir())


def _rows(path: Path) -> list[dict[str, str]]:
    try:
        with open(path, newline="") as fh:
            return list(csv.DictReader(fh))
    except (OSError, csv.Error):
        return []


def _session(folder: Path) -> dict:
    return json.loads(next(folder.glob("session-*.json")).read_text())


def _window_centre(folder: Path) -> tuple[int, int]:
    left, top, w, h = _session(folder)["tracker"]["window_px"]
    return int(left + w / 2), int(top + h / 2)


def _check_logs(folder: Path) -> tuple[dict, object, list]:
    """The frames log passes the blanking rule and the final_value checks; returns the
    session record, the frames and the trial rows."""
    from fovexp.experiment.records.logs import read_trials

    info = _session(folder)
    sid = info["session"]
    frames = read_frame_log(folder / f"frames-{sid}.csv")
    rows, _ = read_trials(folder / "trials.csv")
    bad = unblanked_violations(frames, BlankingRule())
    assert bad.empty, bad.to_string()
    wrong = final_value_violations(frames, rows)
    assert wrong.empty, wrong.to_string()
    return info, frames, rows


def _start(ws: Path, pid: str, *extra: str):
    return popen_cli(["run", "calibration-fe", "--participant", pid, "--dry-run", "--tracker",
                      "iohub", "--tracker-config", MOUSEGAZE, "--practice", "0",
                      "--results", str(ws / "results"), *extra], cwd=ws)


def _wait_frames(proc, folder: Path, n: int, timeout_s: float = 120) -> list[dict[str, str]]:
    t_end = time.monotonic() + timeout_s
    while time.monotonic() < t_end:
        assert proc.poll() is None, proc.communicate()[1][-3000:]
        logs = list(folder.glob("frames-*.csv"))
        rows = _rows(logs[0]) if logs else []
        if len(rows) >= n:
            return rows
        time.sleep(0.05)
    raise AssertionError("no frames logged")


@pytest.mark.slow
def test_dry_run_session_through_iohub_mousegaze(tmp_path, xvfb_display) -> None:  # noqa: F811
    """A dry run whose gaze is ioHub's MouseGaze: the calibration screen moves the pointer to
    its targets and validates on the real samples; during the trials the test moves the pointer
    3 deg off the cross and back: those frames are black ('outside'), the others show the
    stimulus; the frames log keeps the blanking rule and shows final_value; the trials are
    marked as a dry run's; the session file has the tracker and its measured rate."""
    ws = make_workspace(tmp_path / "d")
    folder = ws / "results" / "calibration-fe" / "M01"
    proc = _start(ws, "M01", "--limit-trials", "3", "--sim-speed", "3")
    try:
        _wait_frames(proc, folder, 5)
        cx, cy = _window_centre(folder)
        from fovexp.experiment.trackers.gaze import FixationGeometry

        off = round(3.0 * FixationGeometry(LG).ppd_centre * 480 / 3840)  # 3 deg in the window
        while proc.poll() is None:  # excursions until the session ends
            xdotool("mousemove", str(cx + off), str(cy))
            time.sleep(0.3)
            xdotool("mousemove", str(cx), str(cy))
            time.sleep(0.6)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err[-3000:]
    info, frames, rows = _check_logs(folder)
    assert len(rows) == 3 and {r["tracker"] for r in rows} == {"simulated"}
    assert (frames["blanked"] == 1).any() and (frames["blanked"] == 0).any()
    sid = info["session"]
    reasons = {r["reason"] for r in _rows(folder / f"blanking-{sid}.csv")}
    assert "outside" in reasons
    shown = frames[frames["blanked"] == 0]
    assert (shown["gaze_ecc_deg"] <= 1.25).all()
    t = info["tracker"]
    assert t["source"] == "iohub" and t["family"] == "mousegaze" and t["eyes"] == ["right"]
    assert t["measured"]["rate_hz"] == pytest.approx(RATE_HZ, rel=0.02)
    assert t["config"]["sha256"] and info["runs"][-1]["tracker"] == "iohub"
    q = info["tracker_quality"][0]
    assert q["accepted"] and q["validation"]["passed"] and q["validation"]["eyes"] == ["right"]
    # the latency is measured on one clock: positive, and within a few frames
    lat = (frames["flip_system_time_us"] - frames["gaze_system_time_us"]).dropna() / 1e3
    assert (lat > 0).all() and lat.median() < 60


@pytest.mark.slow
def test_server_killed_mid_trial(tmp_path, xvfb_display) -> None:  # noqa: F811
    """SIGKILL to the ioHub server during a trial: no stimulus frame from a gaze timeout and a
    frame after the kill on (black at once), the attempt ends, the server is started again and
    the trial restarts; the session completes and its logs keep the rules."""
    ws = make_workspace(tmp_path / "k")
    folder = ws / "results" / "calibration-fe" / "K01"
    proc = _start(ws, "K01", "--limit-trials", "2", "--sim-speed", "2")
    try:
        rows = _wait_frames(proc, folder, 30)
        trial = int(rows[-1]["trial_index"])
        pid = _session(folder)["tracker"]["server_pid"]
        t_kill = time.monotonic()
        os.kill(pid, signal.SIGKILL)
        out, err = proc.communicate(timeout=180)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err[-3000:]
    info, frames, trial_rows = _check_logs(folder)
    assert len(trial_rows) == 2
    kinds = [e["event"] for e in info["events"]]
    lost = [e for e in info["events"] if e["event"] == "connection_lost"]
    assert lost and f"(pid {pid}) exited (killed by signal 9)" in lost[0]["reason"]
    assert kinds.index("connection_lost") < kinds.index("connection_restored")
    assert "tracker_disconnected" in kinds and "tracker_reconnected" in kinds
    late = frames[(frames["flip_time_s"] > t_kill + 0.05 + 2 / 60) & (frames["attempt"] == 0)
                  & (frames["trial_index"] == trial)]
    assert (late["blanked"] == 1).all(), late.to_string()
    attempts = set(frames[frames["trial_index"] == trial]["attempt"])
    assert attempts == {0, 1}  # the interrupted attempt, and the one that counted
    assert info["tracker"]["measured"]["server_restarts"] == 1


def test_orphan_servers_of_killed_sessions_are_stopped(tmp_path) -> None:
    """A session killed with SIGKILL leaves its ioHub server running (holding the tracker and
    ioHub's port): the next start stops servers whose experiment process is gone, and only
    those."""
    import sys

    from fovexp.experiment.trackers.iohub import stop_orphan_servers

    script = tmp_path / "start_iohub_process.py"
    script.write_text("import time\ntime.sleep(60)\n")
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    orphan = subprocess.Popen([sys.executable, str(script), "0.0", "/", "cfg", str(gone.pid)])
    kept = subprocess.Popen([sys.executable, str(script), "0.0", "/", "cfg", str(os.getpid())])
    try:
        time.sleep(0.3)
        stopped = stop_orphan_servers()
        assert orphan.pid in stopped and kept.pid not in stopped
        assert orphan.wait(timeout=5) == -signal.SIGKILL and kept.poll() is None
    finally:
        for p in (orphan, kept):
            if p.poll() is None:
                p.kill()
                p.wait()
