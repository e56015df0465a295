"""Contrast enhancement (Patney et al. 2016, as the authors' release applies it; notes 3.3).

The paper defers the formula to Patney et al.; the release implements it per integer blur
level ``k`` (the foveation sigma rounded down and up)::

    avg_k = box mean of width ceil(4 k)             (symmetric borders)
    out_k = avg_k + f_e * (1 + k) * (in - avg_k)

and each pixel interpolates linearly between the two integer levels bracketing its sigma, as
the foveation does. The gain ``f_e (1 + k)`` is below 1 for small ``k`` (with f_e = 0.2 it
softens rather than sharpens up to k = 4): this is the release's formula, kept as such so that
the calibrated f_e of Table 2 means the same thing. Where sigma = 0 the image is unchanged.
The pipeline applies it to luminance, since the method processes luminance only (paper
section 4.5), and adds the change to every colour channel, as it does the noise.

The box means come from a summed-area table (float64), so each pixel costs the same whatever
its width, and only the two widths a pixel needs are evaluated (no stack of filtered images).
Even widths follow MATLAB's anchoring: the window of width ``n`` covers
``[x - floor((n - 1) / 2), x + ceil((n - 1) / 2)]``.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .foveation import per_pixel_sigma
from .jit import FASTMATH

#: Box-filter width per integer blur level (notes section 3.3): level k averages ceil(4 k) px.
BOX_WIDTH_PX_PER_LEVEL = 4


def box_width_px(level: int) -> int:
    """Box-filter width of integer blur level ``level`` (notes section 3.3): ceil(4 level)."""
    return int(math.ceil(BOX_WIDTH_PX_PER_LEVEL * level))


@numba.njit(cache=True, inline="always", nogil=True, fastmath=FASTMATH)
def _symmetric(i, n):  # pragma: no cover - compiled
    """MATLAB 'symmetric' padding index (-1 -> 0, n -> n - 1), repeated past the edges as
    padarray does when the pad is wider than the image (period 2 n)."""
    i = i % (2 * n)  # Python semantics: in [0, 2n)
    return 2 * n - 1 - i if i >= n else i


@numba.njit(parallel=True, cache=True, fastmath=FASTMATH, nogil=True)
def _sat(img, pad):  # pragma: no cover - compiled
    """Summed-area table (float64, leading zero row and column) of a grey image padded by
    ``pad`` pixels with symmetric borders (:func:`_symmetric`)."""
    h, w = img.shape
    hp, wp = h + 2 * pad, w + 2 * pad
    s = np.zeros((hp + 1, wp + 1))
    cols = np.empty(wp, dtype=np.int64)
    for x in range(wp):
        cols[x] = _symmetric(x - pad, w)
    for y in numba.prange(hp):  # row prefix sums, rows in parallel
        sy = _symmetric(y - pad, h)
        run = 0.0
        for x in range(wp):
            run += img[sy, cols[x]]
            s[y + 1, x + 1] = run
    nblk = (wp + 63) // 64
    for b in numba.prange(nblk):  # then column sums, blocks of columns in parallel
        x0 = b * 64 + 1
        x1 = min(x0 + 64, wp + 1)
        for y in range(1, hp + 1):
            for x in range(x0, x1):
                s[y, x] += s[y - 1, x]
    return s


@numba.njit(parallel=True, cache=True, fastmath=FASTMATH, nogil=True)
def _enhance(img, sigma, sat, pad, f_e, minus):  # pragma: no cover - compiled
    """The enhanced image, less ``minus`` times the input (1: just the change)."""
    h, w = img.shape
    out = np.empty_like(img)
    for y in numba.prange(h):
        for x in range(w):
            s = sigma[y, x]
            v = img[y, x]
            if s <= 0.0:
                out[y, x] = v - minus * v
                continue
            k0 = int(s)
            t = s - k0
            acc = 0.0
            for j in range(2):
                k = k0 + j
                wgt = (1.0 - t) if j == 0 else t
                if k == 0:  # width 0: the pixel itself
                    acc += wgt * v
                    continue
                # width n = box_width_px(k) (k is an integer), MATLAB anchoring:
                # [x - floor((n - 1) / 2), x + ceil((n - 1) / 2)]
                n = BOX_WIDTH_PX_PER_LEVEL * k
                ya = y + pad - (n - 1) // 2
                xa = x + pad - (n - 1) // 2
                yb = ya + n
                xb = xa + n
                box = sat[yb, xb] - sat[ya, xb] - sat[yb, xa] + sat[ya, xa]
                avg = box / (n * n)
                acc += wgt * (avg + f_e * (1.0 + k) * (v - avg))
            out[y, x] = acc - minus * v
    return out


def _enhance_channels(img: np.ndarray, sigma: np.ndarray, max_sigma: float, f_e: float):
    pad = sat_pad_px(max_sigma)
    out = np.empty_like(img)
    for ch in range(img.shape[2]):
        plane = np.ascontiguousarray(img[..., ch])
        out[..., ch] = _enhance(plane, sigma, _sat(plane, pad), pad, f_e, np.float32(0.0))
    return out


def sat_pad_px(max_sigma: float) -> int:
    """Border the summed-area table needs: half the widest box (level floor(max) + 1)."""
    return box_width_px(int(max_sigma) + 1) // 2 + 1


def contrast_enhance(linear: np.ndarray, sigma_map_px: np.ndarray, f_e: float) -> np.ndarray:
    """Release contrast enhancement of an (H, W) or (H, W, C) linear image (notes 3.3).

    ``sigma_map_px`` is the foveation sigma per pixel; ``f_e`` the enhancement factor
    (Table 2: 0.15 .. 0.28). The result may leave [0, 1]; the noise's clipping control
    accounts for that.
    """
    return per_pixel_sigma(linear, sigma_map_px, _enhance_channels, float(f_e))


def contrast_change(grey: np.ndarray, sigma_map_px: np.ndarray, f_e: float) -> np.ndarray:
    """``contrast_enhance(grey) - grey`` of an (H, W) linear luminance image, in one pass: the
    change the pipeline adds to every colour channel (the method works on luminance)."""
    img = np.ascontiguousarray(grey, dtype=np.float32)
    sigma = np.ascontiguousarray(sigma_map_px, dtype=np.float32)
    max_sigma = float(sigma.max()) if sigma.size else 0.0
    if max_sigma <= 0.0:
        return np.zeros(img.shape, dtype=np.float32)
    pad = sat_pad_px(max_sigma)
    return _enhance(img, sigma, _sat(img, pad), pad, np.float32(f_e), np.float32(1.0))
