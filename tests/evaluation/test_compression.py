"""``fovexp evaluate compression`` (paper section 6.3): JPEG sizes of foveated frames at the
participants' blur-rates, contrast against ours, on a synthetic validation study
(analysis_fixtures: ours' blur-rate is contrast's x 1.25) and generated scenes at 640 x 360
on the small display."""

from __future__ import annotations

import csv
import io
import json

import numpy as np
import pytest
from PIL import Image

from fovexp.cli import main
from fovexp.evaluation import compression
from fovexp.evaluation.outputs import Setup

from analysis_fixtures import SCENES, write_study
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
def result(study):
    d, results, images, display = study
    return compression.run(results, Setup.make(str(display), backend="cpu"), d / "out",
                           images=images)


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
                 "--backend", "cpu", "--out", str(tmp_path / "o")])
    assert code == 0, capsys.readouterr().err
    assert "largest saving" in capsys.readouterr().out


@pytest.mark.parametrize("argv,message", [
    (["--experiment", "calibration-fe"], "no trials of experiment"),
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
