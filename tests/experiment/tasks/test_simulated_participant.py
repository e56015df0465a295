"""The simulated participant of dry runs
(:mod:`fovexp.experiment.tasks.simulated_participant`), and the fixation window it is tested
in."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fovexp import FovexpError, load_display
from fovexp.experiment.tasks.simulated_participant import SimTruth, SimulatedParticipant
from fovexp.experiment.tasks.trial import (
    Key,
    ValueAdjuster,
)
from fovexp.experiment.trackers.gaze import FixationGeometry

DISPLAY = load_display("lg-oled55cx")


# -- simulated participant -------------------------------------------------------------------

@pytest.mark.parametrize(("param", "lo", "hi", "step", "fine", "start"), [
    ("f_e", 0.0, 0.4, 0.02, 0.005, 0.39),
    ("s_k", 0.0, 45.0, 1.5, 0.25, 2.0),
    ("blur_rate", 0.0, 1.5, 0.02, 0.005, 0.0),
])
def test_participant_reaches_noise_free_target(param, lo, hi, step, fine, start) -> None:
    truth = SimTruth()
    p = SimulatedParticipant(truth, seed=3, speed=1.0, noise_scale=0.0)
    adj = ValueAdjuster(lo, hi, step, fine, start)
    target = p.begin(param, "ours", 0.34, 1.9, lo, hi, step, fine)
    assert target == pytest.approx(truth.value(param, "ours", 0.34, 1.9))
    t, overshoot, rt = 0.0, 0.0, None
    while t < 60:
        for ev in p.poll(t, adj.value, True):
            if isinstance(ev, Key):
                rt = t
                break
            adj.apply(ev)
            overshoot = max(overshoot, (adj.value - target) * np.sign(target - start))
        if rt is not None:
            break
        t += 0.01
    assert rt is not None and 1.0 < rt < 30.0
    assert abs(adj.value - target) <= fine / 2 + 1e-9
    assert overshoot >= step - 1e-9  # it overshoots with coarse steps, then corrects


@pytest.mark.parametrize(("start", "expected"), [(0.0, 0.04), (1.49, 1.45)])
def test_quick_participant_confirms_two_steps_from_the_start(start, expected) -> None:
    """``--sim-truth quick`` (a rehearsal): the target is two wheel steps from the trial's
    start (towards the range's inside), whatever the truth and its noise, so that a trial
    renders a handful of steps."""
    truth = SimTruth.named("quick")
    assert truth.quick and SimTruth.named("quick") == truth
    p = SimulatedParticipant(truth, seed=3, speed=4.0, noise_scale=1.0)
    adj = ValueAdjuster(0.0, 1.5, 0.02, 0.005, start)
    assert p.begin("blur_rate", "ours", None, None, 0.0, 1.5, 0.02, 0.005,
                   start=start) == pytest.approx(expected)
    notches, t = 0, 0.0
    while t < 30:
        events = p.poll(t, adj.value, True)
        if any(isinstance(ev, Key) for ev in events):
            break
        for ev in events:
            adj.apply(ev)
            notches += 1
        t += 0.01
    assert t < 30 and abs(adj.value - expected) <= 0.0025 + 1e-9 and notches <= 7


def test_participant_waits_while_blanked() -> None:
    p = SimulatedParticipant(SimTruth(), seed=1, speed=1.0)
    p.begin("f_e", "contrast", 0.34, None, 0, 0.4, 0.02, 0.005)
    assert all(p.poll(t / 10, 0.0, False) == [] for t in range(100))


def test_sim_truth_yaml(tmp_path: Path) -> None:
    f = tmp_path / "truth.yaml"
    f.write_text("sk_slope: -2\nnoise_sd: {s_k: 0.5}\nvalidation_blur_rate: {ours: 0.7}\n"
                 "table: {source: x, rows: [{blur_rate: 0.1, f_e: 0.1, s_k: 10, s_f: 2}, "
                 "{blur_rate: 0.5, f_e: 0.3, s_k: 20, s_f: 3}]}\n")
    t = SimTruth.load(f)
    assert t.value("f_e", "contrast", 0.3, None) == pytest.approx(0.2)
    assert t.value("s_k", "ours", 0.3, 3.5) == pytest.approx(15 - 2 * (3.5 - 2.5))
    assert t.value("blur_rate", "ours", None, None) == 0.7
    f.write_text("sk_slop: 1\n")
    with pytest.raises(FovexpError, match=r"sk_slop=1: Extra inputs are not permitted"):
        SimTruth.load(f)


def test_fixation_window_is_physical_whatever_the_enhancers_model(tmp_path: Path) -> None:
    """The release preset's geometry describes the prototype's screen, not the participant's:
    the 1.25 deg window is still measured on the display profile (here a protocol with
    preset release, whose enhancer geometry is 'release')."""
    import yaml

    from fovexp.experiment.options import SessionOptions
    from fovexp.experiment.protocol.spec import load_protocol
    from fovexp.experiment.session import Session
    from fovexp.geometry import ViewingGeometry

    from experiment_helpers import make_workspace

    ws = make_workspace(tmp_path / "ws")
    path = ws / "protocols" / "calibration-fe.yaml"
    data = yaml.safe_load(path.read_text())
    data["preset"], data["geometry"] = "release", "release"
    path.write_text(yaml.safe_dump(data))
    lp = load_protocol(path)
    assert lp.spec.geometry_model == "release"
    s = Session(lp, SessionOptions(participant="X01", results_root=tmp_path / "results",
                                   window_size=(480, 270)))  # the test session's scenes
    exact = ViewingGeometry.for_image(DISPLAY, DISPLAY.width_px, DISPLAY.height_px, "exact")
    pt = point_at_offset(s.fixation, (0.5, 0.5), 1.25)
    px = exact.gaze_px(pt)
    want = float(exact.eccentricity_deg(np.array(px[0]), np.array(px[1]),
                                        exact.gaze_px((0.5, 0.5))))
    assert want == pytest.approx(1.25, abs=1e-6)
    release = ViewingGeometry.for_image(DISPLAY, DISPLAY.width_px, DISPLAY.height_px, "release")
    rpx = release.gaze_px(pt)
    assert abs(float(release.eccentricity_deg(np.array(rpx[0]), np.array(rpx[1]),
                                              release.gaze_px((0.5, 0.5)))) - 1.25) > 0.1


def point_at_offset(fix: FixationGeometry, target: tuple[float, float], deg: float):
    lo, hi = 0.0, 0.2
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if fix.angle_between((target[0] + mid, target[1]), target) < deg:
            lo = mid
        else:
            hi = mid
    return target[0] + lo, target[1]
