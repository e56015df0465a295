"""``fovexp evaluate compression`` (paper section 6.3): JPEG sizes of foveated frames at the
participants' blur-rates, contrast against ours, on a synthetic validation study
(analysis_fixtures: ours' blur-rate is contrast's x 1.25) and generated scenes at 640 x 360
on the small display; the paper's 12-impulse experiment as the default (a second study in
which ``validation-12`` has ours at contrast's x 1.6, its session files carrying the shipped
protocol), the saving against the blur-rate ratio and at Table 2's pair."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from fovexp import FovexpError, read_image
from fovexp.cli import main
from fovexp.evaluation import compression
from fovexp.evaluation.outputs import Setup

from analysis_fixtures import (
    SCENES,
    Noise,
    Truth,
    session_id,
    simulate_rows,
    write_study,
    write_trials,
)
from evaluation_helpers import scene, small_display, write_scene


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    d = tmp_path_factory.mktemp("compression")
    results = write_study(d / "results", n_participants=4, experiments=("validation",))
    images = d / "images"
    images.mkdir()
    for k, sid in enumerate(SCENES[:3]):
        write_scene(images / f"{sid}.png", 5 + k)
    for sid in SCENES[3:]:  # the remaining scenes as copies: only their sizes matter here
        (images / f"{sid}.png").write_bytes((images / f"{SCENES[0]}.png").read_bytes())
    return d, results, images, small_display(d)


@pytest.fixture(scope="module")
def run_and_warnings(study):
    d, results, images, display = study
    with pytest.warns(UserWarning) as caught:
        res = compression.run(results, Setup.make(str(display), backend="cpu"), d / "out",
                              images=images, ratios=(1.5,))  # one ratio: the time
    return res, [str(w.message) for w in caught]


@pytest.fixture(scope="module")
def result(run_and_warnings):
    return run_and_warnings[0]


def test_without_a_12_impulse_experiment_it_falls_back_and_says_so(run_and_warnings, study):
    """These results hold only the 64-impulse validation: it is used, with one warning, and
    the note names it and says why."""
    res, messages = run_and_warnings
    assert res.experiment == "validation"
    assert len(messages) == 1 and "no 12-impulse validation" in messages[0], messages
    md = (study[0] / "out" / "compression.md").read_text()
    assert "experiment validation (" in md and "a fallback" in md
    assert "**Warning**: compression: these results hold no 12-impulse validation" in md


def test_ours_allows_smaller_files(result):
    t = result.table
    assert len(t) == len(SCENES)
    assert (t["blur_rate_ours"] > t["blur_rate_contrast"]).all()
    assert (t["bytes_ours"] < t["bytes_contrast"]).all()
    assert (t["saving_pct"] > 0).all()
    print("savings (%):", [round(v, 1) for v in t["saving_pct"]])


def test_the_jpeg_is_quality_90_with_420_subsampling():
    img = scene(5)
    data = io.BytesIO()
    size = compression.jpeg_size(img)
    Image.fromarray(np.round(img * 255).astype(np.uint8)).save(
        data, format="JPEG", quality=90, subsampling="4:2:0")
    assert size == data.tell()
    from PIL import JpegImagePlugin

    data.seek(0)
    assert JpegImagePlugin.get_sampling(Image.open(data)) == 2  # 4:2:0


def test_files_and_note(result, study):
    d = study[0]
    for name in ("compression.csv", "compression.png", "compression.md"):
        assert (d / "out" / name).stat().st_size > 0
    rows = list(csv.DictReader((d / "out" / "compression.csv").open()))
    assert {r["image"] for r in rows} == set(SCENES)
    assert "4:2:0" in (d / "out" / "compression.md").read_text()


def test_the_files_the_sessions_recorded_are_the_default(study, tmp_path, capsys):
    """Without --images, each scene's file comes from session-*.json's stimuli record."""
    d, results, images, display = study
    for sess in (results / "validation").rglob("session-*.json"):
        info = json.loads(sess.read_text())
        info["stimuli"] = {"folder": str(images), "images": {
            s: {"kind": "scene", "path": f"{s}.png"} for s in SCENES}}
        sess.write_text(json.dumps(info))
    code = main(["evaluate", "compression", str(results), "--display", str(display),
                 "--backend", "cpu", "--ratios", "none", "--pair", "none", "--out",
                 str(tmp_path / "o")])
    assert code == 0, capsys.readouterr().err
    assert "largest saving" in capsys.readouterr().out


@pytest.mark.parametrize("argv,message", [
    (["--experiment", "calibration-fe"], "no trials of experiment"),
    (["--ratios", "x"], "--ratios"),
    (["--ratios", "0"], "--ratios"),
    (["--pair", "0.34"], "--pair"),
    (["--images", "/nonexistent"], "--images"),
    (["--quality", "0"], "--quality"),
])
def test_bad_input_is_one_line(study, tmp_path, capsys, argv, message):
    d, results, images, display = study
    code = main(["evaluate", "compression", str(results), "--display", str(display),
                 "--backend", "cpu", "--out", str(tmp_path / "o"), *argv])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and message in err[0], err


def test_a_missing_scene_file_is_named(study, tmp_path, capsys):
    d, results, images, display = study
    partial = tmp_path / "partial"
    partial.mkdir()
    (partial / f"{SCENES[0]}.png").write_bytes((images / f"{SCENES[0]}.png").read_bytes())
    code = main(["evaluate", "compression", str(results), "--display", str(display),
                 "--backend", "cpu", "--images", str(partial), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 2 and SCENES[1] in err


# ------------------------------------------------ the paper's experiment, ratios, Table 2
REPO = Path(__file__).resolve().parents[2]
GAIN_12 = 0.6  # validation-12: ours at contrast's x 1.6 (validation: x 1.25)


def _write_experiment(root: Path, experiment: str, protocol_text: str | None, gain: float,
                      seed: int) -> None:
    """Simulated validation logs under ``experiment``, their session files carrying
    ``protocol_text`` (as the runner's do), 4 participants."""
    rng = np.random.default_rng(seed)
    for p in range(4):
        pid = f"P{p + 1:02d}"
        sess = session_id(100 * seed + p)
        rows = [dict(r, experiment=experiment) for r in simulate_rows(
            "validation", pid, sess, rng, Truth(gain=gain), Noise())]
        folder = root / experiment / pid
        write_trials(folder, rows)
        if protocol_text is not None:
            info_path = folder / f"session-{sess}.json"
            info = json.loads(info_path.read_text())
            info["protocol"] = protocol_text
            info_path.write_text(json.dumps(info))


@pytest.fixture(scope="module")
def study12(study):
    d, _, images, display = study
    results = d / "results12"
    _write_experiment(results, "validation", (REPO / "protocols" / "validation.yaml").read_text(),
                      0.25, seed=1)
    _write_experiment(results, "validation-12",
                      (REPO / "protocols" / "validation-12.yaml").read_text(), GAIN_12, seed=2)
    return d, results, images, display


def _ratio(path: Path) -> float:
    rows = list(csv.DictReader(path.open()))
    return float(np.mean([float(r["blur_rate_ours"]) / float(r["blur_rate_contrast"])
                          for r in rows]))


def test_the_12_impulse_experiment_is_the_default(study12, capsys):
    """Both validations in the results: the one whose recorded protocol has 12 impulses is
    used, without a warning, and the command says which; it prints the saving against the
    blur-rate ratio as a table and the result at Table 2's pair."""
    d, results, images, display = study12
    out = d / "out12"
    code = main(["evaluate", "compression", str(results), "--images", str(images), "--display",
                 str(display), "--backend", "cpu", "--out", str(out)])
    cap = capsys.readouterr()
    assert code == 0 and cap.err == "", cap.err
    lines = cap.out.splitlines()
    assert lines[0].startswith("fovexp evaluate compression: 10 scene(s) of experiment "
                               "validation-12 (12 impulses per kernel; the paper's "
                               "12-impulse experiment"), lines[0]
    assert "JPEG saving against the blur-rate ratio" in cap.out
    table = [line.split() for line in lines if line.startswith("  ") and line.split()[0][0]
             in "0123456789"]
    assert [row[0] for row in table] == ["1.00", "1.25", "1.50", "1.75", "2.00", "2.25", "2.50"]
    assert table[0][1:] == ["0.0", "0.0", "0.0"]  # ratio 1: the same file
    assert any(line.startswith("Table 2's pair, contrast at 0.34 and ours at 0.57 (ratio "
                               "1.68): saving mean") for line in lines), cap.out
    assert _ratio(out / "compression.csv") == pytest.approx(1 + GAIN_12, abs=0.1)
    md = (out / "compression.md").read_text()
    assert "experiment validation-12 (12 impulses per kernel" in md and "Warning" not in md
    assert "| 2.50 |" in md and "Table 2's pair" in md


def test_an_experiment_asked_for_is_used(study12, tmp_path, capsys):
    d, results, images, display = study12
    code = main(["evaluate", "compression", str(results), "--images", str(images), "--display",
                 str(display), "--backend", "cpu", "--experiment", "validation", "--ratios",
                 "none", "--pair", "none", "--out", str(tmp_path)])
    cap = capsys.readouterr()
    assert code == 0 and cap.err == "", cap.err
    assert "experiment validation (64 impulses per kernel; asked for" in cap.out
    assert "Table 2's pair" not in cap.out
    assert _ratio(tmp_path / "compression.csv") == pytest.approx(1.25, abs=0.1)


def test_the_ratio_and_table_2_savings_by_hand(study12, tmp_path):
    """Each ratio row's saving is 1 - bytes / bytes_base of the same scene, bytes_base is
    the scene's JPEG at its contrast blur-rate (the per-scene table's), and Table 2's pair is
    the scene foveated at 0.34 and at 0.57, encoded here independently."""
    import pandas as pd

    d, results, images, display = study12
    setup = Setup.make(str(display), backend="cpu")
    res = compression.analyse(results, setup, images=images, ratios=(1.0, 2.0))
    r = res.ratios
    np.testing.assert_allclose(r["saving_pct"], 100 * (1 - r["bytes"] / r["bytes_base"]))
    base = res.table.set_index("image")["bytes_contrast"]
    assert (r.set_index("image")["bytes_base"] == base.loc[r["image"]].to_numpy()).all()
    assert (r[r["ratio"] == 1.0]["saving_pct"] == 0).all()
    assert (r[r["ratio"] == 2.0]["saving_pct"] > 0).all()  # more blur, a smaller file
    first = res.table2.iloc[0]
    enh = setup.enhancer()
    enh.set_image(read_image(images / f"{first['image']}.png"))
    for key, rate in (("bytes_contrast", 0.34), ("bytes_ours", 0.57)):
        out = enh.enhance(setup.gaze, setup.params("foveated", rate)).output
        assert first[key] == compression.jpeg_size(out)
    assert first["saving_pct"] == pytest.approx(
        100 * (1 - first["bytes_ours"] / first["bytes_contrast"]))
    summary = dict((ratio, mean) for ratio, mean, _lo, _hi in res.ratio_summary())
    assert summary[2.0] == pytest.approx(float(r[r["ratio"] == 2.0]["saving_pct"].mean()))
    assert isinstance(res.ratios, pd.DataFrame)


def test_the_experiment_is_picked_by_its_recorded_impulse_count(tmp_path):
    """The 12-impulse experiment by its recorded protocol, whatever its name; by the name
    validation-12 where no protocol is recorded; else validation, with a warning."""
    text12 = (REPO / "protocols" / "validation-12.yaml").read_text()
    _write_experiment(tmp_path / "a", "fast-check", text12, GAIN_12, seed=3)
    _write_experiment(tmp_path / "a", "validation", None, 0.25, seed=4)
    c = compression.pick_experiment(tmp_path / "a", ["fast-check", "validation"], None)
    assert (c.experiment, c.impulses, c.warning) == ("fast-check", 12, "")
    _write_experiment(tmp_path / "b", "validation-12", None, GAIN_12, seed=5)
    c = compression.pick_experiment(tmp_path / "b", ["validation", "validation-12"], None)
    assert (c.experiment, c.impulses) == ("validation-12", None) and "by its name" in c.why
    c = compression.pick_experiment(tmp_path / "b", ["validation"], None)
    assert c.experiment == "validation" and "no 12-impulse validation" in c.warning
    with pytest.raises(FovexpError, match="no validation experiment"):
        compression.pick_experiment(tmp_path / "b", [], None)
