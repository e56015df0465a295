"""Contrast enhancement (Patney et al. 2016, as the authors' release applies it; notes 3.3).

The paper defers the formula to Patney et al.; the release implements it per integer blur
level ``k`` (the foveation sigma rounded down and up)::

    avg_k = box mean of width ceil(4 k)             (symmetric borders)
    out_k = avg_k + f_e * (1 + k) * (in - avg_k)

and each pixel interpolates linearly between the two integer levels bracketing its sigma, as
the foveation does. The gain ``f_e (1 + k)`` is below 1 for small ``k`` (with f_e = 0.2 it
softens rather than sharpens up to k = 4): this is the release's formula, kept as such so that
the calibrated f_e of Table 2 means the same thing. Where sigma = 0 the image is unchanged.

The box means come from a summed-area table, so each pixel costs the same whatever its width,
and only the two widths a pixel needs are evaluated (no stack of filtered images).
Even widths follow MATLAB's anchoring: the window of width ``n`` covers
``[x - floor((n - 1) / 2), x + ceil((n - 1) / 2)]``.
"""

from __future__ import annotations

import math

import numba
import numpy as np


def box_width_px(level: int) -> int:
    """Box-filter width of integer blur level ``level`` (notes section 3.3): ceil(4 level)."""
    return int(math.ceil(4 * level))


@numba.njit(parallel=True, cache=True, fastmath=True)
def _sat(padded):  # pragma: no cover - compiled
    """Summed-area table (float64) with a leading zero row and column, per channel."""
    h, w, c = padded.shape
    s = np.zeros((h + 1, w + 1, c), dtype=np.float64)
    for ch in numba.prange(c):
        for y in range(h):
            run = 0.0
            for x in range(w):
                run += padded[y, x, ch]
                s[y + 1, x + 1, ch] = s[y, x + 1, ch] + run
    return s


@numba.njit(parallel=True, cache=True, fastmath=True)
def _enhance(img, sigma, sat, pad, f_e):  # pragma: no cover - compiled
    h, w, c = img.shape
    out = np.empty_like(img)
    for y in numba.prange(h):
        for x in range(w):
            s = sigma[y, x]
            if s <= 0.0:
                for ch in range(c):
                    out[y, x, ch] = img[y, x, ch]
                continue
            k0 = int(math.floor(s))
            t = s - k0
            for ch in range(c):
                v = img[y, x, ch]
                acc = 0.0
                for j in range(2):
                    k = k0 + j
                    wgt = (1.0 - t) if j == 0 else t
                    if wgt == 0.0:
                        continue
                    if k == 0:
                        acc += wgt * v  # width 0: the pixel itself
                        continue
                    n = int(math.ceil(4.0 * k))
                    lo = (n - 1) // 2
                    hi = n - 1 - lo
                    ya, yb = y + pad - lo, y + pad + hi + 1
                    xa, xb = x + pad - lo, x + pad + hi + 1
                    box = sat[yb, xb, ch] - sat[ya, xb, ch] - sat[yb, xa, ch] + sat[ya, xa, ch]
                    avg = box / (n * n)
                    acc += wgt * (avg + f_e * (1.0 + k) * (v - avg))
                out[y, x, ch] = acc
    return out


def contrast_enhance(linear: np.ndarray, sigma_map_px: np.ndarray, f_e: float) -> np.ndarray:
    """Release contrast enhancement of an (H, W) or (H, W, C) linear image (notes 3.3).

    ``sigma_map_px`` is the foveation sigma per pixel; ``f_e`` the enhancement factor
    (Table 2: 0.15 .. 0.28). The result may leave [0, 1]; the noise's clipping control
    accounts for that.
    """
    grey = linear.ndim == 2
    img = np.ascontiguousarray(linear[..., None] if grey else linear, dtype=np.float32)
    sigma = np.ascontiguousarray(sigma_map_px, dtype=np.float32)
    max_sigma = float(sigma.max()) if sigma.size else 0.0
    if max_sigma <= 0.0:
        return linear.astype(np.float32, copy=True)
    pad = box_width_px(int(math.floor(max_sigma)) + 1) // 2 + 1
    sat = _sat(np.pad(img, ((pad, pad), (pad, pad), (0, 0)), mode="symmetric"))
    out = _enhance(img, sigma, sat, pad, np.float32(f_e))
    return out[..., 0] if grey else out
