"""Dry runs of the four shipped protocols under Xvfb, chained as in the paper (section 5.2:
calibration-sk takes f_e from calibration-fe's results, calibration-sf takes the s_f -> s_k line
from calibration-sk's; section 6.1: validation), checking the logs' content."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from fovexp import PAPER_TABLE2
from fovexp.experiment.protocol.spec import load_protocol
from fovexp.experiment.records.logs import (
    BLANKING_COLUMNS,
    FRAME_COLUMNS,
    GAZE_COLUMNS,
    TRIAL_COLUMNS,
    read_trials,
)
from fovexp.results.blanking import BlankingRule
from fovexp.results.frames import (
    decision_age_us,
    draw_latency_ms,
    gaze_to_flip_ms,
    read_frame_log,
    unblanked_violations,
)

from experiment_helpers import make_workspace, run_cli, xvfb_display  # noqa: F401

pytestmark = [pytest.mark.gui, pytest.mark.slow]

SPEED = "12"  # simulated participant's time compression


@pytest.fixture(scope="module")
def ws(tmp_path_factory, xvfb_display) -> Path:  # noqa: F811
    return make_workspace(tmp_path_factory.mktemp("dry") / "project")


def dry(ws: Path, protocol: str, pid: str, *extra: str) -> Path:
    r = run_cli(["run", f"protocols/{protocol}.yaml", "--participant", pid, "--dry-run",
                 "--sim-speed", SPEED, *extra], cwd=ws, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    return ws / "results" / protocol / pid


def read_csv(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def check_common(folder: Path, n_trials: int, n_practice: int) -> list[dict]:
    rows, _ = read_trials(folder / "trials.csv")
    assert (folder / "trials.csv").read_text().splitlines()[0].split(",") == list(TRIAL_COLUMNS)
    assert len(rows) == n_trials
    assert [r["trial_index"] for r in rows] == list(range(n_trials))
    assert sum(r["practice"] for r in rows) == n_practice
    sessions = {r["session"] for r in rows}
    assert len(sessions) == 1
    sid = sessions.pop()
    info = json.loads((folder / f"session-{sid}.json").read_text())
    assert info["completed"] is True and info["state"] == "completed"
    assert info["protocol_sha256"] == rows[0]["protocol_sha256"]
    assert info["display"]["name"] == "lg-oled55cx" and info["tracker"]["name"] == "simulated"
    q = info["tracker_quality"][0]["validation"]
    assert q["passed"] and set(q["left"]) >= {"accuracy_deg", "central_accuracy_deg",
                                               "precision_rms_s2s_deg", "data_loss", "targets"}
    assert info["tracker_quality"][0]["accepted"] and q["origins"] == "measured gaze origin"
    assert q["central_accuracy_deg"] < q["limits"]["max_central_accuracy_deg"] == 0.5
    assert info["display_area"]["source"] == "profile"
    for r in rows:
        assert r["tracker"] == "simulated" and r["seed"] == info["seed"]
        assert r["response_time_s"] > 0 and r["wheel_events"] > 0
        assert 0.0 <= r["blanked_fraction"] <= 1.0 and r["dropped_frames"] >= 0
    gaze = read_csv(folder / f"gaze-{sid}.csv")
    assert list(gaze[0]) == list(GAZE_COLUMNS)
    # the simulated eyes' positions: 71.5 cm in front of the screen
    assert {g["left_origin_z_mm"] for g in gaze if g["left_valid"] == "1"} == {"715.0"}
    per_trial = {}
    for g in gaze:
        if g["trial_index"]:
            per_trial[int(g["trial_index"])] = per_trial.get(int(g["trial_index"]), 0) + 1
    # 600 Hz samples during each trial (at least most of its duration).
    for r in rows:
        assert per_trial[r["trial_index"]] >= 0.5 * 600 * r["response_time_s"]
    frames = read_csv(folder / f"frames-{sid}.csv")
    assert list(frames[0]) == list(FRAME_COLUMNS)
    blank = read_csv(folder / f"blanking-{sid}.csv") if (folder / f"blanking-{sid}.csv").stat(
        ).st_size else []
    if blank:
        assert list(blank[0]) == list(BLANKING_COLUMNS)
    for r in rows:
        fr = [f for f in frames if int(f["trial_index"]) == r["trial_index"]]
        fr = [f for f in fr if f["attempt"] == fr[-1]["attempt"]]  # the attempt that counted
        assert len(fr) >= 2
        # blanked_fraction is time-weighted (a frame lasts until the next flip, the last one
        # until the trial's end, within a frame of its last flip): the logged episodes' time
        # over the trial's span
        eps = [e for e in blank if int(e["trial_index"]) == r["trial_index"]
               and e["attempt"] == fr[-1]["attempt"]]
        blanked_s = sum(float(e["end_s"]) - float(e["start_s"]) for e in eps)
        assert (blanked_s > 0) == any(f["blanked"] == "1" for f in fr)
        t = [float(f["flip_time_s"]) for f in fr]
        span = t[-1] - t[0]
        assert blanked_s / (span + 0.1) - 1e-5 <= r["blanked_fraction"] <= blanked_s / span + 1e-5
        assert r["dropped_frames"] == sum(f["dropped"] == "1" for f in fr)
        # Frame values are those of the render on screen: the first frame shows the start
        # value; the last stimulus frame flipped before Enter shows final_value (a render
        # pending at Enter is dropped, never shown).
        assert float(fr[0]["value"]) == pytest.approx(r["start_value"])
        enter = t[0] + r["response_time_s"]
        before = [f for f in fr if float(f["flip_time_s"]) < enter]
        # a simulated participant presses at the poll: no frame of the trial after Enter
        assert before and before[-1] is fr[-1]
        seen = [f for f in before if f["blanked"] == "0"]
        assert float(seen[-1]["value"]) == pytest.approx(r["final_value"])
    check_frame_log(folder, sid, info)
    # Gaze rows within a trial carry its attempt; between trials both are empty.
    assert all(bool(g["trial_index"]) == bool(g["attempt"]) for g in gaze)
    return rows


def check_frame_log(folder: Path, sid: str, info: dict) -> None:
    """From the frame log alone (the logs' reader, fovexp.results.frames): every stimulus frame
    names the gaze sample that decided it, the decision and its flip on the tracker's clock,
    and none was drawn with the stimulus while the newest sample was invalid, outside 1.25 deg,
    or older than the gaze timeout when it was decided (the rule, exactly)."""
    frames = read_frame_log(folder / f"frames-{sid}.csv")
    assert frames["flip_system_time_us"].notna().all()
    assert frames["decide_system_time_us"].notna().all()
    lat = gaze_to_flip_ms(frames).dropna()
    assert len(lat) >= 0.95 * len(frames) and (lat >= 0).all()
    assert (draw_latency_ms(frames) >= 0).all()
    rule = BlankingRule()
    bad = unblanked_violations(frames, rule)
    assert bad.empty, bad.to_string()
    shown = frames[frames["blanked"] == 0]
    assert rule.inside(shown["gaze_ecc_deg"]).all() and len(shown)
    assert rule.fresh(decision_age_us(shown)).all()


def test_dry_run_calibration_fe(ws: Path) -> None:
    folder = dry(ws, "calibration-fe", "S01", "--practice", "1", "--sim-noise-scale", "0")
    rows = check_common(folder, 16, 1)
    main = [r for r in rows if not r["practice"]]
    assert {(r["image"], r["blur_rate"]) for r in main} == {
        (f"scene-0{i}", b) for i in range(5) for b in (0.11, 0.34, 0.57)}
    for r in rows:
        assert r["method"] == "contrast" and r["adjusted_parameter"] == "f_e"
        assert r["f_e"] == r["final_value"] and r["s_k"] is None and r["s_f"] is None
        # Noise-free simulated participant: the Table 2 value to within half a fine step.
        truth = PAPER_TABLE2.at(r["blur_rate"])[0]
        assert abs(r["final_value"] - truth) <= 0.0025 + 1e-9
        assert 0.0 <= r["start_value"] <= 0.4
    # a drift check after every 10 main trials (the protocol's tracker.drift_check_every)
    info = json.loads(next(folder.glob("session-*.json")).read_text())
    drift = [e for e in info["events"] if e["event"] == "drift_check"]
    assert [(e["why"], e["outcome"]) for e in drift] == [("scheduled", "ok")]
    assert drift[0]["after_trial"] == 10  # the 10th main trial (index 0 is the practice)


def test_dry_run_calibration_sk(ws: Path) -> None:
    from fovexp.results.derive import fe_by_blur_rate

    lp = load_protocol(ws / "protocols" / "calibration-sk.yaml", results_root=ws / "results")
    fe = fe_by_blur_rate(ws / "results" / "calibration-fe")
    # The shortest prefix of the order with two s_f values per blur-rate (needed for a line).
    _, plan = lp.plan("S01", practice=0)
    seen: dict[float, set] = {}
    n = 0
    while not (len(seen) == 3 and all(len(v) >= 2 for v in seen.values())):
        seen.setdefault(plan[n].blur_rate, set()).add(plan[n].s_f)
        n += 1
    folder = dry(ws, "calibration-sk", "S01", "--practice", "0", "--limit-trials", str(n))
    rows = check_common(folder, n, 0)
    for r in rows:
        assert r["method"] == "ours" and r["adjusted_parameter"] == "s_k"
        assert r["s_k"] == r["final_value"] and 0 <= r["s_k"] <= 45
        assert r["s_f"] in (1.0, 1.9, 3.61, 6.81)
        # f_e comes from calibration-fe's results at this blur-rate.
        assert r["f_e"] == pytest.approx(fe[r["blur_rate"]])
        assert r["f_e"] == pytest.approx(PAPER_TABLE2.at(r["blur_rate"])[0], abs=0.003)


def test_dry_run_calibration_sf(ws: Path) -> None:
    from fovexp.results.derive import sk_line_by_blur_rate

    lines = sk_line_by_blur_rate(ws / "results" / "calibration-sk")
    folder = dry(ws, "calibration-sf", "S01", "--practice", "1", "--limit-trials", "5")
    rows = check_common(folder, 6, 1)
    for r in rows:
        assert r["adjusted_parameter"] == "s_f" and r["s_f"] == r["final_value"]
        slope, icpt = lines[r["blur_rate"]]
        # s_k follows the s_f -> s_k line of calibration-sk (section 5.2, bandwidth scaling).
        assert r["s_k"] == pytest.approx(min(max(slope * r["s_f"] + icpt, 0.0), 200.0))


def test_dry_run_validation(ws: Path, tmp_path: Path) -> None:
    truth = tmp_path / "truth.yaml"
    truth.write_text("validation_blur_rate: {contrast: 0.3, ours: 0.5}\n")
    folder = dry(ws, "validation", "S01", "--practice", "1", "--limit-trials", "4",
                 "--sim-truth", str(truth), "--sim-noise-scale", "0")
    rows = check_common(folder, 5, 1)
    # practice on plain foveation, a method not under test (paper section 6.1)
    assert rows[0]["practice"] and rows[0]["method"] == "foveated" and rows[0]["f_e"] is None
    for r in rows[1:]:
        assert r["adjusted_parameter"] == "blur_rate" and r["start_value"] == 0.0
        assert r["blur_rate"] == r["final_value"]
        target = 0.3 if r["method"] == "contrast" else 0.5
        assert abs(r["final_value"] - target) <= 0.0025 + 1e-9
        f_e, s_k, s_f = PAPER_TABLE2.at(r["blur_rate"])
        assert r["f_e"] == pytest.approx(f_e)
        if r["method"] == "ours":
            assert (r["s_k"], r["s_f"]) == (pytest.approx(s_k), pytest.approx(s_f))
        else:
            assert r["s_k"] is None and r["s_f"] is None


def test_dry_run_on_the_gpu_backend(ws: Path) -> None:
    """The runner renders through the GPU backend (Mesa llvmpipe in CI) and records it."""
    folder = dry(ws, "calibration-fe", "G01", "--practice", "0", "--limit-trials", "2",
                 "--backend", "gpu")
    rows = check_common(folder, 2, 0)
    info = json.loads((folder / f"session-{rows[0]['session']}.json").read_text())
    assert info["render"]["backend"] == "gpu" and info["render"]["renderer"]
    # drawn from the textures the enhancer wrote in a context shared with the window
    assert info["render"]["output"] == "texture"
