"""Session logic without a window (a stub screen): what is logged is what was on screen, failed
tracker validation, resuming with nothing left, dependency values kept across --resume, and
errors on the render thread as one line."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest
import yaml

from fovexp import FovexpError
from fovexp.experiment.options import SessionOptions
from fovexp.experiment.protocol.spec import load_protocol
from fovexp.experiment.records.logs import read_trials
from fovexp.experiment.session import Session
from fovexp.experiment.tasks.trial import Key, Wheel

from analysis_fixtures import write_study
from experiment_helpers import (
    REPO,
    GreyEnhancer,
    ScriptedGaze,
    StubScreen,
    make_workspace,
    use_enhancer,
)

W, H = 480, 270


class FakeEnhancer(GreyEnhancer):
    """Each render takes 0.2 s (its speed is not under test)."""

    delay_s = 0.2


def options(tmp_path: Path, pid: str, **kw) -> SessionOptions:
    base = dict(participant=pid, results_root=tmp_path / "results", tracker="mouse",
                dry_run=False, window_size=(W, H), practice_trials=0, limit_trials=1,
                skip_display_check=True, fullscreen=False)
    base.update(kw)
    return SessionOptions(**base)


def centre_gaze() -> ScriptedGaze:
    return ScriptedGaze(lambda t: (0.5, 0.5))


@pytest.mark.parametrize("enter_poll", [4, 150])
def test_logged_value_is_the_one_on_screen(tmp_path: Path, monkeypatch, enter_poll: int) -> None:
    """Enter pressed while the render of the last wheel step is still computed (poll 4: a
    render takes 0.2 s): that render is dropped, never shown, and the value on screen is the
    answer. Enter pressed once it is shown (poll 150): its value. Per frame and as
    final_value, what is logged is what was on screen."""
    use_enhancer(monkeypatch, FakeEnhancer)
    GreyEnhancer.instances.clear()
    lp = load_protocol(REPO / "protocols" / "calibration-fe.yaml")
    _, plan = lp.plan("V01", limit=1, practice=0)
    start = plan[0].start_value
    notches = 3 if start < 0.2 else -3
    stepped = round(start + notches * lp.spec.adjust.step, 10)
    expected = start if enter_poll == 4 else stepped
    screens: list[StubScreen] = []

    def factory(**kw):
        screens.append(StubScreen(inputs={3: [Wheel(notches)], enter_poll: [Key("return")]},
                                  **kw))
        return screens[-1]

    s = Session(lp, options(tmp_path, "V01"))
    assert s.run(screen_factory=factory, gaze=centre_gaze()) == 0
    (row,), _ = read_trials(s.folder / "trials.csv")
    assert row["final_value"] == pytest.approx(expected) and row["f_e"] == row["final_value"]
    # The last stimulus frame showed the confirmed value's render (8-bit: within 1/255) ...
    stim = [(b, shown) for b, shown in screens[0].frames if shown is not None]
    blank, shown = [f for f in screens[0].frames if not f[0]][-1]
    assert float(shown[..., :3].mean()) / 255 == pytest.approx(expected, abs=0.5 / 255)
    # ... and the dropped render never reached the screen.
    if enter_poll == 4:
        assert all(abs(float(x[..., :3].mean()) / 255 - stepped) > 1 / 255 for _, x in stim)
    # The first flip after Enter is black (the cross alone).
    assert screens[0].frames[-1][0] is True
    with open(s.folder / f"frames-{s.session_id}.csv") as fh:
        frames = list(csv.DictReader(fh))
    assert float(frames[-1]["value"]) == pytest.approx(expected)
    # Frames drawn while the new render was computed logged the value they showed.
    assert float(frames[2]["value"]) == pytest.approx(start)
    assert row["response_time_s"] < float(frames[-1]["flip_time_s"]) - float(
        frames[0]["flip_time_s"]) + 0.05
    # Only the processed half reaches the enhancer, as the right half of the full frame, with
    # the protocol's preset and geometry.
    enh = GreyEnhancer.instances[-1]
    assert enh.shape[:2] == (H, W // 2) and enh.viewports[-1] == (W // 2, 0, W, H)
    assert (enh.preset, enh.geometry) == ("paper", "exact")


def test_render_error_is_one_line_and_recorded(tmp_path: Path, monkeypatch) -> None:
    class Broken(FakeEnhancer):
        def enhance(self, gaze, params):
            raise FovexpError("no memory for the pyramids")

    use_enhancer(monkeypatch, Broken)
    s = Session(load_protocol(REPO / "protocols" / "calibration-fe.yaml"),
                options(tmp_path, "R01"))
    with pytest.raises(FovexpError) as err:
        s.run(screen_factory=lambda **kw: StubScreen(**kw), gaze=centre_gaze())
    assert str(err.value) == "rendering failed: no memory for the pyramids"
    info = json.loads((s.folder / f"session-{s.session_id}.json").read_text())
    assert info["state"] == "failed" and "no memory" in info["failure"]


def test_failed_validation_is_recorded_and_blocks_nothing(tmp_path: Path) -> None:
    ws = make_workspace(tmp_path / "ws")
    path = ws / "protocols" / "calibration-fe.yaml"
    data = yaml.safe_load(path.read_text())
    data["tracker"]["max_accuracy_deg"] = 1e-4  # no eye is that accurate
    path.write_text(yaml.safe_dump(data))
    lp = load_protocol(path)
    s = Session(lp, options(tmp_path, "F01", tracker="simulated", dry_run=True))
    with pytest.raises(FovexpError, match="validation failed"):
        s.run(screen_factory=lambda **kw: StubScreen(**kw))
    info = json.loads((s.folder / f"session-{s.session_id}.json").read_text())
    assert info["state"] == "failed" and info["completed"] is False
    assert "validation failed" in info["failure"]
    # The next run starts a new session (no --resume or --new-session needed) ...
    s2 = Session(lp, options(tmp_path, "F01", tracker="simulated", dry_run=True))
    assert s2.session_id != s.session_id and len(s2.remaining) == 1
    # ... and there is nothing to resume.
    with pytest.raises(FovexpError, match="no incomplete session"):
        Session(lp, options(tmp_path, "F01", tracker="simulated", dry_run=True, resume=True))


def test_resume_with_nothing_left_opens_no_window(tmp_path: Path, monkeypatch) -> None:
    use_enhancer(monkeypatch, FakeEnhancer)
    lp = load_protocol(REPO / "protocols" / "calibration-fe.yaml")
    s = Session(lp, options(tmp_path, "N01"))
    assert s.run(screen_factory=lambda **kw: StubScreen(inputs={3: [Key("return")]}, **kw),
                 gaze=centre_gaze()) == 0
    # As if killed after the last row but before the session file said so.
    p = s.folder / f"session-{s.session_id}.json"
    info = json.loads(p.read_text())
    info.update(state="running", completed=False)
    p.write_text(json.dumps(info))

    def no_window(**kw):
        raise AssertionError("a window was opened")

    # A participant's session is never finished by a dry run, nor by another gaze source.
    for mode in (dict(dry_run=True, tracker="simulated"), dict(tracker="tobii")):
        with pytest.raises(FovexpError, match="started as a session with --tracker mouse"):
            Session(lp, options(tmp_path, "N01", resume=True, **mode))
    s2 = Session(lp, options(tmp_path, "N01", resume=True))
    assert s2.session_id == s.session_id and not s2.remaining
    assert s2.run(screen_factory=no_window, gaze=centre_gaze()) == 0
    info = json.loads(p.read_text())
    assert info["completed"] is True and info["state"] == "completed"


def test_resume_keeps_the_dependency_values_it_started_with(tmp_path: Path) -> None:
    ws = make_workspace(tmp_path / "ws")
    write_study(ws / "results", n_participants=2, seed=1, experiments=("calibration-fe",))
    lp = load_protocol(ws / "protocols" / "calibration-sk.yaml", results_root=ws / "results")
    snap = lp.derived["f_e"]
    assert snap["kind"] == "fe_results" and [b for b, _ in snap["f_e"]] == [0.11, 0.34, 0.57]
    opts = dict(tracker="simulated", dry_run=True, results_root=ws / "results")
    s = Session(lp, options(tmp_path, "D01", **opts))
    s._start_info()  # the first start records the derived values
    fe_before = lp.sources["f_e"](0.34, None)
    # More calibration-fe participants arrive before the session is resumed.
    write_study(ws / "results", n_participants=6, seed=2, experiments=("calibration-fe",))
    lp2 = load_protocol(ws / "protocols" / "calibration-sk.yaml", results_root=ws / "results")
    assert lp2.sources["f_e"](0.34, None) != pytest.approx(fe_before, abs=1e-9)
    s2 = Session(lp2, options(tmp_path, "D01", resume=True, **opts))
    assert s2.protocol.sources["f_e"](0.34, None) == pytest.approx(fe_before, abs=1e-12)
    assert s2.info["events"][-1]["event"] == "derived_values_reused"
    # Stored values outside what the enhancer accepts: a clear error, not a crash mid-session.
    bad = json.loads(json.dumps(lp.derived))
    bad["f_e"]["f_e"] = [[b, 3.0] for b, _ in bad["f_e"]["f_e"]]
    with pytest.raises(FovexpError, match=r"calibration-sk\.yaml: s_k=.*f_e"):
        lp.use_derived(bad)
