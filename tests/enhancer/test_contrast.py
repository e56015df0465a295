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
