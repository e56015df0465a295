"""Float32 against float64 stage by stage (``EngineOptions(dtype="float64")``), determinism
(same seed, same bytes; two enhancers; the stage cache; skipping on and off bit for bit), and
the noise's std / K = 1/6 (notes 3.9) over the impulse options."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import event, given, settings
from hypothesis import strategies as st

from fovexp import EngineOptions, Enhancer, gabor, make_params
from fovexp.amplitude import RELEASE_AMPLITUDE_GAIN
from fovexp.orientation import GRADIENT_EPS, ORIENTATION_LEVEL
from fovexp.params import PAPER
from fovexp.pyramids import sample_cubic

from stress.checks import check_result
from stress.strategies import examples, noisy_setups
from stress.test_images import LG

#: float32 against float64, absolute, per map (its unit): each a few hundred float32 ulps of
#: the map's scale, far below anything visible (1/255 of the output is 3.9e-3)
TOLERANCE = {
    "eccentricity_deg": 1e-4, "sigma_px": 1e-4, "f_high_cpp": 1e-6,
    "foveated": 1e-5, "contrast": 1e-5,
}


def _open_impulses(enh: Enhancer) -> np.ndarray:
    """Indices of the impulses whose band is open and neighbourhood not flat (internal)."""
    band = enh._c.get("imp_active")
    return band.index[band.open_]


@settings(max_examples=examples(1.0))
@given(setup=noisy_setups())
def test_float32_follows_float64_stage_by_stage(setup):
    case, kw, vp, gaze = setup
    img = case.image()
    params = make_params(**kw)
    res, enh = {}, {}
    for dtype in ("float32", "float64"):
        enh[dtype] = Enhancer(LG, preset=kw["preset"], options=EngineOptions(dtype=dtype))
        enh[dtype].set_image(img, viewport=vp)
        res[dtype] = enh[dtype].enhance(gaze, params)
        check_result(enh[dtype], res[dtype], img)
    r32, r64 = res["float32"], res["float64"]
    # the contrast gain f_e (1 + k) multiplies the foveation's rounding (fovexp.contrast)
    gain = max(1.0, r64.params.f_e * (1 + math.ceil(float(r64.map("sigma_px").max()))))
    for name, tol in TOLERANCE.items():
        a, b = r32.map(name), r64.map(name)
        if name in ("foveated", "contrast"):
            a, b = r32.linear(name), r64.linear(name)
        tol *= gain if name == "contrast" else 1.0
        assert np.abs(a.astype(np.float64) - b).max() <= tol, (name, np.abs(a - b).max())
    # F_L where the band is open: sigma = blur (e - fovea) ppd cancels near the fovea's edge,
    # where F_L = 3 / (2 pi sigma) is far above F_H (the band is empty) in either precision
    f32, f64 = r32.map("f_low_cpp"), r64.map("f_low_cpp")
    band = f64 < r64.map("f_high_cpp")
    assert np.allclose(f32[band], f64[band], rtol=1e-4)
    # per impulse: K and F agree wherever both give the impulse noise; the orientation where
    # the gradient is a real edge (>= 100 GRADIENT_EPS): near GRADIENT_EPS its direction is
    # rounding, in either precision (fovexp.orientation), and so is the noise's phase there
    b32, b64 = enh["float32"]._c.get("imp_active"), enh["float64"]._c.get("imp_active")
    common, at32, at64 = np.intersect1d(b32.index, b64.index, return_indices=True)
    differ = np.setxor1d(b32.index, b64.index)
    event("the same impulses carry noise" if differ.size == 0 else "an impulse on its band edge")
    k32 = enh["float32"]._c.get("imp_amplitude")[at32]
    k64 = enh["float64"]._c.get("imp_amplitude")[at64]
    k_max = max(float(np.abs(k64).max(initial=0.0)), 1e-12)
    # |L| carries the float32 rounding of the luminance (a few ulps of 1), times s_k's gain;
    # a K set by the clipping control (K = 2 x headroom) carries the contrast image's
    # rounding, twice (the long profile drew f_e = 2 at blur-rate 5 on white: K = 1.8e-5
    # in float64, 0 in float32, the contrast 9e-6 from 1)
    k_ulp = r64.params.s_k * RELEASE_AMPLITUDE_GAIN * 4 * float(np.finfo(np.float32).eps)
    limited = k64 >= enh["float64"]._c.get("imp_headroom")[at64]
    k_tol = 1e-4 * k_max + k_ulp + np.where(limited, 2 * TOLERANCE["contrast"] * gain, 0.0)
    assert (np.abs(k32 - k64) <= k_tol).all(), np.abs(k32 - k64).max(initial=0.0)
    f32 = enh["float32"]._c.get("imp_frequency")[at32]
    f64 = enh["float64"]._c.get("imp_frequency")[at64]
    assert np.allclose(f32, f64, rtol=1e-4, atol=0)
    gx, gy = enh["float64"]._c.get("gradients")
    x, y = b64.x_px[at64], b64.y_px[at64]
    edge = np.hypot(sample_cubic(gx, x, y, ORIENTATION_LEVEL),
                    sample_cubic(gy, x, y, ORIENTATION_LEVEL)) >= 100 * GRADIENT_EPS
    o32 = enh["float32"]._c.get("imp_orientation")[at32].astype(np.float64)
    o64 = enh["float64"]._c.get("imp_orientation")[at64]
    turn = np.abs(np.angle(np.exp(1j * (o32 - o64)[edge])))
    assert turn.max(initial=0.0) <= 1e-3, turn.max()
    # the noise itself, where every impulse is well conditioned
    if differ.size == 0 and edge.all():
        event("noise compared pixel by pixel")
        n32, n64 = r32.map("noise").astype(np.float64), r64.map("noise")
        assert np.abs(n32 - n64).max() <= 1e-3 * k_max + 1e-6
        out = np.abs(r32.output.astype(np.float64) - r64.output)
        assert out.max() <= 1e-3, out.max()


@settings(max_examples=examples(1.0))
@given(setup=noisy_setups(), dtype=st.sampled_from(["float32", "float64"]))
def test_same_seed_same_bytes_and_skipping_is_exact(setup, dtype):
    """Two enhancers, and skipping on and off, give the same bytes; so does the first
    enhancer after a parameter step and back (its stage cache)."""
    case, kw, vp, gaze = setup
    img = case.image()
    params = make_params(**kw)
    outs = []
    for skip in (True, True, False):
        enh = Enhancer(LG, preset=kw["preset"], options=EngineOptions(dtype=dtype, skip=skip))
        enh.set_image(img, viewport=vp)
        res = enh.enhance(gaze, params)
        outs.append((res.output.tobytes(), res.map("noise").tobytes(),
                     res.map("amplitude").tobytes()))
        if len(outs) == 1:
            first = enh
    assert outs[0] == outs[1], "two enhancers differ"
    assert outs[0] == outs[2], "skipping changed the result"
    first.enhance(gaze, params.model_copy(update={"s_k": 0.5 * (params.s_k or 20.0), "seed": 7}))
    again = first.enhance(gaze, params)
    assert again.output.tobytes() == outs[0][0], "the stage cache changed the result"


@st.composite
def noise_cases(draw):
    """Impulses per kernel (enough for the std to be measured: 12 .. 512), the impulse
    options, and a region holding at least MIN_IMPULSES impulses."""
    n = draw(st.sampled_from([12, 64, 512]) | st.integers(12, 512))
    opts = dict(count=draw(st.sampled_from(["poisson", "jittered"])),
                weights=draw(st.sampled_from(["uniform", "sign"])),
                cell_scale=draw(st.sampled_from([0.25, 1.0]) | st.floats(0.25, 1.0)))
    truncation = draw(st.sampled_from([1e-6, 0.01, 0.5]) | st.floats(1e-6, 0.5))
    return n, opts, truncation, draw(st.integers(0, 2**31 - 1))


#: impulses in the measured region: the std's relative sampling error is about
#: 0.7 / sqrt(impulses) (measured over seeds: 10 % with 34 impulses, 1 % with 2000)
MIN_IMPULSES = 5000
MARGIN_PX = 24  # the region's border, where the impulses outside the image are missing


@settings(max_examples=examples(0.5))
@given(case=noise_cases())
def test_noise_std_is_k_over_6(case):
    """The noise at a constant K has std K / 6 (docs/METHOD.md, 5.9; fovexp.gabor.normalisation)
    whatever the impulse count, count law, weights, cell size and kernel truncation (a
    kernel cut closer than 0.01 loses energy, which the normalisation makes up for: without
    that, 0.90 K / 6 at a cut of 0.5). Frequencies in the band's range 0.05 .. 0.5
    cycles/px, random orientations. Tolerance: 5 standard errors of the estimate, 5 *
    sqrt((0.7^2 / impulses) + (1.3 / side)^2) (the second term: a Gaussian field's std
    measured over side^2 px, 0.6 % at 208 px), plus 0.5 % for the normalisation's fixed
    frequency (exp(-2 pi F^2 / a^2) at 0.05 cycles/px) and the truncation."""
    n, opts, truncation, seed = case
    a = PAPER.gabor_a_cpp
    density = gabor.impulse_density(n, a)
    side = int(math.ceil(math.sqrt(MIN_IMPULSES / density))) + 2 * MARGIN_PX
    imp = gabor.generate_impulses(side, side, n, a, seed, **opts)
    rng = np.random.default_rng(seed)
    m = len(imp)
    k = 0.3
    noise = gabor.synthesize((side, side), imp, np.full(m, k), rng.uniform(0.05, 0.5, m),
                             rng.uniform(0.0, np.pi, m), n, a, truncation)
    inner = side - 2 * MARGIN_PX
    measured = float(noise[MARGIN_PX:-MARGIN_PX, MARGIN_PX:-MARGIN_PX].std()) / k * 6.0
    held = density * inner * inner
    tol = 5.0 * math.sqrt(0.7**2 / held + (1.3 / inner) ** 2) + 0.005
    assert abs(measured - 1.0) <= tol, (measured, tol, held)
