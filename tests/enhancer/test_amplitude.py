"""Amplitude (paper section 4.2, eqs. 6-9, corrected as docs/METHOD.md, 3.1-3.2) and the
clipping control's headroom."""

import math

import numpy as np
import pytest
from scipy import ndimage

from fovexp import amplitude as amp
from fovexp import pyramids


@pytest.mark.parametrize("a", [0.25, 0.1])
def test_selected_level_centre_is_attenuated_by_a(a):
    sigma = np.array([1.0, 2.0, 4.0, 7.5])
    level = amp.laplacian_level(sigma, a)
    f = amp.band_centre_cpp(level)
    response = np.exp(-2 * math.pi**2 * sigma**2 * f**2)  # Gaussian blur's frequency response
    assert np.allclose(response, a)


def test_measured_attenuation_crosses_a_at_the_selected_level():
    """Blur white noise by sigma and measure each Laplacian band's amplitude ratio (blurred /
    sharp). The (log-interpolated) level where the ratio crosses a = 0.25 is the level eq. 8
    (corrected, docs/METHOD.md, 3.1) selects, within 0.75 level: a band's RMS ratio averages the
    blur's response over an octave, which puts the measured crossing 0.3-0.5 level below the
    centre-frequency figure. The paper's uncorrected eq. 8 is off by 1.5-2 levels here.)"""
    rng = np.random.default_rng(0)
    img = rng.random((1024, 1024)).astype(np.float32)

    def rms(band):
        m = min(8, band.shape[0] // 4)  # away from the borders
        return np.sqrt(np.mean(band[m:-m, m:-m] ** 2))

    la = pyramids.laplacian_levels(pyramids.gaussian_pyramid(img, 7), 6)
    for sigma in (1.5, 3.0, 6.0):
        selected = float(amp.laplacian_level(np.array(sigma), 0.25))
        blurred = ndimage.gaussian_filter(img, sigma, mode="wrap")
        lb = pyramids.laplacian_levels(pyramids.gaussian_pyramid(blurred, 7), 6)
        ratio = np.array([rms(lb[k]) / rms(la[k]) for k in sorted(la)])
        levels = np.array(sorted(la), dtype=float)
        # past a ratio of 0.9 the bands are untouched (ratio ~ 1) and only noise is left
        upto = int(np.argmax(ratio > 0.9)) + 1 if (ratio > 0.9).any() else ratio.size
        ratio, levels = ratio[:upto], levels[:upto]
        assert np.all(np.diff(ratio) > 0)  # coarser bands are attenuated less
        crossing = np.interp(np.log(0.25), np.log(ratio), levels)
        assert abs(crossing - selected) < 0.75, (sigma, selected, crossing, ratio)


def test_headroom_limit_never_negative():
    k = amp.headroom_limit(np.array([0.2, -0.1, 0.9]), np.array([0.7, 0.5, 1.2]))
    assert np.allclose(k, [0.4, 0.0, 0.0])


def test_headroom_limit_and_its_cells_are_the_numpy_formula_bit_for_bit():
    """The compiled limit is max(2 min(1 - N_max, N_min), 0) as NumPy evaluates it: float32
    arithmetic for float32 extremes, NaN passed through, -0.0 kept (NumPy's minimum and
    maximum); at points on cells, each point's float32 position clipped at 0 and its cell
    (``sample_nearest``), for blocks of a power of two and not."""
    def numpy_limit(n_min, n_max):
        return np.maximum(2.0 * np.minimum(1.0 - n_max, n_min), 0.0)

    rng = np.random.default_rng(4)
    lo = np.concatenate([rng.uniform(-0.2, 1.2, 2000), [0.2, -0.0, np.nan, 0.5, 0.0]])
    hi = np.concatenate([rng.uniform(-0.2, 1.2, 2000), [1.0, 1.0, 0.3, np.nan, 0.5]])
    for dtype in (np.float64, np.float32):
        got = amp.headroom_limit(lo.astype(dtype), hi.astype(dtype))
        assert got.dtype == dtype
        assert got.tobytes() == numpy_limit(lo.astype(dtype), hi.astype(dtype)).tobytes()
    grid_lo, grid_hi = (rng.uniform(0.0, 1.0, (9, 13)).astype(np.float32) for _ in range(2))
    x, y = rng.uniform(-40.0, 140.0, (2, 3000))
    x[:3], y[:3] = -0.0, [-1e-9, 7.5, 8.5]  # the clip at 0, and cells' edges
    for block in (8, 6):
        ext = amp.Extremes("blocks", grid_lo, grid_hi, block)
        xc, yc = np.clip(x.astype(np.float32), 0, None), np.clip(y.astype(np.float32), 0, None)
        want = numpy_limit(pyramids.sample_nearest(grid_lo, xc, yc, block),
                           pyramids.sample_nearest(grid_hi, xc, yc, block))
        got = amp.headroom_at(ext, 20.0, x, y)
        assert got.dtype == np.float32 and got.tobytes() == want.tobytes()


def test_the_formulas_of_eqs_7_to_9_by_hand():
    """f_c = sqrt(-2 ln a) / (2 pi sigma) (eq. 7, corrected), centre 2**-(l + 0.5) (eq. 6,
    levels from 1), l_a = log2(1 / f_c) - 0.5 at least 1 (eq. 8), and the release's gain
    3.5722 (docs/METHOD.md, 3.1-3.2 and 5.7), at values worked out by hand."""
    a = 0.25
    fc = math.sqrt(-2 * math.log(a)) / (2 * math.pi * 4.0)
    assert amp.attenuation_cutoff_cpp(np.array([4.0]), a)[0] == pytest.approx(fc, rel=1e-12)
    assert amp.attenuation_cutoff_cpp(np.array([0.0]), a)[0] == np.inf
    assert amp.band_centre_cpp(np.array([1.0, 2.5])) == pytest.approx(
        [2**-1.5, 2**-3.0], rel=1e-12)
    level = amp.laplacian_level(np.array([4.0, 0.05, 0.0]), a)
    assert level == pytest.approx([math.log2(1 / fc) - 0.5, 1.0, 1.0], rel=1e-12)
    assert amp.RELEASE_AMPLITUDE_GAIN == 3.5722


def test_bracketing_levels_and_their_reach():
    """(k0, t): the levels below and above a continuous level, at most the coarsest built,
    and the weight of the upper one (eq. 9's interpolation)."""
    k0, t = amp.bracketing_levels(np.array([1.0, 2.25, 7.5, 9.0]), 8)
    assert k0.tolist() == [1, 2, 7, 7] and t == pytest.approx([0.0, 0.25, 0.5, 1.0])
    k0, t = amp.bracketing_levels(np.array([1.0, 3.0]), 1)  # one level: no interpolation
    assert k0.tolist() == [1, 1] and t == pytest.approx([0.0, 0.0])
    reach = amp.laplacian_reach_px(np.array([1, 2, 7]), 7)
    assert reach.tolist() == [pyramids.abs_laplacian_reach_px(k) for k in (2, 3, 7)]


def test_laplacian_amplitude_interpolates_between_the_two_levels():
    """|L| at a continuous level: (1 - t) |L_k0| + t |L_k0+1|, each read on its own grid
    (level k lives on G_{k-1}'s grid); the coarsest level read alone."""
    levels = {k: np.full((64 >> (k - 1), 64 >> (k - 1)), float(10 * k)) for k in (1, 2, 3)}
    x, y = np.array([10.0, 20.0, 30.0]), np.array([12.0, 5.0, 40.0])
    got = amp.laplacian_amplitude_at(levels, np.array([1.0, 2.25, 3.0]), x, y)
    assert got == pytest.approx([10.0, 22.5, 30.0])
    ramp = {1: np.tile(np.arange(64.0), (64, 1)), 2: np.zeros((32, 32))}
    lo = amp.laplacian_amplitude_at(ramp, np.array([1.5]), np.array([20.0]), np.array([9.0]))
    assert lo[0] == pytest.approx(0.5 * 20.0)  # x = 20 on level 1's full-resolution grid


def test_headroom_limit_takes_the_nearer_side():
    """K <= 2 min(1 - N_max, N_min): 3 std either side within [0, 1] (section 4.2)."""
    k = amp.headroom_limit(np.array([0.3, 0.05, 0.5]), np.array([0.9, 0.5, 0.5]))
    assert k == pytest.approx([0.2, 0.1, 1.0])


def test_the_coarsest_level_is_the_one_a_blur_of_94_px_selects():
    """MAX_LAPLACIAN_LEVEL: the level eq. 8 selects (a = 0.25) for sigma = 94 px, centre
    2**-8.5 cycles/px (amplitude's docstring)."""
    assert amp.MAX_LAPLACIAN_LEVEL == 8
    assert amp.laplacian_level(np.array([94.0]), 0.25)[0] == pytest.approx(8.0, abs=0.05)


def test_each_clipping_rule_takes_its_own_neighbourhood():
    """The clipping control's rules (section 4.2; docs/METHOD.md, 6.6) on a grey 40 x 48 image
    holding one saturated red pixel at (x 20, y 12) and one white pixel at (x 37, y 12), 17 px
    to its right: worked out by hand at the red pixel (block (2, 1) of the level-3 grid)."""
    h, w = 40, 48
    fov = np.full((h, w, 3), 0.4, np.float32)
    fov[12, 20] = (0.9, 0.0, 0.0)
    fov[12, 37] = (1.0, 1.0, 1.0)
    luma = (fov @ np.array([0.299, 0.587, 0.114], np.float32)).astype(np.float32)
    delta = np.zeros((h, w), np.float32)
    r = 20.2
    x, y = np.array([20.0]), np.array([12.0])

    def at(rule):
        ext = amp.clipping_extremes(rule, fov, luma, delta, kernel_radius_px=r)
        return float(amp.headroom_at(ext, r, x, y)[0])

    # paper: one 8 x 8 block of luminance; the red pixel's luma 0.2691 is the block's minimum
    assert at("paper") == pytest.approx(2 * 0.299 * 0.9, rel=1e-6)
    # widened: its channels (green 0) over every block the kernel reaches: no headroom
    assert at("widened") == 0.0
    # release: a 25 px box of grey: the white pixel 17 px away is outside it (half-side 12)
    assert at("release") == pytest.approx(2 * 0.299 * 0.9, rel=1e-6)
    # exact: the channels of the kernel's square: green 0 again
    assert at("exact") == 0.0
    assert at("off") == np.inf
    # one block further right (x 28) the paper rule no longer sees the red pixel, the widened
    # rule still does (and reaches the white pixel: no room above either)
    ext = amp.clipping_extremes("paper", fov, luma, delta, kernel_radius_px=r)
    assert float(amp.headroom_at(ext, r, np.array([28.0]), y)[0]) == pytest.approx(0.8)
    ext = amp.clipping_extremes("widened", fov, luma, delta, kernel_radius_px=r)
    assert float(amp.headroom_at(ext, r, np.array([28.0]), y)[0]) == 0.0
    # the map at every pixel is the same function as at the points
    for rule in amp.CLIPPING_RULES:
        ext = amp.clipping_extremes(rule, fov, luma, delta, kernel_radius_px=r)
        full = amp.headroom_at(ext, r, shape=(h, w))
        ys, xs = np.array([0, 12, 12, 39]), np.array([0, 20, 28, 47])
        pts = amp.headroom_at(ext, r, xs.astype(float), ys.astype(float))
        assert np.array_equal(full[ys, xs], pts), rule
    with pytest.raises(ValueError, match="clipping rule"):
        amp.clipping_extremes("widest", fov, luma, delta, kernel_radius_px=r)


def test_a_negative_zero_sigma_selects_the_finest_level():
    """sigma = -0.0 is no blur, as +0.0: the finest Laplacian level (1), the level eq. 8
    clamps to, not a level of a negative cut-off."""
    level = amp.laplacian_level(np.array([-0.0, 0.0, 1e-300]), 0.25)
    assert level.tolist() == [1.0, 1.0, 1.0]
