"""The calibration screens drawn by the real PsychoPy window under Xvfb at the paper's 3840x2160
(issue 9, section 4): the target centred exactly where the flow says, the head box, the result
plot in the eyes' colours, the quit confirmation over the screen it interrupts, the operator's
between-trial keys, and a whole dry-run calibration, validation and drift check through the
window."""

from __future__ import annotations

import numpy as np
import pytest

from fovexp import load_display
from fovexp.experiment.protocol.defaults import QualityLimits
from fovexp.experiment.trackers.calibration import (
    CalibrationFlow,
    CalibrationTiming,
    DriftCheck,
    HeadBoxView,
    ResultPoint,
    ResultView,
    SimulatedCalibration,
    TargetView,
    TextView,
)
from fovexp.experiment.trackers.gaze import DisplayArea, FixationGeometry
from fovexp.experiment.trackers.quality import target_points
from fovexp.experiment.trackers.simulated import SimulatedGaze

from experiment_helpers import xvfb_display  # noqa: F401

pytestmark = [pytest.mark.gui, pytest.mark.slow]

W, H = 3840, 2160
LG = load_display("lg-oled55cx")
FIX = FixationGeometry(LG)
PPD = FIX.ppd_centre  # the window is the profile's size


@pytest.fixture(scope="module")
def screen(xvfb_display):  # noqa: F811
    from fovexp.experiment.display.window import PsychoScreen

    s = PsychoScreen((W, H), fullscreen=False, cross_px=20, dry_run=True)
    assert tuple(s.win.size) == (W, H)
    s.capture = True
    yield s
    s.close()


def frame(screen, view) -> np.ndarray:
    keys = screen.calibration_frame(view)
    assert keys == []
    return np.asarray(screen.last_frame)[..., :3].astype(int)


def test_target_is_centred_exactly_on_its_point(screen) -> None:
    """Thaler's ABC target at a calibration point: a dark disc of the given diameter, light
    cross arms, dark centre, centred on the point's pixel to within a pixel, on Titta's grey."""
    x, y = 0.3, 0.7
    back, front = 1.2 * PPD, 0.12 * PPD
    f = frame(screen, TargetView((x, y), back, front))
    grey = f[10, 10]
    assert abs(int(grey[0]) - 128) <= 2  # mid grey background
    dark = (f.sum(axis=2) < 60)
    ys, xs = np.nonzero(dark)
    cx, cy = x * W - 0.5, y * H - 0.5
    assert xs.mean() == pytest.approx(cx, abs=1.0) and ys.mean() == pytest.approx(cy, abs=1.0)
    assert (xs.max() - xs.min() + 1) == pytest.approx(back, abs=2)  # the disc's diameter
    ring = f[int(round(cy)), int(round(cx + back / 4))]  # on the cross's horizontal arm
    assert ring.min() > 200
    centre = f[int(round(cy)), int(round(cx))]
    assert centre.max() < 60  # the dark centre dot


def test_head_box_and_quit_confirmation(screen) -> None:
    ok = HeadBoxView(((0.45, 0.5), (0.55, 0.5)), 1.0, 715.0, True, "Position is good.",
                     "Space: start")
    f = frame(screen, ok)
    green = (f[..., 1] > 150) & (f[..., 0] < 100)
    assert green.sum() > 1000  # the box outline in green when the position is right
    bad = HeadBoxView(((0.45, 0.5), (0.55, 0.5)), 1.3, 550.0, False, "too close", "Space")
    f = frame(screen, bad)
    assert ((f[..., 0] > 200) & (f[..., 1] < 130) & (f[..., 2] < 60)).sum() > 1000  # red: not right
    plain = frame(screen, TextView("Computing the calibration ...", ""))
    confirm = frame(screen, TextView("Quit the session?", "Y: quit    N: go back", bad))
    # the interrupted screen shows dimmed behind the question
    assert not np.array_equal(confirm, plain)


def test_result_plot_shows_samples_in_the_eyes_colours(screen) -> None:
    from fovexp.experiment.display.window import EYE_COLOURS

    left = [(0.705 + 0.001 * i, 0.3) for i in range(20)]
    right = [(0.7, 0.31 + 0.001 * i) for i in range(20)]
    pts = [ResultPoint(1, (0.5, 0.5), {"left": [], "right": []}, {"left": None, "right": None},
                       "L - R -", False),
           ResultPoint(2, (0.7, 0.3), {"left": left, "right": right},
                       {"left": (0.7145, 0.3), "right": (0.7, 0.3195)}, "L 0.10 R 0.20", True)]
    view = ResultView("Validation", "validation", pts, "text", "Space: accept", True,
                      1.25 * PPD, 0.35 * PPD)
    f = frame(screen, view)

    def colour_at(x, y):
        return f[int(round(y * H - 0.5)), int(round(x * W - 0.5))]

    want_l = (np.array(EYE_COLOURS["left"]) + 1) * 127.5
    want_r = (np.array(EYE_COLOURS["right"]) + 1) * 127.5
    assert np.abs(colour_at(*left[5]) - want_l).max() < 40
    assert np.abs(colour_at(*right[5]) - want_r).max() < 40
    # the same view object is drawn from the stimuli built for it the first time
    stims = screen._plot[1]
    frame(screen, view)
    assert screen._plot[1] is stims


def test_operator_keys_are_noticed_on_any_screen(screen) -> None:
    from pyglet.window import key as pkey  # after the window: importing it needs the display

    screen.take_operator_keys()
    screen.win.winHandle.dispatch_event("on_key_press", pkey.D, 0)
    screen.win.winHandle.dispatch_event("on_key_press", pkey.X, 0)
    assert screen.take_operator_keys() == {"d"}
    assert screen.take_operator_keys() == set()
    screen.win.winHandle.dispatch_event("on_key_press", pkey.C, 0)
    assert screen.take_operator_keys() == {"c"}


def test_dry_run_calibration_and_drift_check_through_the_window(screen) -> None:
    """The whole flow in the 4K window with simulated gaze, answering itself as a dry run."""
    gaze = SimulatedGaze(FIX, seed=5)
    gaze.start()
    area = DisplayArea.nominal(LG)
    flow = CalibrationFlow(SimulatedCalibration(gaze), target_points(9), target_points(5),
                           QualityLimits(), area, 715.0, 600.0, (W, H), PPD, 1.25,
                           timing=CalibrationTiming.dry_run(), look_at=gaze.look_at, auto=True)
    drift = DriftCheck(area, 715.0, 600.0, (W, H), PPD, 0.5, 0.2,
                       timing=CalibrationTiming.dry_run(), look_at=gaze.look_at, auto=True)
    screen.capture = False
    try:
        kinds = set()
        for f in (flow, drift):
            f.start(gaze.now_us())
            while not f.finished:
                v = f.view()
                kinds.add(type(v).__name__)
                screen.calibration_frame(v)
                f.feed(gaze.poll())
                f.step([], gaze.now_us())
            f.close()
    finally:
        screen.capture = True
    assert flow.outcome == "accepted" and flow.result.passed
    assert drift.outcome == "ok"
    assert kinds >= {"HeadBoxView", "TargetView", "ResultView"}
