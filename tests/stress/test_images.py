"""Extreme images (issue 10, section 3): all black, all white, constant, a Nyquist
checkerboard, one bright or dark pixel, random, ramps; 8-bit, 16-bit and float values; odd
sizes; grey, grey + alpha, RGB, RGBA. Every invariant of :func:`checks.check_result` holds
(no NaN/Inf in any map or the output, the values in range before anything clips, K within its
headroom, alpha unchanged), the noise leaves the range rarely, and images too small for the
enhancer are refused in one line by the API and the CLI."""

from __future__ import annotations

import contextlib
import functools
import io

import numpy as np
import pytest
from hypothesis import event, given, settings
from hypothesis import strategies as st

from fovexp import EngineOptions, Enhancer, FovexpError, gabor, load_display, make_params
from fovexp.cli import main
from fovexp.colour import luminance
from fovexp.params import PAPER

from stress.checks import check_result, colour_of, eps
from stress.strategies import (
    MIN_SIDE_PX,
    examples,
    gazes,
    image_cases,
    noisy_setups,
    param_kwargs,
    peripheral_setups,
    viewports,
)

LG = load_display("lg-oled55cx")


@given(case=image_cases(), kw=param_kwargs(), gaze=gazes, data=st.data())
def test_extreme_images_keep_every_invariant(case, kw, gaze, data):
    img = case.image()
    vp = data.draw(viewports(case.height, case.width))
    enh = Enhancer(LG, preset=kw["preset"])
    enh.set_image(img, viewport=vp)
    check_result(enh, enh.enhance(gaze, make_params(**kw)), img)


#: Noisy pixels needed before the fraction pushed out of range is judged.
NOISE_CLIP_MIN_PIXELS = 500
#: Area (px) of one excursion of the noise past 3 std at the least: out-of-range pixels come in
#: clumps, which sets the sampling error of their fraction on a small image.
EXCURSION_PX = 30


def excursion_px(f_cpp: float) -> float:
    """Area (px) of one excursion of the noise past 3 std: a lobe of the carrier, half a period
    (1 / (2 F)) along it by the envelope's width across it (twice its std, 1 / (a sqrt(2 pi)),
    16 px); at least :data:`EXCURSION_PX`. At the low frequencies of a strong blur (F = 0.02
    cycles/px) a lobe is some 400 px, and a 16 x 44 image holds fewer than two."""
    across_px = 2.0 / (PAPER.gabor_a_cpp * np.sqrt(2.0 * np.pi))
    return max(EXCURSION_PX, 0.5 / f_cpp * across_px)


@functools.cache
def three_std_tail(impulses: int) -> float:
    """P(|noise| > K / 2) of the noise at a constant K (400 x 400 px, one seed): the share of
    pixels the clipping control's K / 2 = 3 std headroom (section 4.2) cannot keep in range.
    0.3 % with 512 impulses (Gaussian: 0.27 %), 0.9 % with 12, 3.3 % with 1: sparse noise has
    heavier tails."""
    size, margin = 400, 24
    imp = gabor.generate_impulses(size, size, impulses, PAPER.gabor_a_cpp, 7)
    rng = np.random.default_rng(7)
    m = len(imp)
    noise = gabor.synthesize((size, size), imp, np.ones(m), rng.uniform(0.05, 0.5, m),
                             rng.uniform(0.0, np.pi, m), impulses, PAPER.gabor_a_cpp)
    return float((np.abs(noise[margin:-margin, margin:-margin]) > 0.5).mean())


@st.composite
def judged_noisy_setups(draw):
    """(case, params kwargs, viewport, gaze, built): half the examples from
    :func:`noisy_setups` (mostly small images, often too few noisy pixels to judge), half
    built to have the noise over thousands of pixels (:func:`peripheral_setups`: 64 px or
    more, textured, the band open across the image). Issue 19: 7 of CI's 12 examples had
    been too small to judge."""
    if draw(st.booleans()):
        # values within [0.3, 0.7], the table's f_e, 12 impulses or more: headroom for K
        # and noise over the image (a strong f_e or values at 0 and 1 leave K = 0). The
        # table's s_f too: at the top of its range (50) about half the impulses draw F near
        # 0 (eq. 5 truncates to (0, F_H)), kernels without a carrier whose variance is up to
        # twice the normalisation's, and the 3-std headroom does not hold (found by the long
        # profile: 3.4 % of noisy pixels out of range, the tail 0.35 %; benchmarks/MUTATION.md)
        case, kw, vp, gaze = draw(peripheral_setups(kinds=("mid_texture",), methods=("ours",)))
        kw.update(preset="paper",
                  impulses=draw(st.sampled_from([12, 64, 512]) | st.integers(12, 512)))
        kw.pop("f_e", None)
        kw.pop("s_f", None)
        return case, kw, vp, gaze, True
    return (*draw(noisy_setups(presets=("paper",))), False)


@settings(max_examples=examples(1.0))
@given(setup=judged_noisy_setups())
def test_the_noise_leaves_the_range_no_more_than_its_tail_before_clipping(setup):
    """The composed linear result, contrast + noise, before the encoding clips it. Where the
    noise pushes a channel out of [0, 1] beyond where the contrast image already was, it is in
    its tail past K / 2: that happens to no larger a share of the noisy pixels than the noise's
    own 3-std tail at this impulse count (measured beside it), within the sampling error of
    the image's clumps, whose size is set by the noise's frequency (4 standard errors). The
    widened clipping rule, whose headroom is over every channel and every block the kernel
    reaches (the paper's one block of luminance lets more clip: benchmarks/CLIPPING.md)."""
    case, kw, vp, gaze, built = setup
    img = case.image()
    enh = Enhancer(LG, options=EngineOptions(clipping="widened"))
    enh.set_image(img, viewport=vp)
    res = enh.enhance(gaze, make_params(**kw))
    maps = check_result(enh, res, img)
    con = res.linear("contrast")
    noise = maps["noise"]
    comp = con + (noise[..., None] if con.ndim == 3 else noise)
    tol = eps(comp.dtype)
    beyond = (comp > np.maximum(con, 1.0) + tol) | (comp < np.minimum(con, 0.0) - tol)
    beyond = beyond.any(axis=2) if beyond.ndim == 3 else beyond
    noisy = noise != 0
    n = int(noisy.sum())
    event(f"noisy pixels >= {NOISE_CLIP_MIN_PIXELS}: judged" if n >= NOISE_CLIP_MIN_PIXELS
          else "too few noisy pixels to judge")
    if built:  # the case this example was made for
        assert n >= NOISE_CLIP_MIN_PIXELS, n
    if n >= NOISE_CLIP_MIN_PIXELS:
        tail = three_std_tail(res.params.impulses)
        # the noise's typical frequency there: the centre of its log-normal, sqrt(F_L F_H)
        f_cpp = float(np.median(np.sqrt(res.map("f_low_cpp")[noisy].astype(np.float64)
                                        * res.map("f_high_cpp")[noisy])))
        allowed = tail + 4.0 * np.sqrt(tail * excursion_px(f_cpp) / n)
        assert beyond[noisy].mean() <= allowed, (beyond[noisy].mean(), tail, f_cpp, allowed)


@settings(max_examples=examples(0.5))
@given(case=image_cases(kinds=("texture", "random", "white")), gaze=gazes,
       kw=param_kwargs(), data=st.data())
def test_alpha_comes_back_unchanged_and_the_colour_as_without_it(case, gaze, kw, data):
    """Grey + alpha and RGBA: the alpha channel bit for bit, the colour as the same frame
    without an alpha channel gives (the alpha changes nothing else)."""
    img = case.image()
    colour, alpha = colour_of(img)
    if alpha is None:
        img = np.dstack([colour, data.draw(st.sampled_from([0.0, 1.0, 0.5]))
                         * np.ones(colour.shape[:2], np.float32)]).astype(np.float32)
        colour, alpha = colour_of(img)
    vp = data.draw(viewports(case.height, case.width))
    params = make_params(**kw)
    with_a, without = Enhancer(LG, preset=kw["preset"]), Enhancer(LG, preset=kw["preset"])
    with_a.set_image(img, viewport=vp)
    without.set_image(colour, viewport=vp)
    a, b = with_a.enhance(gaze, params).output, without.enhance(gaze, params).output
    assert np.array_equal(a[..., -1], alpha)
    assert np.array_equal(a[..., :-1].reshape(b.shape), b)


small_sides = st.sampled_from([1, 2, MIN_SIDE_PX - 1]) | st.integers(1, MIN_SIDE_PX - 1)


@given(h=small_sides | st.integers(MIN_SIDE_PX, 64), w=small_sides, flip=st.booleans(),
       channels=st.sampled_from([1, 2, 3, 4]))
def test_images_too_small_are_refused_in_one_line(h, w, flip, channels):
    """1x1, 1xN, Nx1 and anything below 16 px a side: one FovexpError line naming the size
    and the minimum (the pyramids and the 8 px blocks need 16 px; the decision is in
    fovexp.pipeline.check_image)."""
    if flip:
        h, w = w, h
    shape = (h, w) if channels == 1 else (h, w, channels)
    enh = Enhancer(LG)
    with pytest.raises(FovexpError) as exc:
        enh.set_image(np.full(shape, 0.5, np.float32))
    msg = str(exc.value)
    assert "\n" not in msg and f"is {w}x{h} px" in msg and "at least 16x16" in msg


def run_cli(*argv: object) -> tuple[int, str]:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            rc = main([str(a) for a in argv])
        except SystemExit as exc:  # argparse
            rc = exc.code
    return rc, err.getvalue()


@settings(max_examples=examples(0.5))
@given(h=small_sides, w=st.integers(1, 40), flip=st.booleans())
def test_the_cli_refuses_images_too_small_in_one_line(tmp_path_factory, h, w, flip):
    from fovexp import write_image

    if flip:
        h, w = w, h
    folder = tmp_path_factory.mktemp("small")
    src, out = folder / "in.png", folder / "out.png"
    write_image(src, np.full((h, w), 0.5, np.float32))
    rc, err = run_cli("enhance", src, out)
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 1 and lines[0].startswith("fovexp: error:"), err
    assert f"{w}x{h} px" in lines[0] and "at least 16x16" in lines[0]
    assert not out.exists()


@st.composite
def checker_setups(draw):
    """(case, params kwargs, viewport, gaze, built): half the examples anywhere (any viewport,
    any gaze: mostly little blur on a small image), half built to blur the checkerboard by
    2.5 to 5 px with room inside the border (``built``: the property's case in every one of
    them; issue 19: in CI's 6 examples the case had been reached in none)."""
    if draw(st.booleans()):
        setup = draw(peripheral_setups(kinds=("checker",),
                                       methods=("foveated", "contrast", "ours")))
        return (*setup, True)
    case = draw(image_cases(kinds=("checker",), channels=(1, 3)))
    return (case, draw(param_kwargs()), draw(viewports(case.height, case.width)), draw(gazes),
            False)


@settings(max_examples=examples(0.5))
@given(setup=checker_setups())
def test_a_nyquist_checkerboard_foveates_towards_its_mean(setup):
    """A checkerboard of 0 and 1 at Nyquist: its foveated linear luminance stays in [0, 1]
    and where the blur is wide (sigma >= 2 px) it is its mean 1/2 within 5 %: the blur stack
    does not alias the finest pattern into a coarser one."""
    case, kw, vp, gaze, built = setup
    img = case.image()
    enh = Enhancer(LG, preset=kw["preset"])
    enh.set_image(img, viewport=vp)
    res = enh.enhance(gaze, make_params(**kw))
    y = luminance(res.linear("foveated"))
    assert y.min() >= -eps(y.dtype) and y.max() <= 1 + eps(y.dtype)
    sigma = res.map("sigma_px")
    h, w = sigma.shape
    yy, xx = np.mgrid[0:h, 0:w]
    to_border = np.minimum(np.minimum(yy, h - 1 - yy), np.minimum(xx, w - 1 - xx))
    # away from the borders, where the symmetric padding repeats a column of the pattern
    wide = (sigma >= 2.0) & (to_border >= np.ceil(3 * sigma.max()))
    event("wide blur inside the border: judged" if wide.any() else "no wide blur: not judged")
    if built:  # the case this example was made for
        assert wide.mean() > 0.05, (wide.mean(), float(sigma.max()))
    if wide.any():
        assert np.abs(y[wide] - 0.5).max() <= 0.05, np.abs(y[wide] - 0.5).max()
