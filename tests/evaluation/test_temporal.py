"""``fovexp evaluate temporal`` (paper section 6.2) on a deterministic camera pan made by
``fovexp stimuli pan`` (4 frames of 640 x 360, 6 px per frame), on the small display.

The paper's order is foveated > contrast > ours > full resolution. Measured here, the part
the paper explains holds: ours is below contrast (the noise is added to the contrast-enhanced
frames and changes where the content moves), and every method is above full resolution. The
place of foveated differs: the release's contrast formula, which Table 2's f_e is calibrated
with, has a gain f_e (1 + k) below 1 for blur levels k < 1/f_e - 1 (docs/METHOD.md 5.3), so at
these blurs it smooths rather than sharpens and the contrast-enhanced sequence is smoother
than the foveated one. Measured on this input at 0.57: full 0.431, foveated 0.532, contrast
0.558, ours 0.543. At 4K on the paper's display, where the blur reaches several pixels, the
paper's whole order holds at blur-rates 0.34 and 0.57 (30 frames: 0.872 > 0.869 > 0.828 and
0.909 > 0.886 > 0.857, full resolution 0.683; benchmarks/EVALUATION.md); the slow test below
checks it on three 4K frames.

The control: new impulses every frame lower ours' SSIM (measured here: by 0.023 at 0.57)."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from fovexp.cli import main
from fovexp.evaluation import temporal
from fovexp.evaluation.outputs import Setup

from evaluation_helpers import small_display


@pytest.fixture(scope="module")
def pan(tmp_path_factory):
    d = tmp_path_factory.mktemp("temporal")
    code = main(["stimuli", "pan", "--size", "640x360", "--frames", "4", "--step", "6",
                 "--out", str(d / "pan")])
    assert code == 0
    return d, small_display(d), d / "pan"


@pytest.fixture(scope="module")
def result(pan):
    d, display, frames = pan
    return temporal.run(frames, Setup.make(str(display), backend="cpu"), [0.57], d / "out")


def test_the_pan_is_deterministic_and_moves(pan, tmp_path):
    d, _, frames = pan
    assert main(["stimuli", "pan", "--size", "640x360", "--frames", "4", "--step", "6",
                 "--out", str(tmp_path)]) == 0
    for k in range(4):
        name = f"frame-{k:04d}.png"
        assert (tmp_path / name).read_bytes() == (frames / name).read_bytes()
    from fovexp import read_image

    a, b = read_image(frames / "frame-0000.png"), read_image(frames / "frame-0001.png")
    assert (a[:, 6:] == b[:, :-6]).all()  # the content moved 6 px to the left


def test_the_noise_lowers_the_coherence_of_the_contrast_enhanced_frames(result):
    f, c, o = (result.mean(m, 0.57) for m in ("foveated", "contrast", "ours"))
    full = result.mean("full")
    print(f"SSIM: full {full:.4f}, foveated {f:.4f}, contrast {c:.4f}, ours {o:.4f}")
    assert o < c
    assert c > f  # the release's contrast formula smooths at these blurs (module docstring)
    assert not result.order_holds(0.57)
    assert full < min(f, c, o)  # full resolution: the most detail moving, the lowest SSIM
    assert result.n_frames == 4
    assert set(result.ssim["n_pairs"]) == {3}


def test_reseeding_the_impulses_every_frame_lowers_the_coherence(result):
    drop = result.mean("ours", 0.57) - result.mean("ours-reseeded", 0.57)
    print(f"re-seeded impulses lower ours' mean SSIM by {drop:.4f}")
    assert drop > 0.005


def test_slices_and_files(result, pan):
    d = pan[0]
    for name in ("temporal.csv", "slices.csv", "pairs.csv", "temporal.png", "temporal.md"):
        assert (d / "out" / name).stat().st_size > 0
    rows = list(csv.DictReader((d / "out" / "slices.csv").open()))
    assert {(r["x_px"], r["y_px"]) for r in rows} == {("160", "180"), ("512", "251")}
    assert len(rows) == 4 * 2 * 5  # frames x pixels x conditions


def test_the_standard_ssim_is_reported_beside_fovexps(result, pan):
    """Each condition's mean SSIM under both variants, in the CSV and the note; on this pan
    they differ (the windows differ), and each pair's values are in pairs.csv."""
    d = pan[0]
    t = result.ssim
    assert t["mean_ssim_standard"].notna().all()
    assert (t["mean_ssim_standard"] - t["mean_ssim"]).abs().max() > 1e-3
    rows = list(csv.DictReader((d / "out" / "temporal.csv").open()))
    assert {"mean_ssim", "mean_ssim_standard"} <= set(rows[0])
    pairs = list(csv.DictReader((d / "out" / "pairs.csv").open()))
    assert len(pairs) == 5 * 3  # conditions x pairs
    md = (d / "out" / "temporal.md").read_text()
    assert "mean SSIM (standard)" in md and "11 x 11 Gaussian" in md


def test_the_standard_ssim_is_wang_et_al_s():
    """Against an independent computation of Wang et al. 2004's index: Gaussian-weighted
    means and population (co)variances with an 11 x 11 window of sigma 1.5 px (scipy's
    gaussian_filter truncated at 3.5 sigma: radius 5), K1 = 0.01, K2 = 0.03, averaged without
    the 5 px border; and it differs from fovexp's 7 x 7 uniform SSIM on the same pair."""
    from scipy.ndimage import gaussian_filter

    from fovexp import ssim

    rng = np.random.default_rng(3)
    x = rng.random((48, 64))
    y = np.clip(x + 0.2 * rng.standard_normal(x.shape), 0, 1)

    def g(img):
        return gaussian_filter(img, 1.5, truncate=3.5)

    mx, my = g(x), g(y)
    vx, vy, vxy = g(x * x) - mx**2, g(y * y) - my**2, g(x * y) - mx * my
    c1, c2 = 0.01**2, 0.03**2
    m = (2 * mx * my + c1) * (2 * vxy + c2) / ((mx**2 + my**2 + c1) * (vx + vy + c2))
    want = m[5:-5, 5:-5].mean()
    assert temporal.standard_ssim(x, y) == pytest.approx(want, abs=1e-12)
    assert abs(temporal.standard_ssim(x, y) - ssim(x, y)) > 1e-3  # measured: 0.0026


def _stand_in(means: dict[str, tuple[float, float]]):
    """A result at blur-rate 0.34 with the given (fovexp, standard) mean SSIM per condition."""
    import pandas as pd

    rows = [{"condition": c, "blur_rate": float("nan") if c == "full" else 0.34,
             "mean_ssim": f, "mean_ssim_standard": s, "n_pairs": 3}
            for c, (f, s) in means.items()]
    return temporal.TemporalResult(pd.DataFrame(rows), pd.DataFrame(), 4, (64, 36), [0.34],
                                   [])


def test_a_margin_within_the_variants_difference_is_flagged():
    """foveated - contrast = 0.003 under fovexp's SSIM, while the variants differ by up to
    0.020 (contrast: 0.869 against 0.889): flagged, with the standard SSIM's margin
    (0.891 - 0.889 = +0.002). contrast - ours = 0.041 and ours - full = 0.145, larger than
    every variant difference (0.020, 0.010, 0.005): not flagged."""
    res = _stand_in({"full": (0.683, 0.688), "foveated": (0.872, 0.891),
                     "contrast": (0.869, 0.889), "ours": (0.828, 0.838)})
    lines = temporal.close_margins(res)
    assert len(lines) == 1, lines
    assert lines[0].startswith("blur-rate 0.34: foveated - contrast = +0.0030 under fovexp's "
                               "SSIM (+0.0020 under the standard SSIM) is smaller than the "
                               "difference between the two SSIM variants (0.0200)")
    md = temporal.note(res, "stand-in")
    assert "smaller than the difference between the two SSIM variants" in md
    assert "| ours | 0.34 | 0.828 | 0.838 | yes / yes |" in md


def test_margins_larger_than_the_variants_difference_are_not_flagged():
    res = _stand_in({"full": (0.683, 0.688), "foveated": (0.909, 0.915),
                     "contrast": (0.886, 0.890), "ours": (0.857, 0.860)})
    assert temporal.close_margins(res) == []
    assert "is larger in size than the difference" in temporal.note(res, "stand-in")


def test_the_command(pan, capsys):
    d, display, frames = pan
    code = main(["evaluate", "temporal", str(frames), "--display", str(display), "--blur-rate",
                 "0.34", "--backend", "cpu", "--impulses", "12", "--no-reseed", "--slices",
                 "0.9,0.9", "--out", str(d / "cli")])
    assert code == 0
    md = (d / "cli" / "temporal.md").read_text()
    assert "ours-reseeded" not in open(d / "cli" / "temporal.csv").read()
    assert "pixel (576, 324)" in md


@pytest.mark.parametrize("argv,message", [
    (["--slices", "0.5"], "--slices"),
    (["--blur-rate", "-1"], "blur-rate"),
    (["--impulses", "0"], "--impulses"),
])
def test_bad_input_is_one_line(pan, capsys, argv, message):
    d, display, frames = pan
    code = main(["evaluate", "temporal", str(frames), "--display", str(display), "--backend",
                 "cpu", "--out", str(d / "bad"), *argv])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and message in err[0], err


def test_one_frame_is_not_a_sequence(pan, tmp_path, capsys):
    d, display, frames = pan
    (tmp_path / "one").mkdir()
    (tmp_path / "one" / "f.png").write_bytes((frames / "frame-0000.png").read_bytes())
    code = main(["evaluate", "temporal", str(tmp_path / "one"), "--display", str(display),
                 "--backend", "cpu", "--no-reseed", "--blur-rate", "0.34", "--out",
                 str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 2 and "2 or more" in err


@pytest.mark.slow
def test_the_papers_order_at_4k(tmp_path):
    """Three frames of a 4K pan on the paper's display at blur-rate 0.57: foveated > contrast >
    ours, the paper's order. The paper also puts ours above full resolution; under the paper's
    clipping rule (the default since issue 26) it is below (measured: ours 0.645, full 0.681;
    under the widened rule it was above). The cause is the noise's strength, not the rule's
    per-block neighbourhood: on these frames ours' SSIM falls as the cap loosens, 0.855
    (widened), 0.645 (paper), 0.604 (no cap at all; benchmarks/EVALUATION.md, 6.2). A known
    difference from the paper (docs/STATUS.md, Next); when a change restores the paper's
    order this assertion fails, and is to be turned back."""
    assert main(["stimuli", "pan", "--size", "3840x2160", "--frames", "3", "--step", "8",
                 "--out", str(tmp_path / "pan")]) == 0
    res = temporal.analyse(tmp_path / "pan", Setup.make("lg-oled55cx", backend="cpu"), [0.57],
                           reseed=False)
    f, c, o = (res.mean(m, 0.57) for m in ("foveated", "contrast", "ours"))
    print(f"4K SSIM: full {res.mean('full'):.4f}, foveated {f:.4f}, contrast {c:.4f}, ours {o:.4f}")
    assert res.order_holds(0.57) and o < res.mean("full")


# ------------------------------------------------------------- each pair's SSIM, by hand
def test_each_frame_is_compared_with_the_one_before_it(tmp_path):
    """Frames A, A, B, B, each of one grey level (8-bit codes 64 and 192): only the second
    pair differs. For two flat images of levels a and b both SSIM variants reduce to the
    luminance term, (2 a b + C1) / (a^2 + b^2 + C1) with C1 = (0.01)^2 (the structure term is
    C2 / C2 = 1), so the pairs' SSIMs are exactly (1, x, 1) and their mean (2 + x) / 3. A frame
    compared with the first instead gives (1, x, x)."""
    from fovexp import read_image, write_image

    frames = tmp_path / "flat"
    frames.mkdir()
    for k, level in enumerate((64 / 255, 64 / 255, 192 / 255, 192 / 255)):
        write_image(frames / f"frame-{k:04d}.png", np.full((90, 160), level, np.float32))
    # the levels as read (float32 code / 255), in float64
    a, b = (float(read_image(frames / f"frame-{k:04d}.png")[0, 0]) for k in (0, 2))
    x = (2 * a * b + 0.01**2) / (a * a + b * b + 0.01**2)  # 0.600...
    res = temporal.analyse(frames, Setup.make(str(small_display(tmp_path)), backend="cpu"),
                           [0.34], reseed=False)
    full = res.pairs[res.pairs["condition"] == "full"].sort_values("pair")
    assert list(full["pair"]) == [0, 1, 2]
    np.testing.assert_allclose(full["ssim"], [1.0, x, 1.0], rtol=0, atol=1e-9)
    np.testing.assert_allclose(full["ssim_standard"], [1.0, x, 1.0], rtol=0, atol=1e-9)
    assert res.mean("full") == pytest.approx((2 + x) / 3, abs=1e-9)
    assert res.mean("full", variant="standard") == pytest.approx((2 + x) / 3, abs=1e-9)
