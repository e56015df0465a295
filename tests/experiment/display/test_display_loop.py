"""The display loop in a real PsychoPy window under Xvfb (issue 9, sections 2 and 3): nothing but
the cross between trials, the blanking rule checked from the written frame log alone with
scripted gaze crossing 1.25 deg and dropping out, and the GPU backend's zero-copy output on
screen as the enhancer computed it."""

from __future__ import annotations

import csv
import math
import os
from pathlib import Path

import numpy as np
import pytest

from fovexp import load_display, make_params
from fovexp.experiment.options import SessionOptions
from fovexp.experiment.protocol.spec import load_protocol
from fovexp.experiment.records.logs import read_trials
from fovexp.experiment.session import Session
from fovexp.experiment.trackers.gaze import FixationGeometry
from fovexp.results.blanking import BlankingRule
from fovexp.results.frames import (
    decision_age_us,
    gaze_to_flip_ms,
    read_frame_log,
    unblanked_violations,
)

from experiment_helpers import REPO, ScriptedGaze, xvfb_display  # noqa: F401

pytestmark = [pytest.mark.gui]

W, H = 480, 270
DISPLAY = load_display("lg-oled55cx")


def recording_screen(shown: list[tuple[float, int]]):
    """A PsychoScreen that keeps, for every flip, its time and the brightest value outside the
    cross (0: black but for the cross)."""
    from fovexp.experiment.display.window import PsychoScreen

    class Recording(PsychoScreen):
        def __init__(self, **kw) -> None:
            super().__init__(**kw)
            self.capture = True
            arm = int(math.ceil(max(7.0, kw.get("cross_px", 20.0)))) + 2
            self._mask = np.ones((H, W), bool)
            self._mask[H // 2 - arm:H // 2 + arm, W // 2 - arm:W // 2 + arm] = False

        def flip(self):
            t = super().flip()
            shown.append((t.flip_s, int(self.last_frame[self._mask].max())))
            return t

    return Recording


def session(tmp_path: Path, pid: str, **kw) -> Session:
    lp = load_protocol(REPO / "protocols" / "calibration-fe.yaml")
    opts = SessionOptions(participant=pid, results_root=tmp_path / "results", tracker="simulated",
                          dry_run=True, window_size=(W, H), practice_trials=0, sim_speed=6.0,
                          console=lambda line: None, **kw)
    return Session(lp, opts)


def point_at(fix: FixationGeometry, ecc: float) -> tuple[float, float]:
    lo, hi = 0.0, 0.4
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if fix.eccentricity((0.5 + mid, 0.5)) < ecc:
            lo = mid
        else:
            hi = mid
    return 0.5 + 0.5 * (lo + hi), 0.5


def test_between_trials_only_the_cross(tmp_path: Path, xvfb_display) -> None:  # noqa: F811
    """From the first flip after Enter until the next trial's first stimulus frame, every frame
    is black but for the cross, however long the next trial takes to prepare (its image, its
    first render, the logs' sync)."""
    shown: list[tuple[float, int]] = []
    s = session(tmp_path, "X01", limit_trials=3)
    assert s.run(screen_factory=recording_screen(shown)) == 0
    rows, _ = read_trials(s.folder / "trials.csv")
    frames = read_frame_log(s.folder / f"frames-{s.session_id}.csv")
    assert len(rows) == 3
    first, enter = {}, {}
    for r in rows:
        fr = frames[frames["trial_index"] == r["trial_index"]]
        t0 = float(fr["flip_time_s"].iloc[0])
        enter[r["trial_index"]] = t0 + r["response_time_s"]
        first[r["trial_index"]] = float(fr.loc[fr["blanked"] == 0, "flip_time_s"].iloc[0])
    assert any(v > 0 for _, v in shown)  # stimulus frames were seen, so black is meaningful
    for i in (0, 1):
        between = [v for t, v in shown if enter[i] < t < first[i + 1] - 1e-4]
        assert len(between) >= 1, "no flip between the trials"
        assert max(between) == 0, f"stimulus on screen between trials {i} and {i + 1}"
        # the first flip after Enter is already black
        after = [v for t, v in shown if t > enter[i]]
        assert after[0] == 0


class GappyGaze(ScriptedGaze):
    """Scripted gaze whose stream pauses (no samples at all, the tracker still connected) for
    ``gap_s`` every ``every_s``: the blanking monitor must call such gaze "lost"."""

    def __init__(self, path, every_s: float = 0.9, gap_s: float = 0.15) -> None:
        super().__init__(path)
        self.every_s, self.gap_s = every_s, gap_s

    def poll(self):
        return [s for s in super().poll()
                if (s.device_time_us / 1e6) % self.every_s < self.every_s - self.gap_s]


def test_blanking_rule_holds_in_the_frame_log(tmp_path: Path, xvfb_display) -> None:  # noqa: F811
    """Gaze steps between the cross, 1.1 deg (inside), 1.4 deg (outside) and an invalid sample,
    and the stream pauses: read back from the written frame log alone, no frame was drawn with
    the stimulus against the rule, and every case occurred (so the check had something to
    catch)."""
    fix = FixationGeometry(DISPLAY)
    inside, outside = point_at(fix, 1.1), point_at(fix, 1.4)

    def path(t: float):
        k = int(t / 0.13) % 5
        return [(0.5, 0.5), outside, inside, None, inside][k]

    s = session(tmp_path, "G01", limit_trials=2)
    s.opts.sim_speed = 2.0
    assert s.run(gaze=GappyGaze(path)) == 0
    frames = read_frame_log(s.folder / f"frames-{s.session_id}.csv")
    rule = BlankingRule(1.25, 0.05)
    bad = unblanked_violations(frames, rule)
    assert bad.empty, bad.to_string()
    age_ms = gaze_to_flip_ms(frames)
    blanked = frames["blanked"] == 1
    # outside the radius: only ever black
    assert (frames["gaze_ecc_deg"] > 1.25).any()
    assert blanked[frames["gaze_ecc_deg"] > 1.25].all()
    # invalid newest sample: black, and its eccentricity empty
    invalid = frames["gaze_ecc_deg"].isna() & frames["gaze_system_time_us"].notna()
    assert invalid.any() and blanked[invalid].all()
    # the stream paused: frames decided when their newest sample was older than the timeout
    # are black
    stale = ~rule.fresh(decision_age_us(frames))  # NaN (no sample yet): not fresh either
    assert stale.any() and blanked[stale].all()
    # inside, near the radius: shown
    near = (frames["gaze_ecc_deg"] > 1.0) & (frames["gaze_ecc_deg"] <= 1.25) & (age_ms < 40)
    assert (~blanked[near]).any()
    # the blanking log agrees on the reasons
    with open(s.folder / f"blanking-{s.session_id}.csv") as fh:
        reasons = {e["reason"] for e in csv.DictReader(fh)}
    assert {"outside", "invalid", "lost"} <= reasons


def test_gpu_output_reaches_the_screen_without_a_read_back(xvfb_display) -> None:  # noqa: F811
    """The GPU backend renders in a GL context sharing objects with the window's into one of
    two textures; the window draws that texture. The frame on screen (the back buffer before
    the flip) equals the enhancer's output to 8-bit rounding: compared with the same backend's
    read-back output, quantised as the 8-bit path does it. A second render goes to the other
    texture and replaces the first on screen."""
    pytest.importorskip("moderngl")
    from fovexp.experiment.display.render import TestRenderer
    from fovexp.experiment.display.window import PsychoScreen

    screen = PsychoScreen((W, H), fullscreen=False, cross_px=12, dry_run=True)
    rng = np.random.default_rng(3)
    right = rng.uniform(0.05, 0.95, (H, W // 2, 3)).astype(np.float32)
    share = screen.gl_share()
    assert share is not None
    zero = TestRenderer(DISPLAY, backend="gpu", gl_share=share)
    readback = TestRenderer(DISPLAY, backend="gpu")  # its own context, the 8-bit path
    try:
        info = zero.info()
        assert info["backend"] == "gpu" and info["output"] == "texture", info
        assert readback.info()["output"] == "8-bit upload"
        textures = []
        for blur in (0.34, 0.57):
            p = make_params(method="ours", blur_rate=blur, impulses=12)
            for r in (zero, readback):
                r.set_image(right, (W, H))
            got = zero.wait(zero.request(p))
            ref = readback.wait(readback.request(p))
            assert got.rgba8 is None and got.texture is not None and ref.rgba8 is not None
            textures.append(got.texture)
            screen.set_test(got)
            screen.capture = True
            screen.draw(blank=False)
            on_screen = screen.last_frame[:, W // 2:].astype(int)
            diff = np.abs(on_screen - ref.rgba8[..., :3].astype(int))
            diff[H // 2 - 14:H // 2 + 14, :14] = 0  # the cross
            assert diff.max() <= 1, (blur, diff.max())
        assert textures[0] != textures[1]  # the second render did not overwrite the first
    finally:
        zero.close()
        readback.close()
        screen.close()


def test_the_display_loop_benchmark_runs_on_a_fresh_checkout(tmp_path: Path) -> None:
    """Issue 18, section 5: benchmarks/display_loop.py without the shared Sponza frame and
    without generated scenes generates the one it needs (at its window's size, into the given
    stimulus folder), runs old and new back to back, and writes its record with the load."""
    import json
    import subprocess
    import sys

    from experiment_helpers import private_xvfb

    pytest.importorskip("psychopy", reason="PsychoPy is not installed (fovexp[experiment])")
    out, stim = tmp_path / "out", tmp_path / "stimuli"
    with private_xvfb("640x360") as display:
        r = subprocess.run(
            [sys.executable, str(REPO / "benchmarks" / "display_loop.py"), "--frame",
             "generated", "--stimuli", str(stim), "--size", "480x270", "--seconds", "1",
             "--repeats", "1", "--parameters", "f_e", "--upload-reps", "2", "--out", str(out)],
            env={**os.environ, "DISPLAY": display}, capture_output=True, text=True,
            timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    assert (stim / "generated" / "480x270" / "scene-00.png").is_file()
    res = json.loads((out / "display_loop-480x270.json").read_text())
    assert [run["mode"] for run in res["runs"]] == ["old", "new"]
    assert all(len(run["load_average"]) == 3 and run["frames"] > 0 for run in res["runs"])
    assert res["runs"][1]["latch"]["frames"] == res["runs"][1]["frames"]
    text = (out / "DISPLAY_LOOP-480x270.md").read_text()
    assert "Late latching, old against new" in text and "load (1 min)" in text
