"""Contrast enhancement (Patney et al. 2016 as the release applies it; docs/METHOD.md, 5.3)
against a brute-force evaluation of its formula.

The inputs are textured (no flat square of ``textured_image``): on a constant box every
formula gives a change of 0, so a test on one could not tell the release's gain from a wrong
one (issue 19). Each test checks that its reference changes the image by a visible amount."""

import numpy as np
import pytest

from fovexp.contrast import box_width_px, contrast_change, contrast_enhance

from engine_helpers import textured_image


def release_contrast(img: np.ndarray, sigma: np.ndarray, f_e: float) -> np.ndarray:
    """The release's formula written out pixel by pixel in float64 (docs/METHOD.md, 5.3):
    per integer level k, avg_k (box of width 4 k, MATLAB's anchoring, on the symmetric
    padding that np.pad makes, repeated where the box is wider than the image) and
    out_k = avg_k + f_e (1 + k) (in - avg_k); out_0 = in; linear between floor(sigma) and
    floor(sigma) + 1."""
    src = img.astype(np.float64)
    h, w = src.shape[:2]
    p = 4 * (int(sigma.max()) + 1)
    pad = np.pad(src, ((p, p), (p, p)) + ((0, 0),) * (src.ndim - 2), mode="symmetric")
    out = np.empty_like(src)
    for y in range(h):
        for x in range(w):
            s = float(sigma[y, x])
            k0 = int(np.floor(s))
            t = s - k0
            acc = 0.0
            for k, weight in ((k0, 1.0 - t), (k0 + 1, t)):
                if weight == 0.0:
                    continue
                if k == 0:
                    acc = acc + weight * src[y, x]
                    continue
                n = 4 * k
                lo = (n - 1) // 2
                avg = pad[y + p - lo: y + p - lo + n, x + p - lo: x + p - lo + n].mean(axis=(0, 1))
                acc = acc + weight * (avg + f_e * (1 + k) * (src[y, x] - avg))
            out[y, x] = acc
    return out


@pytest.mark.parametrize("k,h,w", [(1, 40, 50), (2, 40, 50), (3, 40, 50), (6, 12, 14)])
def test_contrast_enhancement_matches_brute_force_release_formula(k, h, w):
    """Integer levels; the last case's box (24 px) is wider than the image, where the padding
    repeats its mirror (as MATLAB's padarray)."""
    img = textured_image(h, w, seed=k, flat_squares=False)
    assert img.std() > 0.05  # textured: a wrong gain, width or anchoring shows
    assert box_width_px(k) == 4 * k
    sigma = np.full((h, w), float(k), np.float32)
    ref = release_contrast(img, sigma, 0.2)
    assert np.abs(ref - img).max() > 0.02  # the formula changes this image
    out = contrast_enhance(img, sigma, 0.2)
    assert np.abs(out - ref).max() < 1e-5


def test_contrast_interpolates_between_integer_levels_and_keeps_the_fovea():
    """A sigma that varies across the image (0 to 3.5, rows and columns): each pixel
    interpolates between its two integer levels, by its own weight; sigma 0 is unchanged."""
    img = textured_image(40, 50, seed=5, flat_squares=False)
    yy, xx = np.mgrid[0:40, 0:50]
    sigma = (3.5 * xx / 49 * (0.6 + 0.4 * yy / 39)).astype(np.float32)
    assert (sigma == 0).sum() == 40 and (sigma % 1 > 0.1).mean() > 0.5
    ref = release_contrast(img, sigma, 0.3)
    assert np.abs(ref - img).max() > 0.05
    assert np.abs(contrast_enhance(img, sigma, 0.3) - ref).max() < 1e-5
    assert np.array_equal(contrast_enhance(img, np.zeros((40, 50), np.float32), 0.3), img)
    # the pipeline's one-pass change of luminance is the enhanced image less the input
    grey = img[..., 1].copy()
    change = contrast_change(grey, sigma, 0.3)
    assert np.abs(change - (release_contrast(grey, sigma, 0.3) - grey)).max() < 1e-6
    assert np.all(change[:, 0] == 0)
    assert np.abs(contrast_change(grey.astype(np.float64), sigma, 0.3)
                  - (release_contrast(grey, sigma, 0.3) - grey)).max() < 1e-12


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
    # ... and the whole image computed (no block left out) gives the same bits
    full = contrast_change(grey, sigma, 0.3)
    assert np.array_equal(full.view(np.uint32), want.view(np.uint32))
    assert len(asked) == 1 and 0.3 < asked[0].mean() < 0.8  # the flat part was not asked for
    assert np.abs(want).max() > 1e-3
    # a bound above the map's maximum reaches farther: the same result
    got = contrast_change_where_needed(grey, on_blocks, 2 * float(sigma.max()), 0.3, blocks)
    assert np.array_equal(got.view(np.uint32), want.view(np.uint32))


def test_the_table_border_and_its_limit():
    """The summed-area table's border is half the widest box (level floor(max) + 1) plus one;
    a frame whose exact sums would overflow int64 is refused in one line; a map without blur
    changes nothing."""
    from fovexp import FovexpError
    from fovexp.contrast import SAT_FRACTION_BITS, check_sat_fits, sat_pad_px

    assert [sat_pad_px(s) for s in (0.0, 0.9, 1.0, 2.5, 6.0)] == [3, 3, 5, 7, 15]
    assert SAT_FRACTION_BITS == 36
    check_sat_fits((4320, 7680), 64, 1.0)  # an 8K frame fits (docs: a margin of 3.8)
    # the limit to 0.1 %, on a frame that is not square: (H + 2 pad)(W + 2 pad) 2**36 v
    hp, wp = 4320 + 2 * 64, 7680 + 2 * 64
    v = (2**63 - 1) / (hp * wp * 2.0**36)
    check_sat_fits((4320, 7680), 64, 0.999 * v)
    with pytest.raises(FovexpError, match="too large"):
        check_sat_fits((4320, 7680), 64, 1.001 * v)
    with pytest.raises(FovexpError, match="too large for the contrast stage's exact sums"):
        check_sat_fits((4320, 7680), 64, 4.0)
    with pytest.raises(FovexpError, match="76800x43200 frame"):
        check_sat_fits((43200, 76800), 0, 0.5)  # a value below 1 counts as 1
    grey = textured_image(20, 30, rgb=False, flat_squares=False)
    zero = np.zeros((20, 30), np.float32)
    assert np.array_equal(contrast_change(grey, zero, 0.3), zero)
    assert contrast_change(grey.astype(np.float64), zero, 0.3).dtype == np.float64


def test_flat_blocks_are_left_out_exactly():
    """With the image's constant radius per 8 x 8 block, the blocks whose boxes all lie in one
    constant region are not computed (their change is exactly 0) and the others are
    computed on a table limited to where their boxes reach: the same result bit for bit,
    also when every block or none is flat."""
    from fovexp import pyramids
    from fovexp.contrast import contrast_change_where_needed

    # 61 rows (not a multiple of the 8-row chunks), texture over most of them
    grey = np.full((61, 80), 0.4, np.float32)
    grey[12:, 50:] = textured_image(49, 30, seed=7, rgb=False, flat_squares=False)
    sigma = np.full((61, 80), 1.5, np.float32)
    flat = pyramids.constant_radius_blocks(*pyramids.channel_block_extremes(grey[..., None], 3))
    want = contrast_change(grey, sigma, 0.25)  # every pixel computed
    got = contrast_change(grey, sigma, 0.25, flat)  # the flat blocks left out
    assert np.array_equal(got.view(np.uint32), want.view(np.uint32))
    assert np.abs(want).max() > 1e-3 and (want[:, :30] == 0).all()
    assert (np.abs(want[12:, 50:]) > 0).mean() > 0.9  # every textured row computed

    def on_blocks(need, shift):
        return sigma

    got = contrast_change_where_needed(grey, on_blocks, 1.5, 0.25, flat)
    assert np.array_equal(got.view(np.uint32), want.view(np.uint32))
    const = np.full((61, 80), 0.4, np.float32)
    cflat = pyramids.constant_radius_blocks(*pyramids.channel_block_extremes(const[..., None], 3))
    assert not contrast_change_where_needed(const, on_blocks, 1.5, 0.25, cflat).any()
    assert not contrast_change(const, sigma, 0.25, cflat).any()
    assert not contrast_change_where_needed(grey, on_blocks, 0.0, 0.25, flat).any()


def test_negative_zero_sigmas_and_f_e_change_nothing_more_than_zero():
    """-0.0 is 0: a sigma map holding -0.0 gives the change and the enhanced image of the map
    with +0.0 bit for bit (0 where sigma is 0: those pixels keep their value), and an f_e of
    -0.0 the change of f_e = 0."""
    img = textured_image(40, 50, seed=5, rgb=False, flat_squares=False)
    sigma = np.zeros((40, 50), np.float32)
    sigma[:, 25:] = 3.4
    negative = sigma.copy()
    negative[:, :25] = -0.0
    change = contrast_change(img, negative, 0.2)
    assert change.tobytes() == contrast_change(img, sigma, 0.2).tobytes()
    assert not change[:, :25].any() and change[:, 25:].any()
    rgb = np.stack([img, img[::-1], img[:, ::-1]], axis=-1)
    assert (contrast_enhance(rgb, negative, 0.2).tobytes()
            == contrast_enhance(rgb, sigma, 0.2).tobytes())
    zero = np.zeros_like(sigma)
    assert contrast_change(img, -zero, 0.2).tobytes() == np.zeros_like(img).tobytes()
    assert contrast_enhance(rgb, -zero, 0.2).tobytes() == rgb.tobytes()
    assert (contrast_change(img, sigma, -0.0).tobytes()
            == contrast_change(img, sigma, 0.0).tobytes())
