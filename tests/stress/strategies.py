"""Hypothesis strategies of the stress tests: extreme images, parameters at every edge of their
ranges, displays from tiny to huge, gazes at the corners, and invalid values."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from hypothesis import assume, settings
from hypothesis import strategies as st

from fovexp import PARAMETER_RANGES, Display, load_display
from fovexp.geometry import MIN_PIXEL_ASPECT

#: smallest image side the enhancer accepts (fovexp.pipeline.check_image)
MIN_SIDE_PX = 16
#: largest side drawn: small images keep a property's cases fast
MAX_SIDE_PX = 96

IMAGE_KINDS = ("black", "white", "constant", "checker", "bright_pixel", "dark_pixel", "random",
               "texture", "ramp")


def examples(fraction: float, least: int = 3) -> int:
    """A fraction of the loaded profile's examples, for properties that cost more per case."""
    return max(least, int(settings.default.max_examples * fraction))


def draw_image(kind: str, h: int, w: int, channels: int, seed: int, level: float) -> np.ndarray:
    """A display-encoded float32 image in [0, 1] of ``kind`` (IMAGE_KINDS); ``channels`` 1 to 4
    (2 and 4 with an alpha channel, drawn independently of the colour)."""
    rng = np.random.default_rng(seed)
    colour_ch = 3 if channels >= 3 else 1
    yy, xx = np.mgrid[0:h, 0:w]
    if kind == "black":
        img = np.zeros((h, w, colour_ch))
    elif kind == "white":
        img = np.ones((h, w, colour_ch))
    elif kind == "constant":
        img = np.full((h, w, colour_ch), level)
    elif kind == "checker":  # the Nyquist frequency in both directions
        img = np.repeat(((xx + yy) % 2).astype(float)[..., None], colour_ch, axis=2)
    elif kind in ("bright_pixel", "dark_pixel"):
        img = np.zeros((h, w, colour_ch)) if kind == "bright_pixel" else np.ones((h, w, colour_ch))
        img[rng.integers(h), rng.integers(w)] = 1.0 if kind == "bright_pixel" else 0.0
    elif kind == "random":
        img = rng.random((h, w, colour_ch))
    elif kind == "ramp":
        img = np.repeat(((xx + yy) / max(h + w - 2, 1))[..., None], colour_ch, axis=2)
    else:  # texture: smooth noise, flat squares, saturated colours (mid_texture: softened)
        from scipy import ndimage

        tex = sum(ndimage.gaussian_filter(rng.standard_normal((h, w)), s) * s**0.5
                  for s in (0.7, 2.0, 5.0))
        tex = (tex - tex.min()) / max(float(tex.max() - tex.min()), 1e-12)
        tex[(xx // 24 + yy // 24) % 4 == 0] = level
        img = tex[..., None] * (rng.random(colour_ch) if colour_ch == 3 else np.ones(1))
        if kind == "mid_texture":  # inside [0.3, 0.7]: headroom for the noise everywhere
            img = 0.3 + 0.4 * img
    if channels in (2, 4):
        img = np.concatenate([img, rng.random((h, w, 1))], axis=2)
    img = np.clip(img, 0.0, 1.0).astype(np.float32)
    return img[..., 0] if channels == 1 else img


@dataclass(frozen=True)
class ImageCase:
    kind: str
    height: int
    width: int
    channels: int
    depth: int  # 8, 16: quantised to that many bits; 0: any float
    seed: int
    level: float

    def image(self) -> np.ndarray:
        img = draw_image(self.kind, self.height, self.width, self.channels, self.seed, self.level)
        if self.depth:
            top = np.float32(2**self.depth - 1)
            img = np.rint(img * top) / top
        return img.astype(np.float32)


sides = st.one_of(st.sampled_from([MIN_SIDE_PX, MIN_SIDE_PX + 1, 17, 31, 33, 64, MAX_SIDE_PX]),
                  st.integers(MIN_SIDE_PX, MAX_SIDE_PX))


@st.composite
def image_cases(draw, kinds=IMAGE_KINDS, channels=(1, 2, 3, 4), depths=(8, 16, 0)):
    return ImageCase(
        kind=draw(st.sampled_from(kinds)), height=draw(sides), width=draw(sides),
        channels=draw(st.sampled_from(channels)), depth=draw(st.sampled_from(depths)),
        seed=draw(st.integers(0, 2**32 - 1)),
        level=draw(st.sampled_from([0.0, 1.0, 0.5, 1 / 255, 254 / 255])
                   | st.floats(0.0, 1.0)),
    )


def edge_floats(lo: float, hi: float, open_lo: bool = False) -> st.SearchStrategy[float]:
    """Values of a range, its edges and their neighbours most often."""
    lo_edge = math.nextafter(lo, math.inf) if open_lo else lo
    edges = [lo_edge, hi, math.nextafter(hi, -math.inf), lo_edge + 1e-9 * (hi - lo)]
    if not open_lo:
        edges.append(math.nextafter(lo, math.inf))
    return st.sampled_from(edges) | st.floats(lo, hi, exclude_min=open_lo)


@st.composite
def param_kwargs(draw, methods=("foveated", "contrast", "ours"), presets=("paper", "release")):
    """Keyword arguments of :func:`fovexp.make_params`: every number at or near the edges of
    its range (PARAMETER_RANGES, impulses 1..512, seed 0..2**31 - 1) or anywhere inside;
    f_e, s_k, s_f sometimes left to the table."""
    kw: dict[str, object] = {
        "method": draw(st.sampled_from(methods)),
        "preset": draw(st.sampled_from(presets)),
        "blur_rate": draw(edge_floats(*PARAMETER_RANGES["blur_rate"])),
        "impulses": draw(st.sampled_from([1, 2, 12, 64, 512]) | st.integers(1, 512)),
        "seed": draw(st.sampled_from([0, 1, 2**31 - 1]) | st.integers(0, 2**31 - 1)),
    }
    for name in ("f_e", "s_k", "s_f"):
        if draw(st.booleans()):
            kw[name] = draw(edge_floats(*PARAMETER_RANGES[name], open_lo=name == "s_f"))
    return kw


#: the gaze at the corners, the edges' middles and the centre, or anywhere on the screen
gazes = st.one_of(
    st.tuples(st.sampled_from([0.0, 0.5, 1.0]), st.sampled_from([0.0, 0.5, 1.0])),
    st.tuples(st.floats(0.0, 1.0), st.floats(0.0, 1.0)),
)

#: outside the screen, or not a number
bad_coordinates = st.one_of(
    st.sampled_from([math.nan, math.inf, -math.inf, -1e-12, 1.0 + 1e-12, -1.0, 2.0, 1e308]),
    st.floats(allow_nan=False).filter(lambda v: v < 0.0 or v > 1.0),
)


@st.composite
def displays(draw):
    """A shipped profile, or any profile the schema accepts from tiny (1 cm, 1 px) to huge
    (10 m at 10 m; 32768 px), at any gamma it accepts."""
    if draw(st.booleans()):
        return load_display("lg-oled55cx")
    cm = st.sampled_from([1e-3, 1.0, 1000.0]) | st.floats(1e-3, 1000.0)
    width_px = draw(st.sampled_from([1, 3840, 32768]) | st.integers(1, 32768))
    height_px = draw(st.sampled_from([1, 2160, 32768]) | st.integers(1, 32768))
    width_cm = draw(cm)
    # pixels square to within the factor geometry.MIN_PIXEL_ASPECT allows (a hair inside it:
    # the size computed back from the aspect is rounded)
    lo, hi = MIN_PIXEL_ASPECT * (1 + 1e-9), (1 - 1e-9) / MIN_PIXEL_ASPECT
    aspect = draw(st.sampled_from([lo, 1.0, hi]) | st.floats(lo, hi))
    height_cm = width_cm / width_px * height_px / aspect
    assume(1e-3 <= height_cm <= 1000.0)
    return Display(
        name="stress",
        width_px=width_px, height_px=height_px,
        width_cm=width_cm, height_cm=height_cm, distance_cm=draw(cm),
        refresh_hz=draw(st.floats(1.0, 1000.0)),
        peak_luminance_cd_m2=draw(st.floats(1.0, 100000.0)),
        gamma=draw(st.sampled_from([math.nextafter(0.5, 1.0), 1.0, 2.2, 5.0])
                   | st.floats(0.5, 5.0, exclude_min=True)),
    )


@st.composite
def viewports(draw, height: int, width: int):
    """None (the image fills the screen) or ``(x0, y0, screen_w, screen_h)`` placing the image
    anywhere in a frame up to 4K: far in the periphery of a large screen a small image has
    both a high px/deg and a wide band, so the noise has room to appear."""
    if draw(st.integers(0, 3)) == 0:
        return None
    sw = draw(st.sampled_from([width, 3840]) | st.integers(width, 3840))
    sh = draw(st.sampled_from([height, 2160]) | st.integers(height, 2160))
    x0 = draw(st.sampled_from([0, sw - width]) | st.integers(0, sw - width))
    y0 = draw(st.sampled_from([0, sh - height]) | st.integers(0, sh - height))
    return (x0, y0, sw, sh)


@st.composite
def noisy_setups(draw, presets=("paper", "release")):
    """(image case, params kwargs, viewport, gaze) where noise is likely: the paper's display,
    a small image somewhere in a 4K frame (high px/deg, eccentricities up to 45 deg), a blur
    that opens the band, and structure for |L| to measure."""
    case = draw(image_cases(kinds=("texture", "random", "checker", "ramp", "bright_pixel",
                                   "dark_pixel")))
    sw, sh = 3840, 2160
    vp = (draw(st.integers(0, sw - case.width)), draw(st.integers(0, sh - case.height)), sw, sh)
    kw = draw(param_kwargs(methods=("ours",), presets=presets))
    kw["blur_rate"] = draw(edge_floats(0.1, PARAMETER_RANGES["blur_rate"][1]))
    kw["s_k"] = draw(edge_floats(10.0, PARAMETER_RANGES["s_k"][1]))
    return case, kw, vp, draw(gazes)


def sigma_at_centre(case: ImageCase, vp: tuple[int, int, int, int], gaze: tuple[float, float],
                    preset_name: str, blur_rate: float = 1.0) -> float:
    """The foveation sigma (px) at the image's centre on the paper's display (section 5.2):
    what a strategy scales the blur-rate by to reach a case (sigma is linear in it)."""
    from fovexp import ViewingGeometry
    from fovexp.foveation import sigma_px
    from fovexp.params import get_preset

    preset = get_preset(preset_name)
    geom = ViewingGeometry.for_image(load_display("lg-oled55cx"), case.width, case.height,
                                     preset.geometry, vp)
    x, y = np.array([case.width / 2]), np.array([case.height / 2])
    ecc = geom.eccentricity_deg(x, y, geom.gaze_px(gaze))
    return float(sigma_px(ecc, geom.ppd(x, y), blur_rate, preset.fovea_deg, np.float64)[0])


@st.composite
def peripheral_setups(draw, kinds=("texture", "random"), min_side: int = 64,
                      sigma_px: tuple[float, float] = (2.5, 5.0), methods=("ours",)):
    """(image case, params kwargs, viewport, gaze) built to reach a property's case in every
    example, not by chance: an image of ``min_side`` px or more in a corner of a 4K frame on
    the paper's display, the gaze in the opposite corner, and the blur-rate that puts the
    foveation sigma at the image's centre in ``sigma_px`` (blurred, and the band open, across
    the image)."""
    side = st.integers(min_side, MAX_SIDE_PX)
    case = draw(image_cases(kinds=kinds, channels=(1, 3)))
    case = ImageCase(kind=case.kind, height=draw(side), width=draw(side), channels=case.channels,
                     depth=case.depth, seed=case.seed, level=case.level)
    kw = draw(param_kwargs(methods=methods))
    right, bottom = draw(st.booleans()), draw(st.booleans())
    vp = ((3840 - case.width) if right else 0, (2160 - case.height) if bottom else 0, 3840, 2160)
    gaze = (0.0 if right else 1.0, 0.0 if bottom else 1.0)
    target = draw(st.floats(*sigma_px))
    kw["blur_rate"] = target / sigma_at_centre(case, vp, gaze, kw["preset"])
    if "ours" in methods:
        kw["s_k"] = draw(edge_floats(10.0, PARAMETER_RANGES["s_k"][1]))
    return case, kw, vp, gaze
