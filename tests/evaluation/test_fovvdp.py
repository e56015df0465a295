"""``fovexp evaluate fovvdp`` (paper section 6.1): FovVDP through pyfvvdp, the optional
``[fovvdp]`` extra. The main environment (Python 3.10) does not install it: PyTorch's default
Linux wheels pull several GB of CUDA libraries. ``.ci/fovvdp`` runs this file in a Python 3.11
environment with a CPU build of torch, with ``FOVEXP_REQUIRE_FOVVDP=1`` so that it cannot
skip there; the 4K run on the shipped scenes is benchmarks/EVALUATION.md."""

from __future__ import annotations

import csv
import importlib.util
import os
import sys

import numpy as np
import pytest

from fovexp.cli import main

from evaluation_helpers import small_display, write_scene

HAVE = importlib.util.find_spec("pyfvvdp") is not None and importlib.util.find_spec(
    "torch") is not None
needs_fovvdp = pytest.mark.skipif(
    not HAVE and not os.environ.get("FOVEXP_REQUIRE_FOVVDP"),
    reason="pyfvvdp and torch are not installed (the [fovvdp] extra; .ci/fovvdp runs these "
           "tests in a Python 3.11 environment with a CPU build of torch)")


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    d = tmp_path_factory.mktemp("fovvdp")
    return d, small_display(d), [write_scene(d / f"s{i}.png", i) for i in (0, 5)]


def test_without_the_extra_the_command_says_how_to_install_it(inputs, capsys, monkeypatch):
    """Without pyfvvdp (made unimportable, as where the extra is not installed): one line
    naming the extra and torch, and nothing written."""
    monkeypatch.setitem(sys.modules, "pyfvvdp", None)
    d, display, images = inputs
    code = main(["evaluate", "fovvdp", str(images[0]), "--display", str(display),
                 "--blur-rate", "0.57", "--backend", "cpu", "--out", str(d / "none")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "[fovvdp]" in err[0] and "torch" in err[0]
    assert not (d / "none").exists()


@needs_fovvdp
def test_jod_per_scene_and_the_three_t_tests(inputs, capsys):
    d, display, images = inputs
    out = d / "out"
    code = main(["evaluate", "fovvdp", *map(str, images), "--display", str(display),
                 "--blur-rate", "0.57", "--backend", "cpu", "--impulses", "12", "--out",
                 str(out)])
    assert code == 0, capsys.readouterr().err
    rows = list(csv.DictReader((out / "fovvdp.csv").open()))
    assert len(rows) == 6
    jod = {(r["image"], r["method"]): float(r["jod"]) for r in rows}
    assert all(0.0 < v <= 10.0 for v in jod.values())
    tests = {(r["a"], r["b"]): r for r in csv.DictReader((out / "fovvdp-tests.csv").open())}
    assert set(tests) == {("foveated", "contrast"), ("foveated", "ours"), ("ours", "contrast")}
    assert all(int(r["n"]) == 2 for r in tests.values())
    for name in ("fovvdp.png", "fovvdp.md"):
        assert (out / name).stat().st_size > 0
    print({k: round(v, 3) for k, v in jod.items()})


@needs_fovvdp
def test_identical_images_score_ten(inputs):
    from fovexp import load_display
    from fovexp.evaluation.fovvdp import Metric

    from evaluation_helpers import scene

    d, display, _ = inputs
    img = scene(0)
    m = Metric(load_display(str(display)), img.shape[1], img.shape[0])
    assert m.jod(img, img, (320.0, 180.0)) == pytest.approx(10.0, abs=1e-3)


# ------------------------------------------- the reporting, on stand-in JODs (no pyfvvdp)
class StandInMetric:
    """pyfvvdp's place where it is absent: JOD = 10 - w * mean |test - reference|, w = 50 in
    the foveated mode and 80 in the non-foveated one (numbers only: the reporting is tested,
    not the metric)."""

    def __init__(self, display, width_px, height_px, contrast_ratio=1000.0, device="cpu",
                 foveated=True):
        self.shape = (height_px, width_px)
        self.ppd = 20.0
        self.weight = 50.0 if foveated else 80.0

    def jod(self, test, reference, fixation_px):
        return 10.0 - self.weight * float(np.abs(test - reference).mean())


@pytest.fixture
def stand_in(monkeypatch):
    from fovexp.evaluation import fovvdp

    monkeypatch.setattr(fovvdp, "_import", lambda: (None, None))
    monkeypatch.setattr(fovvdp, "Metric", StandInMetric)


def test_a_clamped_blur_rate_is_said_and_both_modes_are_reported(inputs, stand_in, capsys):
    """At the paper's 0.68, beyond Table 2's last row (0.57): one warning line naming the
    clamp, the same line in the note; the non-foveated JODs beside the foveated ones in the
    CSV, the t-tests in both modes, the per-scene differences in both."""
    d, display, images = inputs
    out = d / "clamped"
    code = main(["evaluate", "fovvdp", *map(str, images), "--display", str(display),
                 "--blur-rate", "0.68", "--backend", "cpu", "--impulses", "12", "--out",
                 str(out)])
    cap = capsys.readouterr()
    assert code == 0, cap.err
    err = cap.err.strip().splitlines()
    assert err == ["fovexp: warning: fovvdp: blur-rate 0.68 lies outside Table 2's rows (0.11 "
                   "to 0.57): f_e, s_k and s_f are clamped to its 0.57 row (f_e 0.28, s_k "
                   "18.68, s_f 2.19)"], err
    assert "foveated and non-foveated mode" in cap.out
    md = (out / "fovvdp.md").read_text()
    clamp = [line for line in md.splitlines() if "clamped" in line]
    assert len(clamp) == 1 and clamp[0].startswith("**Parameters clamped**: blur-rate 0.68")
    rows = list(csv.DictReader((out / "fovvdp.csv").open()))
    assert len(rows) == 6
    for r in rows:  # the stand-in's two modes: 10 - 50 e and 10 - 80 e of one error e
        e = (10.0 - float(r["jod"])) / 50.0
        assert float(r["jod_nonfoveated"]) == pytest.approx(10.0 - 80.0 * e, abs=1e-4)
    tests = list(csv.DictReader((out / "fovvdp-tests.csv").open()))
    assert sorted((t["mode"], t["a"], t["b"]) for t in tests) == sorted(
        (m, a, b) for m in ("foveated", "non-foveated")
        for a, b in (("foveated", "contrast"), ("foveated", "ours"), ("ours", "contrast")))
    scenes = [line for line in md.splitlines() if line.startswith(("| s0 |", "| s5 |"))]
    assert len(scenes) == 4  # two scenes x two modes
    assert "has the same sign in both modes in 2 of 2 scene(s)" in md


def test_inside_table_2_nothing_is_clamped_and_one_mode_can_be_asked(inputs, stand_in,
                                                                     capsys):
    d, display, images = inputs
    out = d / "inside"
    code = main(["evaluate", "fovvdp", *map(str, images), "--display", str(display),
                 "--blur-rate", "0.57", "--backend", "cpu", "--impulses", "12",
                 "--foveated-only", "--out", str(out)])
    cap = capsys.readouterr()
    assert code == 0 and cap.err == "", cap.err
    md = (out / "fovvdp.md").read_text()
    assert "clamped" not in md and "non-foveated" not in cap.out
    assert "jod_nonfoveated" not in (out / "fovvdp.csv").read_text().splitlines()[0]


def _result(jods: dict[tuple[str, str], tuple[float, float]], blur_rate: float = 0.57):
    """A FovvdpResult of stand-in (foveated, non-foveated) JODs per (scene, method)."""
    import pandas as pd

    from fovexp.evaluation import fovvdp

    jod = pd.DataFrame([{"image": i, "method": m, "jod": f, "jod_nonfoveated": n,
                         "seconds": 1.0, "seconds_nonfoveated": 1.0}
                        for (i, m), (f, n) in jods.items()])
    images = list(dict.fromkeys(i for i, _ in jods))
    return fovvdp.FovvdpResult(jod, fovvdp.paired_tests(jod, fovvdp.MODES), blur_rate, images,
                               39.3, "stand-in", fovvdp.table2_clamp(blur_rate))


def test_the_per_scene_differences_and_their_signs_by_hand():
    """Three scenes. Foveated mode: ours - contrast = -0.02, -0.03, +0.01; non-foveated:
    -0.05, -0.01, -0.02: the same sign in 2 of 3 scenes. The t-tests by hand: ours - contrast
    in the foveated mode has mean (-0.02 - 0.03 + 0.01) / 3 = -0.01333."""
    from fovexp.evaluation import fovvdp

    jods = {}
    for scene, (fc, fo, nc, no) in {"a": (8.70, 8.68, 9.10, 9.05),
                                    "b": (8.80, 8.77, 9.20, 9.19),
                                    "c": (8.60, 8.61, 9.00, 8.98)}.items():
        jods[(scene, "foveated")] = (8.3, 8.9)
        jods[(scene, "contrast")] = (fc, nc)
        jods[(scene, "ours")] = (fo, no)
    res = _result(jods)
    rows = {(r[0], r[1]): r for r in fovvdp.per_scene(res)}
    assert rows[("a", "foveated")][5] == pytest.approx(-0.02)
    assert rows[("a", "non-foveated")][5] == pytest.approx(-0.05)
    assert rows[("c", "foveated")][5] == pytest.approx(0.01)
    assert rows[("c", "non-foveated")][6] == pytest.approx(8.9 - 9.0)
    assert fovvdp.sign_agreement(res) == ("ours - contrast has the same sign in both modes in "
                                          "2 of 3 scene(s).")
    t = res.tests.set_index(["mode", "a", "b"])
    assert t.loc[("foveated", "ours", "contrast"), "mean_diff"] == pytest.approx(-0.04 / 3)
    assert t.loc[("non-foveated", "ours", "contrast"), "mean_diff"] == pytest.approx(
        -0.08 / 3)
    assert t.loc[("non-foveated", "ours", "contrast"), "paper_p"] == "-"
    md = fovvdp.note(res)
    assert fovvdp.PAPER_STATES in md and "clamped" not in md
    assert "| c | foveated | 8.3 | 8.6 | 8.61 | 0.01 | -0.3 |" in md
