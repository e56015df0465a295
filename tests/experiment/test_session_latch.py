"""Issue 18 at the session's level, without a window (a stub screen whose keyboard stamps the
press, a stand-in enhancer): the session late-latches every trial with one latch and records
it, records the window's keyboard, warns when keys are stamped only at the poll, and writes
frame logs that keep the blanking rule exactly (the rule's one definition) and the
``final_value`` rule."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from fovexp import FovexpError
from fovexp.experiment.options import SessionOptions
from fovexp.experiment.protocol.spec import load_protocol
from fovexp.experiment.records.logs import read_trials
from fovexp.experiment.session import Session
from fovexp.experiment.tasks.trial import Key
from fovexp.results.blanking import BlankingRule
from fovexp.results.frames import final_value_violations, read_frame_log, unblanked_violations

from experiment_helpers import REPO, GreyEnhancer, ScriptedGaze, StubScreen, use_enhancer

W, H = 480, 270


class FakeEnhancer(GreyEnhancer):
    delay_s = 0.01


def run_session(tmp_path: Path, monkeypatch, pid: str, screen_cls=StubScreen,
                lines: list[str] | None = None, accept_poll_keys: bool = False) -> Session:
    use_enhancer(monkeypatch, FakeEnhancer)
    lp = load_protocol(REPO / "protocols" / "calibration-fe.yaml")
    opts = SessionOptions(participant=pid, results_root=tmp_path / "results", tracker="mouse",
                          dry_run=False, window_size=(W, H), practice_trials=0, limit_trials=2,
                          skip_display_check=True, fullscreen=False,
                          accept_poll_keys=accept_poll_keys,
                          console=(lines.append if lines is not None else lambda t: None))
    s = Session(lp, opts)
    enter = {i: [Key("return")] for i in range(12, 10_000, 12)}
    gaze = ScriptedGaze(lambda t: (0.5, 0.5))
    assert s.run(screen_factory=lambda **kw: screen_cls(inputs=enter, **kw), gaze=gaze) == 0
    return s


def test_a_session_late_latches_and_keeps_the_rules(tmp_path: Path, monkeypatch) -> None:
    lines: list[str] = []
    s = run_session(tmp_path, monkeypatch, "L01", lines=lines)
    info = json.loads((s.folder / f"session-{s.session_id}.json").read_text())
    run = info["runs"][-1]
    assert run["window"]["keyboard"] == {"backend": "stub", "key_time": "press"}
    latch = run["display_thread"]["late_latch"]
    assert latch["safety"] == 1.5 and latch["frames"] >= 20 and latch["margin_ms"] >= 1.0
    assert not [ln for ln in lines if "stamped when polled" in ln]
    frames = read_frame_log(s.folder / f"frames-{s.session_id}.csv")
    assert frames["decide_system_time_us"].notna().all()
    assert (frames["decide_system_time_us"] <= frames["flip_system_time_us"]).all()
    assert (frames["blanked"] == 0).any()
    assert unblanked_violations(frames, BlankingRule(1.25, 0.05)).empty
    rows, _ = read_trials(s.folder / "trials.csv")
    assert len(rows) == 2 and final_value_violations(frames, rows).empty


class PollStampedScreen(StubScreen):
    """A window whose keyboard stamps keys only at the poll (PsychoPy's event module)."""

    def info(self):
        return {**super().info(), "keyboard": {"backend": "event", "key_time": "poll"}}


def test_keys_stamped_at_the_poll_stop_a_real_session_unless_accepted(tmp_path: Path,
                                                                       monkeypatch) -> None:
    """Without ``--accept-poll-keys`` the session stops before its first trial, naming what to
    install, its session file saying why; with it, a warning and the choice recorded."""
    with pytest.raises(FovexpError, match=r"stamped when polled.*libjack-jackd2-0.*"
                                          r"--accept-poll-keys"):
        run_session(tmp_path, monkeypatch, "L03", PollStampedScreen)
    folder = tmp_path / "results" / "calibration-fe" / "L03"
    info = json.loads(next(folder.glob("session-*.json")).read_text())
    assert info["state"] == "failed" and "libjack" in info["failure"]
    assert not (folder / "trials.csv").exists() or len(read_trials(folder / "trials.csv")[0]) == 0
    lines: list[str] = []
    s = run_session(tmp_path, monkeypatch, "L02", PollStampedScreen, lines,
                    accept_poll_keys=True)
    warned = [ln for ln in lines if "stamped when polled" in ln]
    assert len(warned) == 1 and "libjack-jackd2-0" in warned[0]
    info = json.loads((s.folder / f"session-{s.session_id}.json").read_text())
    assert info["runs"][-1]["window"]["keyboard"]["key_time"] == "poll"
    [event] = [e for e in info["events"] if e["event"] == "keyboard_stamps_at_poll"]
    assert event["accepted"] is True
