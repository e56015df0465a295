"""The engine's implementation options (EngineOptions, issue 10 section 1): each does what it
says, measured against the method's own statistics or the exact computation it stands for."""

import math

import numpy as np
import pytest

from fovexp import (
    EngineOptions,
    EnhanceParams,
    Enhancer,
    FovexpError,
    foveation,
    gabor,
    load_display,
    make_enhancer,
    make_options,
    pyramids,
)
from fovexp.params import PAPER

from engine_helpers import textured_image

LG = load_display("lg-oled55cx")


def test_defaults_are_the_method_and_bad_values_are_named():
    o = EngineOptions()
    assert (o.skip, o.foveation, o.clipping, o.dtype) == (True, "pyramid", None, "float32")
    assert (o.kernel_truncation, o.impulse_count, o.weights, o.cell_scale) == (
        0.01, "poisson", "uniform", 1.0)
    assert o.non_default() == {}
    assert make_options(weights="sign").non_default() == {"weights": "sign"}
    for kw, field in (({"dtype": "float16"}, "dtype"), ({"cell_scale": 2.0}, "cell_scale"),
                      ({"kernel_truncation": 0.0}, "kernel_truncation"), ({"skipp": 1}, "skipp")):
        with pytest.raises(FovexpError, match=field):
            make_options(**kw)
    with pytest.raises(FovexpError, match="clipping"):
        make_options(clipping="widest")
    # the rule: the option's, else the preset's (every rule runs under either preset)
    assert Enhancer(LG).clipping == PAPER.clipping
    assert Enhancer(LG, preset="release").clipping == "release"
    assert Enhancer(LG, preset="release", options=EngineOptions(clipping="exact")).clipping == (
        "exact")
    enh = make_enhancer(LG, backend="cpu", options=EngineOptions(dtype="float64"))
    assert enh.options.dtype == "float64"
    # the GPU implements skip only: "auto" takes the CPU for the rest
    auto = make_enhancer(LG, options=EngineOptions(weights="sign"))
    assert auto.backend == "cpu"
    assert auto.fallback_reason is not None  # said, never silent (the runner shows it)


# ------------------------------------------------------------------------------- float64


@pytest.mark.slow  # the first float64 run compiles every kernel again (about a minute)
def test_float64_and_float32_agree_stage_by_stage():
    """float64 is the reference: every image stage really runs in float64, and float32
    agrees with it to float32 rounding stage by stage. The noise differs a little more where
    the gradient's direction is ill-conditioned (|G| just above GRADIENT_EPS): orientation is
    float32 rounding there; K is small there, so the noise differs by < 0.2 % of its peak."""
    image = textured_image(270, 480, seed=4)
    p = EnhanceParams(blur_rate=0.57, impulses=24)
    enh = {}
    for dt in ("float32", "float64"):
        e = Enhancer(LG, options=EngineOptions(dtype=dt))
        e.set_image(image)
        e.enhance((0.5, 0.5), p)
        enh[dt] = e
    tolerance = {"linear": 2e-7, "foveated": 1e-6, "luma": 1e-6, "contrast": 1e-6}
    for stage, tol in tolerance.items():
        a, b = (e._c.get(stage) for e in (enh["float32"], enh["float64"]))
        if stage == "contrast":  # its zeros outside the rows' spans, written
            a, b = a.full(), b.full()
        assert a.dtype == np.float32 and b.dtype == np.float64, stage
        d = np.abs(a - b).max()
        assert 0 < d < tol, (stage, d)
    for k, lap in enh["float64"]._c.get("abs_laplacian_full").items():
        ref = enh["float32"]._c.get("abs_laplacian_full")[k]
        assert lap.dtype == np.float64 and np.abs(lap - ref).max() < 1e-6, k
    n32, n64 = enh["float32"]._c.get("noise").full(), enh["float64"]._c.get("noise").full()
    assert n64.dtype == np.float64 and np.abs(n32 - n64).max() < 2e-3 * np.abs(n64).max()
    o32, o64 = (e._c.get("output") for e in (enh["float32"], enh["float64"]))
    assert o64.dtype == np.float64
    d = np.abs(o32 - o64)
    assert d.max() < 2e-3 and np.sqrt((d**2).mean()) < 2e-5


# -------------------------------------------------------------------------- noise variants


def _std_over_k(n: int, **kw) -> float:
    h, w = 600, 800
    imp = gabor.generate_impulses(w, h, n, 0.06, 2, **kw)
    m = len(imp)
    rng = np.random.default_rng(0)
    noise = gabor.synthesize((h, w), imp, np.full(m, 0.3), rng.uniform(0.08, 0.4, m),
                             rng.uniform(0, np.pi, m), n, 0.06)
    return float(noise[40:-40, 40:-40].std() / 0.3)


@pytest.mark.parametrize("kw", [
    {"count": "jittered"}, {"weights": "sign"}, {"cell_scale": 0.5},
    {"count": "jittered", "weights": "sign", "cell_scale": 0.5},
])
@pytest.mark.parametrize("n", [12, 64])
def test_faster_noise_variants_keep_the_noise_std_at_k_over_6(kw, n):
    """docs/METHOD.md, 5.9: std / K = 1/6 whatever the impulses; the variants keep the density
    (and the normalisation follows E[w^2]), so they keep it too."""
    assert _std_over_k(n, **kw) == pytest.approx(1 / 6, rel=0.04)


def test_the_variants_are_what_they_say():
    n, a = 12, 0.06
    jit = gabor.generate_impulses(4000, 3000, n, a, 3, count="jittered")
    poi = gabor.generate_impulses(4000, 3000, n, a, 3)
    m = n / math.pi  # mean impulses per cell
    for imp in (jit, poi):
        inside = (imp.x_px >= 0) & (imp.x_px < 4000) & (imp.y_px >= 0) & (imp.y_px < 3000)
        assert inside.sum() / (4000 * 3000) == pytest.approx(gabor.impulse_density(n, a), rel=0.02)
    counts = np.bincount(gabor.cell_index(jit.y_px, jit.cell_px) * 1000
                         + gabor.cell_index(jit.x_px, jit.cell_px))
    counts = counts[counts > 0]
    assert set(np.unique(counts)) <= {math.floor(m), math.floor(m) + 1}
    sign = gabor.generate_impulses(400, 300, n, a, 3, weights="sign")
    uni = gabor.generate_impulses(400, 300, n, a, 3)
    assert set(np.unique(sign.weight)) == {-1.0, 1.0}
    assert np.array_equal(sign.x_px, uni.x_px) and np.array_equal(sign.weight, np.sign(uni.weight))
    assert gabor.normalisation(n, a, "sign") == pytest.approx(
        gabor.normalisation(n, a) / math.sqrt(3))
    small = gabor.generate_impulses(400, 300, n, a, 3, cell_scale=0.5)
    assert small.cell_px == pytest.approx(gabor.kernel_radius_px(a) / 2)


def test_the_kernel_truncation_sets_how_far_a_kernel_reaches():
    h, w = 121, 121
    imp = gabor.Impulses(np.array([60.3]), np.array([60.0]), np.array([1.0], np.float32),
                         np.array([0.5]), gabor.cell_size_px(0.06), 0)
    for t in (0.05, 0.01, 1e-4):
        noise = gabor.synthesize((h, w), imp, np.ones(1), np.array([0.1]), np.zeros(1), 12,
                                 0.06, truncation=t)
        r = gabor.kernel_radius_px(0.06, t)
        cols = np.flatnonzero(np.abs(noise).max(axis=0) > 0)
        # the square of half-side r around x = 60.3
        assert cols.min() == math.ceil(60.3 - r) and cols.max() == min(math.floor(60.3 + r), w - 1)
    # r = sqrt(-ln t / pi) / a: 1e-4 reaches sqrt(2) times as far as 1e-2
    assert gabor.kernel_radius_px(0.06, 1e-4) == pytest.approx(
        math.sqrt(2) * gabor.kernel_radius_px(0.06))


def test_enhancer_options_reach_the_noise():
    image = textured_image(270, 480, seed=2)
    p = EnhanceParams(blur_rate=0.57, impulses=12)
    noise = {}
    for kw in ({}, {"kernel_truncation": 1e-4}, {"weights": "sign"}, {"impulse_count": "jittered"},
               {"cell_scale": 0.5}):
        e = Enhancer(LG, options=EngineOptions(**kw))
        e.set_image(image)
        noise[tuple(kw)] = e.enhance((0.5, 0.5), p).map("noise")
    base = noise[()]
    for key, n in noise.items():
        if key:
            assert np.abs(n - base).max() > 1e-3, key  # they change the noise ...
            assert n.std() == pytest.approx(base.std(), rel=0.15), key  # ... not its strength


# -------------------------------------------------------------------- exact counterparts


def test_the_exact_foveation_option_runs_the_exact_convolution():
    image = textured_image(68, 120, seed=1)
    e = Enhancer(LG, options=EngineOptions(foveation="exact"))
    e.set_image(image)
    res = e.enhance((0.3, 0.5), EnhanceParams(blur_rate=2.0, method="foveated"))
    sigma = res.map("sigma_px")
    assert sigma.max() > 1.0
    exact = foveation.foveate_exact(e._c.get("linear"), sigma)
    assert np.array_equal(res.linear("foveated"), exact)
    fast = foveation.foveate(e._c.get("linear"), sigma)
    assert np.abs(fast - exact).max() > 1e-5  # the fast one is not it


def test_the_exact_clipping_rule_takes_the_kernel_s_own_neighbourhood():
    """N_min, N_max over exactly the pixels an impulse's truncated kernel covers: a brute-force
    check at the impulses, and never less headroom than the widened level-3 blocks (whose
    neighbourhood contains the kernel's), so K is never smaller."""
    image = textured_image(270, 480, seed=6)
    p = EnhanceParams(blur_rate=0.57, impulses=24)
    enh = {}
    for ex in ("widened", "exact"):
        e = Enhancer(LG, options=EngineOptions(clipping=ex, skip=False))
        e.set_image(image)
        e.enhance((0.5, 0.5), p)
        enh[ex] = e
    e = enh["exact"]
    ext = e._c.get("headroom")
    assert ext.kind == "window"
    lo, hi = ext.lo, ext.hi
    band = e._c.get("imp_active")
    r = gabor.kernel_radius_px(0.06)
    img = e._c.get("foveated") + e._c.get("contrast").full()[..., None]
    reaches = ((band.x_px > -r) & (band.x_px < 479 + r) & (band.y_px > -r)
               & (band.y_px < 269 + r))  # impulses whose kernel meets the image
    pick = np.random.default_rng(0).choice(np.flatnonzero(reaches), 200, replace=False)
    lo_w, hi_w = pyramids.window_extremes(lo, hi, r, band.x_px[pick], band.y_px[pick])
    for i, j in enumerate(pick):
        x, y = band.x_px[j], band.y_px[j]
        xs = slice(max(math.ceil(x - r), 0), min(math.floor(x + r), 479) + 1)
        ys = slice(max(math.ceil(y - r), 0), min(math.floor(y + r), 269) + 1)
        assert lo_w[i] == img[ys, xs].min() and hi_w[i] == img[ys, xs].max()
    h_exact = e._c.get("imp_headroom")
    h_pyr = enh["widened"]._c.get("imp_headroom")
    assert (h_exact >= h_pyr).all() and (h_exact > h_pyr).mean() > 0.3
    k_exact, k_pyr = e._c.get("imp_amplitude"), enh["widened"]._c.get("imp_amplitude")
    assert (k_exact >= k_pyr).all() and (k_exact > k_pyr).any()
    # the amplitude map evaluates the same windows at every pixel (a separable filter)
    lo_map, hi_map = pyramids.window_extremes(lo, hi, r)
    ys, xs = np.array([0, 100, 269]), np.array([5, 240, 479])
    lo_pt, hi_pt = pyramids.window_extremes(lo, hi, r, xs.astype(float), ys.astype(float))
    assert np.array_equal(lo_map[ys, xs], lo_pt) and np.array_equal(hi_map[ys, xs], hi_pt)
