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
