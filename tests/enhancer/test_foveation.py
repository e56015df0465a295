"""Foveation (paper section 5.2; docs/METHOD.md, 6.5): the fast blur stack against the exact
spatially varying convolution, and the fovea left as it is."""

import numpy as np
import pytest
from scipy import ndimage

from fovexp.colour import linearize
from fovexp.foveation import foveate, foveate_exact

from engine_helpers import textured_image


def _radial_sigma(h, w, max_sigma):
    yy, xx = np.mgrid[0:h, 0:w]
    r = np.hypot(xx - w / 2, yy - h / 2) / np.hypot(w / 2, h / 2)
    return (max_sigma * np.clip((r - 0.2) / 0.8, 0, None)).astype(np.float32)


def test_exact_reference_equals_gaussian_filter_for_constant_sigma():
    img = textured_image(60, 80)
    s = np.full((60, 80), 2.3, np.float32)
    ref = ndimage.gaussian_filter(img, (2.3, 2.3, 0), mode="nearest")
    assert np.abs(foveate_exact(img, s) - ref).max() < 1e-5


@pytest.mark.parametrize("max_sigma", [3.0, 12.0])
def test_fast_foveation_error_against_exact_convolution(max_sigma):
    """Stated bound (benchmarks/RESULTS.md): RMS < 0.002, max < 0.02 on [0, 1]."""
    img = linearize(textured_image(270, 480), 2.2)
    sigma = _radial_sigma(270, 480, max_sigma)
    fast = foveate(img, sigma)
    rng = np.random.default_rng(1)
    ys, xs = rng.integers(0, 270, 4000), rng.integers(0, 480, 4000)
    err = fast[ys, xs] - foveate_exact(img, sigma, ys, xs)
    assert np.sqrt(np.mean(err**2)) < 0.002
    assert np.abs(err).max() < 0.02


def test_foveation_leaves_sigma_zero_pixels_bit_exact():
    img = linearize(textured_image(), 2.2)
    sigma = _radial_sigma(270, 480, 6.0)
    out = foveate(img, sigma)
    zero = sigma == 0
    assert zero.sum() > 1000
    assert np.array_equal(out[zero], img[zero])
    assert np.abs(out[~zero] - img[~zero]).max() > 0.01  # and it does blur elsewhere


def test_a_blur_beyond_any_display_is_refused_in_one_line(monkeypatch):
    """A blur whose padded image would not fit is one clear error, not a MemoryError."""
    from fovexp import FovexpError, foveation

    monkeypatch.setattr(foveation, "MAX_PADDED_BYTES", 2**20)
    img = textured_image(64, 64, seed=1)
    sigma = np.full((64, 64), 200.0, np.float32)  # pad 4 sigma: (64 + 1600)^2 x 3 x 4 bytes
    with pytest.raises(FovexpError, match=r"blur reaches sigma = 200 px on a 64x64 image"):
        foveate(img, sigma)
    assert foveate(img, np.full((64, 64), 2.0, np.float32)).shape == img.shape


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_the_sigma_bound_is_above_every_pixel_of_the_map(dtype):
    """sigma_bound_px sizes the blur stack and the contrast's boxes without the map: it must
    not fall below any pixel's sigma as the map computes it, also where the largest
    eccentricity is only a few float32 steps past the fovea, at the largest blur-rate."""
    from fovexp import load_display
    from fovexp.foveation import sigma_bound_px, sigma_px
    from fovexp.geometry import ViewingGeometry

    lg = load_display("lg-oled55cx")
    rng = np.random.default_rng(5)
    for i in range(40):
        w, h = int(rng.integers(16, 300)), int(rng.integers(16, 200))
        x0, y0 = int(rng.integers(0, 3840 - w)), int(rng.integers(0, 2160 - h))
        g = ViewingGeometry.for_image(lg, w, h, viewport=(x0, y0, 3840, 2160))
        gaze = g.gaze_px(tuple(rng.random(2)))
        fovea = float(rng.uniform(1.0, 40.0))
        if i % 2:  # the largest eccentricity just past the fovea
            ecc_max = g.max_eccentricity_and_ppd(gaze)[0]
            fovea = float(np.nextafter(np.float32(ecc_max), np.float32(0)) - 1e-6 * i)
        rate = float(rng.choice([0.34, 5.0]))
        if dtype == np.float32:
            ecc, ppd = g.eccentricity_and_ppd_maps(gaze)
        else:
            x, y = g.grid()
            ecc, ppd = g.eccentricity_deg(x, y, gaze), g.ppd(x, y)
        sigma = sigma_px(ecc, ppd, rate, fovea, dtype)
        bound = sigma_bound_px(g, gaze, rate, fovea)
        assert float(sigma.max()) <= bound, (i, fovea)
        # ... and not far above it (a bound too high costs work: a wider stack and boxes).
        # The bound takes the largest eccentricity and the largest ppd over the image's
        # corners, half a pixel past the outer pixels' centres (0.71 px: the eccentricity a
        # little over 0.71 / min(ppd) deg more), even where they are at different corners:
        # the paper's formula (section 5.2) at those two maxima, with the bound's own
        # relative 1e-4 and 1e-3 px, written out here in float64
        e_hi = float(ecc.max()) + 0.75 / float(ppd.min())
        upper = rate / 60.0 * max(0.0, e_hi - fovea) * float(ppd.max()) * (1 + 2e-4) + 2e-3
        assert bound <= upper, (i, bound, upper)


def _sigma_in_numpy_float32(ecc, ppd, rate, fovea):
    """The sigma formula step by step in NumPy's float32 arithmetic (what sigma_px's float32
    result is defined as)."""
    a = np.array(ecc, dtype=np.float32)
    a -= np.float32(fovea)
    np.maximum(a, 0.0, out=a)
    a *= np.float32(rate)
    return (a / np.float32(60.0) * ppd).astype(np.float32)


@pytest.mark.parametrize("viewport", [None, (1000, 300, 3840, 2160)])
def test_the_sigma_map_of_some_blocks_is_the_whole_maps_there(viewport):
    """sigma_on_blocks (one pass, no eccentricity map; the ppd map evaluated or read) gives
    sigma_px of the float32 grids bit for bit on the blocks asked for and leaves the other
    pixels as they were; and sigma_px in float32 is NumPy's float32 arithmetic step by step
    (float32 grids, and float64 points as the per-impulse band gives them), at the fovea's
    edge too."""
    from fovexp import load_display
    from fovexp.foveation import sigma_on_blocks, sigma_px
    from fovexp.geometry import ViewingGeometry

    w, h = (600, 400) if viewport else (960, 540)
    g = ViewingGeometry.for_image(load_display("lg-oled55cx"), w, h, viewport=viewport)
    rng = np.random.default_rng(8)
    for rate, q in ((0.34, 10), (5.0, 50), (1.7, 90)):
        gaze = g.gaze_px(tuple(rng.random(2)))
        ecc, ppd = g.eccentricity_and_ppd_maps(gaze)
        fovea = float(np.percentile(ecc, q))  # the fovea's edge in the frame
        full = sigma_px(ecc, ppd, rate, fovea)
        want = _sigma_in_numpy_float32(ecc, ppd, rate, fovea)
        assert np.array_equal(full.view(np.uint32), want.view(np.uint32))
        assert (full == 0).any() and (full > 0).any()
        x, y = rng.random(5000) * (w - 1), rng.random(5000) * (h - 1)
        e64, p64 = g.eccentricity_deg(x, y, gaze), g.ppd(x, y)
        assert np.array_equal(sigma_px(e64, p64, rate, fovea).view(np.uint32),
                              _sigma_in_numpy_float32(e64, p64, rate, fovea).view(np.uint32))
        need = rng.random((-(-h // 8), -(-w // 8))) < 0.3
        px = np.kron(need, np.ones((8, 8), bool))[:h, :w]
        out = np.full((h, w), -1.0, np.float32)
        got = sigma_on_blocks(g, gaze, rate, fovea, need, 3, out)
        assert got is out and (got[~px] == -1.0).all()
        assert np.array_equal(got[px].view(np.uint32), full[px].view(np.uint32))
        assert np.array_equal(sigma_on_blocks(g, gaze, rate, fovea).view(np.uint32),
                              full.view(np.uint32))
        # every block asked for writes every pixel (partial edge blocks too): the map may
        # start empty then (sigma_on_blocks' own, _SigmaBlocks')
        out = np.full((h, w), np.nan, np.float32)
        every = np.ones_like(need)
        got = sigma_on_blocks(g, gaze, rate, fovea, every, 3, out)
        assert np.array_equal(got.view(np.uint32), full.view(np.uint32))
        # the geometry's px/deg map (gaze-free, kept by the enhancer) is the grids', and
        # the map read from it is the same map
        kept = g.ppd_map()
        assert np.array_equal(kept.view(np.uint32), ppd.view(np.uint32))
        out = np.full((h, w), -1.0, np.float32)
        got = sigma_on_blocks(g, gaze, rate, fovea, need, 3, out, ppd_map=kept)
        assert (got[~px] == -1.0).all()
        assert np.array_equal(got[px].view(np.uint32), full[px].view(np.uint32))
        assert np.array_equal(sigma_on_blocks(g, gaze, rate, fovea, ppd_map=kept).view(
            np.uint32), full.view(np.uint32))
    with pytest.raises(ValueError, match="ppd_map must be float32"):
        sigma_on_blocks(g, gaze, 0.34, 8.0, ppd_map=np.ones((h, w)))


# --- small inputs, for the mutation runs (their kernels run as Python there) and as unit
# checks of each formula of the stage (issue 19)

def test_sigma_px_is_the_papers_formula():
    """sigma = blur_rate / 60 * max(0, e - fovea) * ppd (px; section 5.2), float32 or
    float64, 0 inside the fovea."""
    from fovexp.foveation import sigma_px

    ecc = np.array([3.0, 8.0, 20.0, 45.5])
    ppd = np.array([39.0, 40.0, 44.0, 51.0])
    want = 0.34 / 60 * np.maximum(ecc - 8.0, 0) * ppd
    got = sigma_px(ecc, ppd, 0.34, 8.0, np.float64)
    assert got.dtype == np.float64 and np.allclose(got, want, rtol=1e-14, atol=0)
    got32 = sigma_px(ecc.astype(np.float32), ppd.astype(np.float32), 0.34, 8.0)
    assert got32.dtype == np.float32 and np.allclose(got32, want, rtol=1e-6)
    assert sigma_px(np.float64(20.0), np.float64(44.0), 5.0, 8.0, np.float64) == pytest.approx(
        5 / 60 * 12 * 44, rel=1e-14)


def test_the_blur_stack_and_its_kernels():
    """Stack sigmas 0.25 px apart up to 1.5 px, then x 2**0.25; each level blurred on the
    coarsest pyramid level whose residual blur is still >= 1.25 level px, with the residual
    Gaussian: pyramid blur and residual add up (in variance) to the stack sigma."""
    from fovexp.foveation import (
        MIN_RESIDUAL_LEVEL_PX,
        STACK_RATIO,
        blur_stack_plan,
        gaussian_kernel,
        stack_sigmas_px,
    )
    from fovexp.pyramids import gaussian_sigma_px

    assert STACK_RATIO == 2**0.25 and MIN_RESIDUAL_LEVEL_PX == 1.25
    s = stack_sigmas_px(3.0)
    assert s[:7] == pytest.approx([0, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5])
    # then by the ratio until 3 is reached (1.5 * 2**(4/4) lands a rounding below 3: one more)
    assert s[7:] == pytest.approx([1.5 * 2 ** (k / 4) for k in range(1, s.size - 6)])
    assert s[-2] < 3.0 <= s[-1] and stack_sigmas_px(0.3).tolist() == s[:7].tolist()
    plan = blur_stack_plan(40.0)
    assert plan.sigmas_px[-1] >= 40.0 and plan.top == int(plan.pyramid_level.max()) >= 3
    for sig, m, g in zip(plan.sigmas_px, plan.pyramid_level, plan.kernels, strict=True):
        m = int(m)
        r = g.size // 2
        res = np.sqrt(max(sig**2 - gaussian_sigma_px(m) ** 2, 0.0)) / 2**m
        if sig > 0:
            assert res >= 1.25 or m == 0
            nxt = np.sqrt(max(sig**2 - gaussian_sigma_px(m + 1) ** 2, 0.0)) / 2 ** (m + 1)
            assert nxt < 1.25
            assert r == int(4 * res + 0.5)
            assert np.allclose(g, gaussian_kernel(res))
        else:
            assert g.tolist() == [1.0]
    step = 2**plan.top
    assert plan.pad_px % step == 0 and plan.pad_px >= 4 * 40.0 + 2 * step
    assert plan.pad_px < 4 * 40.0 + 3 * step
    assert plan.reach_px() == max(2**int(m) * (g.size // 2 + 1) + 2 * (2**int(m) - 1)
                                  for m, g in zip(plan.pyramid_level, plan.kernels, strict=True))
    assert blur_stack_plan(1.0).pad_px == 0  # no pyramid: no border
    g = gaussian_kernel(1.7, np.float64)
    d = np.arange(-7, 8)
    assert g.size == 15 and np.allclose(g, np.exp(-d**2 / (2 * 1.7**2)) / np.exp(
        -d**2 / (2 * 1.7**2)).sum(), rtol=1e-14)
    assert gaussian_kernel(1.7).dtype == np.float32


def test_the_exact_reference_is_the_gaussian_of_each_pixels_own_sigma():
    """foveate_exact: SciPy's gaussian_filter (nearest borders, 4 sigma) for a constant
    sigma, and each pixel with its own sigma otherwise (pixels at two sigmas each compared
    with the constant-sigma filter of their own); sigma 0 keeps the pixel."""
    img = textured_image(20, 26, seed=3, rgb=False, flat_squares=False)
    for s in (0.8, 1.7):
        ref = ndimage.gaussian_filter(img.astype(np.float64), s, mode="nearest")
        assert np.abs(foveate_exact(img, np.full(img.shape, s, np.float32)) - ref).max() < 1e-6
    sigma = np.where(np.arange(26)[None, :] < 13, 0.8, 1.7).astype(np.float32).repeat(20, 0)
    sigma[5, 5] = 0.0
    got = foveate_exact(img.astype(np.float64), sigma)
    assert got.dtype == np.float64 and got[5, 5] == img[5, 5]
    for s, cols in ((0.8, slice(0, 5)), (1.7, slice(13, 26))):
        ref = ndimage.gaussian_filter(img.astype(np.float64), s, mode="nearest")
        assert np.abs(got[:, cols] - ref[:, cols]).max() < 1e-6
    ys, xs = np.array([0, 19, 7]), np.array([25, 0, 14])
    assert np.allclose(foveate_exact(img, sigma, ys, xs), got[ys, xs], atol=1e-6)


@pytest.mark.parametrize("max_sigma,rgb", [(2.6, False), (9.0, True)])
def test_small_fast_foveation_against_the_exact_convolution(max_sigma, rgb):
    """The blur stack on a 44 x 60 image (the same bounds as on 270 x 480: RMS < 0.002,
    max < 0.02), sigma 0 bit for bit, the blur there elsewhere; float64 kept; the sigma map
    asked for by blocks gives the same result."""
    img = linearize(textured_image(44, 60, seed=6, rgb=rgb, flat_squares=False), 2.2)
    sigma = _radial_sigma(44, 60, max_sigma)
    fast = foveate(img, sigma)
    rng = np.random.default_rng(2)
    ys, xs = rng.integers(0, 44, 60), rng.integers(0, 60, 60)
    err = fast[ys, xs] - foveate_exact(img, sigma, ys, xs)
    assert np.sqrt(np.mean(err**2)) < 0.002 and np.abs(err).max() < 0.02
    zero = sigma == 0
    assert zero.sum() > 50 and np.array_equal(fast[zero], img[zero])
    assert np.abs(fast[~zero] - img[~zero]).max() > 0.01
    assert np.array_equal(foveate(img, sigma, skip=False), fast)
    f64 = foveate(img.astype(np.float64), sigma)
    assert f64.dtype == np.float64 and np.abs(f64 - fast).max() < 1e-5

    def on_blocks(need, shift):
        return sigma

    assert np.array_equal(foveate(img, on_blocks, max_sigma_px=float(sigma.max())), fast)
    with pytest.raises(ValueError, match="needs max_sigma_px"):
        foveate(img, on_blocks)
    flat = np.full((44, 60), 0.3, np.float32)
    assert np.array_equal(foveate(flat, sigma), flat)  # a constant stays its constant
    assert np.array_equal(foveate(img, np.zeros((44, 60), np.float32)), img)


def test_the_sigma_map_of_some_blocks_on_a_small_frame():
    """sigma_on_blocks on a 40 x 56 image in a 1920 x 1080 frame: on the 8 px blocks asked
    for, sigma_px of the float32 maps bit for bit; elsewhere what ``out`` held; the whole
    frame when no blocks are given; refused for another geometry model."""
    from fovexp import load_display
    from fovexp.foveation import sigma_on_blocks, sigma_px
    from fovexp.geometry import ViewingGeometry

    g = ViewingGeometry.for_image(load_display("lg-oled55cx"), 56, 40,
                                  viewport=(1500, 900, 1920, 1080))
    gaze = g.gaze_px((0.2, 0.3))
    ecc, ppd = g.eccentricity_and_ppd_maps(gaze)
    fovea = float(np.percentile(ecc, 30))
    full = sigma_px(ecc, ppd, 1.7, fovea)
    assert (full == 0).any() and (full > 0).any()
    assert np.array_equal(sigma_on_blocks(g, gaze, 1.7, fovea).view(np.uint32),
                          full.view(np.uint32))
    need = np.zeros((5, 7), bool)
    need[1, 2] = need[4, 6] = True
    out = np.full((40, 56), -1.0, np.float32)
    got = sigma_on_blocks(g, gaze, 1.7, fovea, need, 3, out)
    assert got is out
    mask = np.kron(need, np.ones((8, 8), bool))
    assert np.array_equal(got[mask], full[mask]) and (got[~mask] == -1).all()
    with pytest.raises(ValueError, match="exact geometry model"):
        sigma_on_blocks(ViewingGeometry.for_image(load_display("lg-oled55cx"), 56, 40,
                                                  "linear"), gaze, 1.7, fovea)


def test_the_padded_image_is_measured_exactly(monkeypatch):
    """The guard's figure is the padded image's size, (H + 2 pad)(W + 2 pad) C bytes-per-value
    (pad: the blur stack's border), refused just above the limit and let through at it."""
    from fovexp import FovexpError, foveation

    img = textured_image(40, 56, seed=1, flat_squares=False)
    sigma = np.full((40, 56), 30.0, np.float32)
    pad = foveation.blur_stack_plan(30.0).pad_px
    size = (40 + 2 * pad) * (56 + 2 * pad) * 3 * 4
    monkeypatch.setattr(foveation, "MAX_PADDED_BYTES", size - 1)
    with pytest.raises(FovexpError, match=f"would take {size / 2**30:.3g} GiB"):
        foveate(img, sigma)
    monkeypatch.setattr(foveation, "MAX_PADDED_BYTES", size)
    assert foveate(img, sigma).shape == img.shape


def test_the_pyramid_level_of_a_blur_and_a_run_of_blurred_columns():
    """A stack level is blurred on the coarsest pyramid level where its residual blur is still
    1.25 level px: sigma = sqrt(30) is the edge between levels 1 and 2 (the residual there
    sqrt(sigma^2 - 5) / 4). Columns blurred next to columns left sharp: each blurred pixel as
    the exact convolution gives it, to the stack's accuracy, to the last blurred column, and
    bit for bit what it is when the run of blurred columns goes on farther."""
    from fovexp.foveation import _pyramid_level_for

    assert _pyramid_level_for(np.sqrt(30) - 0.01) == 1 and _pyramid_level_for(np.sqrt(30)) == 2
    assert _pyramid_level_for(0.9) == 0
    img = linearize(textured_image(44, 61, seed=8, rgb=False, flat_squares=False), 2.2)
    for s in (3.0, 6.0):
        sigma = np.zeros((44, 61), np.float32)
        sigma[:, :30] = s  # the run ends mid-image, at column 29: off the levels' grids
        fast = foveate(img, sigma)
        ys, xs = np.nonzero(sigma[::3, [0, 7, 20, 27, 28, 29]])
        ys, xs = ys * 3, np.array([0, 7, 20, 27, 28, 29])[xs]
        err = fast[ys, xs] - foveate_exact(img, sigma, ys, xs)
        assert np.abs(err).max() < 0.01, (s, np.abs(err).max())
        assert np.array_equal(fast[:, 30:], img[:, 30:])
        # a blurred pixel does not depend on how far the run of blurred columns goes on
        wider = sigma.copy()
        wider[:, :50] = s
        assert np.array_equal(foveate(img, wider)[:, :30], fast[:, :30])


def test_negative_zero_sigmas_and_blur_rates_are_zero():
    """-0.0 is 0: a sigma map holding -0.0 is blurred as the map with +0.0 bit for bit (those
    pixels left as they are), fast and exact, with and without skipping; a blur-rate of -0.0
    gives the map of +0.0, every pixel +0.0 (sigma_px, sigma_on_blocks, the bound 1e-3 px)."""
    from fovexp import load_display
    from fovexp.foveation import sigma_bound_px, sigma_on_blocks, sigma_px
    from fovexp.geometry import ViewingGeometry

    img = linearize(textured_image(40, 56, seed=3, flat_squares=False), 2.2)
    sigma = np.zeros((40, 56), np.float32)
    sigma[:, 28:] = 2.5
    negative = sigma.copy()
    negative[:, :28] = -0.0
    for blur in (lambda s: foveate(img, s), lambda s: foveate(img, s, skip=False),
                 lambda s: foveate_exact(img, s)):
        out = blur(negative)
        assert out.tobytes() == blur(sigma).tobytes()
        assert out[:, :18].tobytes() == img[:, :18].tobytes()  # 10 px (4 sigma) off the blur
        zero = np.zeros((40, 56), np.float32)
        assert blur(-zero).tobytes() == blur(zero).tobytes() == img.tobytes()
    g = ViewingGeometry.for_image(load_display("lg-oled55cx"), 56, 40,
                                  viewport=(1500, 900, 1920, 1080))
    gaze = g.gaze_px((0.2, 0.3))
    ecc, ppd = g.eccentricity_and_ppd_maps(gaze)
    for dtype in (np.float32, np.float64):
        neg = sigma_px(ecc, ppd, -0.0, 8.0, dtype)
        assert neg.tobytes() == sigma_px(ecc, ppd, 0.0, 8.0, dtype).tobytes()
        assert not np.signbit(neg).any()
    assert sigma_on_blocks(g, gaze, -0.0, 8.0).tobytes() == np.zeros((40, 56), np.float32).tobytes()
    assert sigma_bound_px(g, gaze, -0.0, 8.0) == sigma_bound_px(g, gaze, 0.0, 8.0) == 1e-3


@pytest.mark.parametrize("max_sigma", [6.0, 12.0])
def test_a_mostly_flat_frames_pyramid_is_computed_only_where_it_is_read(monkeypatch, max_sigma):
    """Skipping builds the blur stack's pyramid only on the columns its patches can read
    (pyramids.wanted_columns): with every other value of the pyramid's buffer NaN, a frame
    flat but for a few textured islands (one at an edge, so that the replicated border is
    read) foveates bit for bit as without skipping; at the smaller blur it computes under
    0.9 of the pyramid (at the larger one the patches' reach covers nearly all of it)."""
    from fovexp import foveation, pyramids

    h, w = 480, 720
    img = np.full((h, w, 3), 0.4, np.float32)
    tex = linearize(textured_image(h, w, seed=8, flat_squares=False), 2.2)
    for y0, x0, size in ((40, 60, 24), (220, 560, 40), (h - 20, 0, 20)):
        img[y0:y0 + size, x0:x0 + size] = tex[y0:y0 + size, x0:x0 + size]
    sigma = _radial_sigma(h, w, max_sigma)
    real = pyramids.packed_pyramid
    written = []

    def poisoned(image, levels, pad_px=0, columns=None, buffer=None):
        buf = np.full(image.size * 2, np.nan, image.dtype)
        out = real(image, levels, pad_px, columns, buf)
        written.append(np.count_nonzero(~np.isnan(out[0])) / out[0].size)
        return out

    monkeypatch.setattr(foveation, "packed_pyramid", poisoned)
    got = foveate(img, sigma)
    assert written and written[0] < (0.9 if max_sigma < 10 else 1.0) and not np.isnan(got).any()
    assert np.array_equal(got.view(np.uint32), foveate(img, sigma, skip=False).view(np.uint32))
