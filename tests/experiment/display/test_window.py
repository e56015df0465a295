"""The PsychoPy shell under Xvfb (real windows, no PsychoPy mocks): what is drawn, black frames
exactly when the gaze crosses 1.25 deg, blanking episodes in the logs, a tracker that disconnects
mid-session, and the display check."""

from __future__ import annotations

import csv
import json
import math
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from fovexp import load_display
from fovexp.experiment.options import SessionOptions
from fovexp.experiment.protocol.spec import load_protocol
from fovexp.experiment.records.logs import read_trials
from fovexp.experiment.session import Session
from fovexp.experiment.tasks.trial import Key, Wheel
from fovexp.experiment.trackers.gaze import BlankingMonitor, FixationGeometry
from fovexp.experiment.trackers.simulated import SimGazeParams, SimulatedGaze

from experiment_helpers import (  # noqa: F401
    REPO,
    ScriptedGaze,
    make_workspace,
    run_cli,
    x_key,
    xvfb_display,
)

pytestmark = [pytest.mark.gui]

W, H = 480, 270
CROSS = 12


@pytest.fixture()
def screen(xvfb_display):  # noqa: F811
    from fovexp.experiment.display.window import PsychoScreen

    s = PsychoScreen((W, H), fullscreen=False, cross_px=CROSS, dry_run=True)
    s.capture = True
    yield s
    s.close()


def outside_cross(frame: np.ndarray) -> np.ndarray:
    mask = np.ones(frame.shape[:2], bool)
    mask[H // 2 - CROSS:H // 2 + CROSS, W // 2 - CROSS:W // 2 + CROSS] = False
    return frame[mask]


def test_split_screen_is_drawn_as_given(screen) -> None:
    rng = np.random.default_rng(0)
    left = rng.uniform(0, 1, (H, W // 2, 3)).astype(np.float32)
    right = rng.uniform(0, 1, (H, W // 2, 3)).astype(np.float32)
    screen.set_reference(left)
    screen.set_test(right)
    screen.draw(blank=False)
    f = screen.last_frame.astype(float) / 255
    expect = np.concatenate([left, right], axis=1)
    diff = np.abs(f - expect)
    diff[H // 2 - CROSS:H // 2 + CROSS, W // 2 - CROSS:W // 2 + CROSS] = 0
    # Display-encoded values go to the screen unchanged: no gamma, no flip, no resampling.
    assert diff.max() <= 1.5 / 255
    assert screen.last_frame[H // 2, W // 2, 0] == 255  # the red cross on the seam


def test_a_mirrored_split_screen_is_the_whole_frame_mirrored(screen) -> None:
    """The forced-choice task's degraded left half (issue 30): the test half drawn flipped on
    the left, the reference flipped on the right; and back as given."""
    rng = np.random.default_rng(1)
    left = rng.uniform(0, 1, (H, W // 2, 3)).astype(np.float32)
    right = rng.uniform(0, 1, (H, W // 2, 3)).astype(np.float32)
    screen.set_reference(left)
    screen.set_test(right)
    for mirrored in (True, False):
        screen.set_mirrored(mirrored)
        screen.draw(blank=False)
        f = screen.last_frame.astype(float) / 255
        expect = np.concatenate([left, right], axis=1)
        diff = np.abs(f - (expect[:, ::-1] if mirrored else expect))
        diff[H // 2 - CROSS:H // 2 + CROSS, W // 2 - CROSS:W // 2 + CROSS] = 0
        assert diff.max() <= 1.5 / 255


def point_at(fix: FixationGeometry, ecc: float) -> tuple[float, float]:
    lo, hi = 0.0, 0.4
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if fix.eccentricity((0.5 + mid, 0.5)) < ecc:
            lo = mid
        else:
            hi = mid
    return 0.5 + 0.5 * (lo + hi), 0.5


def test_black_frame_exactly_when_gaze_crosses_radius(screen) -> None:
    """Paper section 5.1: the next frame after gaze leaves the 1.25 deg window is black; the
    stimulus is back on the first frame after it returns."""
    fix = FixationGeometry(load_display("lg-oled55cx"))
    eccs = [0.2, 1.0, 1.24, 1.249, 1.2501, 1.26, 2.0, 5.0, 1.251, 1.2499, 0.5, None, 0.5,
            1.3, 1.1]
    clock = [0]
    gaze = ScriptedGaze(lambda t: None if eccs[round(t * 600)] is None
                        else point_at(fix, eccs[round(t * 600)]),
                        rate_hz=600, clock_us=lambda: clock[0])
    gaze.start()
    mon = BlankingMonitor(fix, 1.25)
    img = np.full((H, W // 2, 3), 0.6, np.float32)
    screen.set_reference(img)
    screen.set_test(img)
    for i, e in enumerate(eccs):
        clock[0] = math.ceil(i * 1e6 / 600)  # sample i is due exactly now
        d = mon.update(gaze.poll(), gaze.now_us())
        screen.draw(d.blank)
        shown = outside_cross(screen.last_frame)
        black = e is None or e > 1.25
        if black:
            assert shown.max() == 0, (i, e)
        else:
            assert shown.min() >= 150, (i, e)


def make_session(tmp_path: Path, tracker: str, pid: str, **kw) -> Session:
    lp = load_protocol(REPO / "protocols" / "calibration-fe.yaml")
    opts = SessionOptions(participant=pid, results_root=tmp_path / "results", tracker=tracker,
                          dry_run=True, window_size=(W, H), practice_trials=0,
                          sim_speed=6.0, **kw)
    return Session(lp, opts)


def test_blanking_episodes_are_logged(tmp_path: Path, xvfb_display) -> None:  # noqa: F811
    """Gaze alternates 0.25 s at the cross and 0.25 s 3 deg away: about half the frames are
    black, in episodes of about 0.25 s, and the trial row's blanked_fraction says so."""
    fix = FixationGeometry(load_display("lg-oled55cx"))
    away = point_at(fix, 3.0)
    gaze = ScriptedGaze(lambda t: away if int(t * 4) % 2 else (0.5, 0.5))
    s = make_session(tmp_path, "simulated", "B01", limit_trials=2)
    assert s.run(gaze=gaze) == 0
    rows, _ = read_trials(s.folder / "trials.csv")
    assert len(rows) == 2
    with open(s.folder / f"blanking-{s.session_id}.csv") as fh:
        eps = list(csv.DictReader(fh))
    with open(s.folder / f"frames-{s.session_id}.csv") as fh:
        frames = list(csv.DictReader(fh))
    for r in rows:
        assert 0.25 <= r["blanked_fraction"] <= 0.75
        mine = [e for e in eps if int(e["trial_index"]) == r["trial_index"]]
        assert mine and all(e["reason"] == "outside" for e in mine)
        inner = [float(e["end_s"]) - float(e["start_s"]) for e in mine[1:-1]]
        # an episode starts and ends on the first frame after the gaze moved: each is off by
        # at most the longest frame interval (which a busy 2-core machine stretches); their
        # median is not
        longest = max(float(f["interval_s"]) for f in frames
                      if f["interval_s"] and int(f["trial_index"]) == r["trial_index"])
        assert inner and abs(float(np.median(inner)) - 0.25) < 0.05, inner
        assert all(abs(d - 0.25) <= longest + 0.02 for d in inner), (inner, longest)


class FlakyGaze(SimulatedGaze):
    """Simulated gaze whose 'tracker' disconnects once for 0.6 s, 40 polls into the second
    trial (by then its frame loop runs: the first render takes a few polls at most)."""

    session: Session | None = None

    def __init__(self, *a, **kw) -> None:
        super().__init__(*a, **kw)
        self.polls = 0
        self.dropped = False

    def poll(self):
        if self.session is not None and len(self.session.done) == 1:
            self.polls += 1
        if self.polls == 40 and not self.dropped:
            self.dropped = True
            self.set_connected(False)
            threading.Timer(0.6, self.set_connected, args=(True,)).start()
        return super().poll()


def test_tracker_disconnect_blanks_pauses_and_loses_nothing(tmp_path: Path,
                                                            xvfb_display) -> None:  # noqa: F811
    fix = FixationGeometry(load_display("lg-oled55cx"))
    gaze = FlakyGaze(fix, seed=3, params=SimGazeParams(saccade_rate=0, blink_rate=0,
                                                       dropout_prob=0))
    s = make_session(tmp_path, "simulated", "D01", limit_trials=3)
    s.opts.sim_speed = 1.5  # long trials, so the drop lands inside one
    gaze.session = s
    assert s.run(gaze=gaze) == 0
    assert gaze.dropped
    rows, _ = read_trials(s.folder / "trials.csv")
    assert [r["trial_index"] for r in rows] == [0, 1, 2]
    info = json.loads((s.folder / f"session-{s.session_id}.json").read_text())
    kinds = [e["event"] for e in info["events"]]
    assert "tracker_disconnected" in kinds and "tracker_reconnected" in kinds
    assert info["completed"] is True
    i = kinds.index("tracker_disconnected")
    assert info["events"][i]["trial_index"] == 1
    # Trial 1 ran twice: an interrupted attempt, no stimulus frame while disconnected (the
    # pause message instead), then the restarted trial, logged once.
    with open(s.folder / f"frames-{s.session_id}.csv") as fh:
        frames = [f for f in csv.DictReader(fh) if int(f["trial_index"]) == 1]
    assert sum(f["frame"] == "0" for f in frames) == 2
    # the two attempts are told apart, the interrupted one's frames kept
    first = [f for f in frames if f["attempt"] == "0"]
    second = [f for f in frames if f["attempt"] == "1"]
    assert first and second and len(first) + len(second) == len(frames)
    # The disconnection lasts 0.6 s (FlakyGaze's threading.Timer, which cannot fire early);
    # the last frame before it was flipped one loop iteration before the drop (a frame, 17 ms
    # under Xvfb): 0.5 s leaves 100 ms for a loaded machine, and a run that did not pause has
    # gaps of a frame
    t = np.array([float(f["flip_time_s"]) for f in frames])
    assert np.diff(t).max() >= 0.5
    assert all(math.isfinite(v) for v in t)
    # the gaze of the interrupted attempt is logged too; none while disconnected (0.6 s)
    with open(s.folder / f"gaze-{s.session_id}.csv") as fh:
        gaze_rows = list(csv.DictReader(fh))
    t_us = np.array([int(r["system_time_us"]) for r in gaze_rows])
    assert np.all(np.diff(t_us) > 0)
    assert np.diff(t_us).max() >= 0.5e6  # the same 0.6 s pause in the gaze samples
    cut = int(np.argmax(np.diff(t_us)))  # the disconnection
    assert any(r["trial_index"] == "1" for r in gaze_rows[:cut + 1])  # attempt 0's samples
    assert any(r["trial_index"] == "1" for r in gaze_rows[cut + 1:])  # attempt 1's


def test_display_check_stops_the_session(tmp_path: Path, xvfb_display) -> None:  # noqa: F811
    ws = make_workspace(tmp_path / "ws")
    r = run_cli(["run", "protocols/calibration-fe.yaml", "--participant", "P01", "--tracker",
                 "simulated", "--windowed", "--window", f"{W}x{H}"], cwd=ws)
    assert r.returncode == 2
    err = [ln for ln in r.stderr.splitlines() if "error" in ln]
    assert len(err) == 1 and "display check failed" in err[0]
    assert "3840x2160" in err[0] and "--skip-display-check" in err[0]
    assert not list((ws / "results").rglob("session-*.json"))


def press(screen, symbol, modifiers: int = 0) -> None:
    """A key press through pyglet's event dispatch, as the X server would deliver it."""
    screen.win.winHandle.dispatch_event("on_key_press", symbol, modifiers)


def test_wheel_and_modifier_and_keys(screen) -> None:
    from pyglet.window import key

    screen.poll_input()
    win = screen.win.winHandle
    win.dispatch_event("on_mouse_scroll", W // 2, H // 2, 0, 2)
    assert screen.poll_input() == [Wheel(2, False)]
    press(screen, key.LSHIFT)  # held: fine steps
    win.dispatch_event("on_mouse_scroll", W // 2, H // 2, 0, -1)
    assert screen.poll_input() == [Wheel(-1, True)]
    win.dispatch_event("on_key_release", key.LSHIFT, 0)
    x_key(screen, "Return")
    x_key(screen, "Escape")
    time.sleep(0.05)
    assert screen.poll_input() == [Key("return"), Key("escape")]


def test_keys_carry_their_press_time(screen) -> None:
    """Issue 18: a key carries the time it went down (PsychoPy's Keyboard with the 'ptb'
    backend: psychtoolbox with libjack; or 'iohub'), on the flips' clock, not the time of the
    poll that saw it: the press comes after it was sent and well before the poll, whether the
    key is still down or already released at the poll, and a press is reported once."""
    kb = screen.info()["keyboard"]
    assert kb["key_time"] == "press", (
        f"keys are stamped at the poll (backend {kb['backend']!r}): psychtoolbox needs "
        "libjack (apt-get install libjack-jackd2-0)")
    screen.poll_input()
    sent = x_key(screen, "Return")
    time.sleep(0.3)
    polled = time.monotonic()
    got = screen.poll_input()
    assert got == [Key("return")]
    t = got[0].t_s
    assert t is not None and sent < t < polled - 0.25, (sent, t, polled)
    assert screen.poll_input() == []  # reported once, not again at its release
    # the press time is on the flips' clock: between the flips around it
    before = screen.draw(blank=True).flip_s
    x_key(screen, "Escape")
    after = screen.draw(blank=True).flip_s
    time.sleep(0.05)
    (esc,) = screen.poll_input()
    assert esc == Key("escape") and before < esc.t_s < after + 0.05


def test_a_key_that_answers_a_message_is_not_an_operator_request(screen) -> None:
    """C confirms the display checklist and is also the operator's between-trial
    "recalibrate": the press that answered the message must not also recalibrate after the
    first trial; a C pressed on any other screen still counts."""
    from pyglet.window import key

    screen.take_operator_keys()
    # pressed while the message is up (it reads the key buffer it cleared on opening)
    threading.Timer(0.3, press, args=(screen, key.C)).start()
    assert screen.message("checklist", ["c"], 5.0) == "c"
    assert screen.take_operator_keys() == set()
    press(screen, key.C)
    press(screen, key.D)
    assert screen.message("instructions", ["space"], 0.05) is None
    assert screen.take_operator_keys() == {"c", "d"}


class EscapeGaze(SimulatedGaze):
    """The operator presses Escape during the second trial, then Q on the pause screen."""

    session: Session | None = None

    def __init__(self, *a, **kw) -> None:
        super().__init__(*a, **kw)
        self.polls = 0
        self.pressed = False

    def poll(self):
        s = self.session
        if s is not None and len(s.done) == 1:
            self.polls += 1
        if self.polls == 30 and not self.pressed:
            from pyglet.window import key

            self.pressed = True
            x_key(s.screen, "Escape")  # through the X server: the trial's keyboard
            # Q arrives while the pause message is up (its loop reads the key buffer).
            threading.Timer(0.5, press, args=(s.screen, key.Q)).start()
        return super().poll()


def test_escape_pauses_and_q_aborts_safely(tmp_path: Path, xvfb_display) -> None:  # noqa: F811
    fix = FixationGeometry(load_display("lg-oled55cx"))
    gaze = EscapeGaze(fix, seed=4)
    s = make_session(tmp_path, "simulated", "E01", limit_trials=4)
    s.opts.sim_speed = 1.5
    gaze.session = s
    assert s.run(gaze=gaze) == 3  # aborted by the operator
    assert gaze.pressed
    rows, _ = read_trials(s.folder / "trials.csv")
    assert [r["trial_index"] for r in rows] == [0]
    info = json.loads((s.folder / f"session-{s.session_id}.json").read_text())
    assert info["state"] == "aborted" and info["completed"] is False
    kinds = [e["event"] for e in info["events"]]
    assert kinds[-2:] == ["paused", "aborted"]
    # The aborted session resumes at trial 1.
    s2 = make_session(tmp_path, "simulated", "E01", limit_trials=4, resume=True)
    assert s2.session_id == s.session_id and [t.index for t in s2.remaining] == [1, 2, 3]
