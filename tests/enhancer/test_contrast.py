"""Contrast enhancement (Patney et al. 2016 as the release applies it; docs/METHOD.md, 5.3)
against a brute-force evaluation of its formula."""

import numpy as np
import pytest

from fovexp.contrast import box_width_px, contrast_change, contrast_enhance

from engine_helpers import textured_image


@pytest.mark.parametrize("k,h,w", [(1, 40, 50), (2, 40, 50), (3, 40, 50), (6, 12, 14)])
def test_contrast_enhancement_matches_brute_force_release_formula(k, h, w):
    """Box means on the symmetric padding, as MATLAB's padarray makes it; the last case's box
    (24 px) is wider than the image, where the padding repeats its mirror."""
    img = textured_image(h, w)[: h, : w]
    out = contrast_enhance(img, np.full((h, w), float(k), np.float32), 0.2)
    n = box_width_px(k)
    p = n
    pad = np.pad(img, ((p, p), (p, p), (0, 0)), mode="symmetric")
    lo = (n - 1) // 2
    ref = np.empty_like(img)
    for y in range(h):
        for x in range(w):
            a = pad[y + p - lo : y + p - lo + n, x + p - lo : x + p - lo + n].mean(axis=(0, 1))
            ref[y, x] = a + 0.2 * (1 + k) * (img[y, x] - a)
    assert np.abs(out - ref).max() < 1e-5


def test_contrast_interpolates_between_integer_levels_and_keeps_the_fovea():
    img = textured_image(40, 50)
    s1 = contrast_enhance(img, np.full((40, 50), 1.0, np.float32), 0.3)
    s2 = contrast_enhance(img, np.full((40, 50), 2.0, np.float32), 0.3)
    mid = contrast_enhance(img, np.full((40, 50), 1.25, np.float32), 0.3)
    assert np.abs(mid - (0.75 * s1 + 0.25 * s2)).max() < 1e-5
    sig = np.zeros((40, 50), np.float32)
    assert np.array_equal(contrast_enhance(img, sig, 0.3), img)
    # the pipeline's one-pass change of luminance is the enhanced image less the input
    grey = img[..., 1].copy()
    ramp = np.linspace(0, 3.5, 50, dtype=np.float32)[None, :].repeat(40, 0)
    change = contrast_change(grey, ramp, 0.3)
    assert np.abs(change - (contrast_enhance(grey, ramp, 0.3) - grey)).max() < 1e-6
    assert np.all(change[:, 0] == 0)


def test_the_contrast_asks_for_sigma_only_where_its_change_is_not_zero():
    """contrast_change_where_needed reads the sigma map only on the blocks it asks for (NaN
    elsewhere changes nothing) and gives contrast_change's result bit for bit."""
    from fovexp import pyramids
    from fovexp.contrast import contrast_change_where_needed

    grey = textured_image(240, 320, rgb=False)
    grey[:, 150:] = 0.25  # flat right part
    yy, xx = np.mgrid[0:240, 0:320]
    sigma = (0.02 * np.hypot(xx - 60, yy - 100)).astype(np.float32)
    blocks = pyramids.constant_radius_blocks(*pyramids.channel_block_extremes(grey[..., None], 3))
    asked = []

    def on_blocks(need, shift):
        asked.append(need.copy())
        px = np.kron(need, np.ones((1 << shift, 1 << shift), bool))[:240, :320]
        return np.where(px, sigma, np.nan).astype(np.float32)

    got = contrast_change_where_needed(grey, on_blocks, float(sigma.max()), 0.3, blocks)
    want = contrast_change(grey, sigma, 0.3, blocks)
    assert np.array_equal(got.view(np.uint32), want.view(np.uint32))
    assert len(asked) == 1 and 0.3 < asked[0].mean() < 0.8  # the flat part was not asked for
    assert np.abs(want).max() > 1e-3
    # a bound above the map's maximum reaches farther: the same result
    got = contrast_change_where_needed(grey, on_blocks, 2 * float(sigma.max()), 0.3, blocks)
    assert np.array_equal(got.view(np.uint32), want.view(np.uint32))
