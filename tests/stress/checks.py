"""The invariants every enhancement keeps, checked on the values before anything clips them:
the maps, the linear-light foveated and contrast images, K and the noise."""

from __future__ import annotations

import math

import numpy as np

from fovexp import MAP_NAMES, Enhancer, EnhanceResult
from fovexp.colour import luminance

#: slack for float rounding on values in [0, 1]: a few units in the last place of the dtype
ULPS = 8


def eps(dtype: np.dtype) -> float:
    return ULPS * float(np.finfo(dtype).eps)


def colour_of(image: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """(colour, alpha) of a test image (grey + alpha and RGBA carry their alpha last); grey
    colour as (H, W)."""
    if image.ndim == 3 and image.shape[2] == 2:
        return image[..., 0], image[..., 1]
    if image.ndim == 3 and image.shape[2] == 4:
        return image[..., :3], image[..., 3]
    return image, None


#: the round trip through the display's transfer function in float32 (linearise, encode) is
#: exact to this much of a value in [0, 1]: a few float32 ulps, far below half a 16-bit step
#: (7.6e-6), so an input at 8 or 16 bits comes back sample for sample at its depth (a float
#: input can land on the other side of a rounding boundary, so it is compared to this bound)
ROUND_TRIP_TOL = 2e-6


def assert_same_samples(out: np.ndarray, image: np.ndarray, depth: int) -> None:
    """``out`` holds ``image``'s samples: at its bit depth and at 16 bits for an 8-bit input
    (k / 255 = 257 k / 65535), within :data:`ROUND_TRIP_TOL` for a float input (depth 0)."""
    if depth == 0:
        diff = np.abs(out.astype(np.float64) - image.astype(np.float64))
        assert diff.max(initial=0.0) <= ROUND_TRIP_TOL, diff.max()
        return
    for d in sorted({depth, 16}):
        assert np.array_equal(quantise(out, d), quantise(image, d)), d


def quantise(image: np.ndarray, depth: int) -> np.ndarray:
    """What write_image stores at ``depth`` bits (its rounding: clip, scale, round half even)."""
    top = np.float32(2**depth - 1)
    return np.rint(np.clip(image, 0, 1).astype(np.float32) * top).astype(np.int64)


def check_result(enh: Enhancer, res: EnhanceResult, image: np.ndarray) -> dict[str, np.ndarray]:
    """Assert every invariant of one enhancement; returns the maps (by name) it read."""
    dtype = np.dtype(enh.options.dtype)
    tol = eps(dtype)
    colour, alpha = colour_of(image)

    # the output: the input's layout, the engine's dtype, finite, the alpha bit for bit
    out = res.output
    assert out.shape == image.shape and out.dtype == dtype, (out.shape, out.dtype)
    assert np.isfinite(out).all(), "output has NaN/Inf"
    if alpha is not None:
        assert np.array_equal(out[..., -1], alpha.astype(dtype)), "alpha changed"

    # every map: never NaN; Inf only as F_L = +Inf where the blur removes nothing (its cut-off
    # 3 / (2 pi sigma) is infinite where sigma = 0, paper eq. 1, or beyond float32 where sigma
    # is a denormal): the band is empty there; nowhere else
    maps = {name: res.map(name) for name in MAP_NAMES}
    for name, m in maps.items():
        assert m.shape[:2] == image.shape[:2], (name, m.shape)
        assert not np.isnan(m).any(), f"map {name} has NaN"
        if name != "f_low_cpp":
            assert not np.isinf(m).any(), f"map {name} has Inf"
    sigma, f_low = maps["sigma_px"], maps["f_low_cpp"]
    assert (sigma >= 0).all()
    assert (f_low[np.isinf(f_low)] > 0).all() and np.isinf(f_low[sigma == 0]).all()
    if enh.options.dtype == "float64":  # no overflow: Inf exactly where sigma = 0
        assert (np.isinf(f_low) == (sigma == 0)).all()

    # the linear foveated image: a blur is a convex combination of the input's values
    fov = res.linear("foveated")
    assert fov.dtype == dtype and np.isfinite(fov).all()
    assert fov.min() >= -tol and fov.max() <= 1 + tol, ("foveated", fov.min(), fov.max())

    # the contrast-enhanced luminance: per level out_k = avg_k + g (in - avg_k), g = f_e (1 + k),
    # an extrapolation for g > 1 (Patney; notes 3.3): within [min(0, 1 - g), max(1, g)]
    con = res.linear("contrast")
    assert con.dtype == dtype and np.isfinite(con).all()
    g = res.params.f_e * (1 + math.ceil(float(sigma.max())))
    y = luminance(con)
    assert y.min() >= min(0.0, 1.0 - g) - tol and y.max() <= max(1.0, g) + tol, (
        "contrast", y.min(), y.max(), g)

    # K: non-negative, 0 where the band is empty (section 4.1), and within the headroom of
    # the image it is added to: contrast +- K/2 (3 noise std) in [0, 1] (section 4.2's
    # clipping control; over every channel under the widened and exact rules, on luminance
    # under the paper's and the release's, none with the rule off)
    k = maps["amplitude"]
    assert (k >= 0).all()
    assert (k[maps["f_low_cpp"] >= maps["f_high_cpp"]] == 0).all(), "K > 0 where the band is empty"
    if res.params.method != "ours":
        assert not k.any() and not maps["noise"].any()
    noisy = k > 0
    if noisy.any() and enh.clipping != "off":
        base = con if enh.clipping in ("widened", "exact") else y
        lo = base if base.ndim == 2 else base.min(axis=2)
        hi = base if base.ndim == 2 else base.max(axis=2)
        half = 0.5 * k[noisy]
        assert (lo[noisy] - half).min() >= -tol, ("K beyond the headroom below",
                                                   (lo[noisy] - half).min())
        assert (hi[noisy] + half).max() <= 1 + tol, ("K beyond the headroom above",
                                                     (hi[noisy] + half).max())
    return maps
