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

The box means come from summed-area tables built tile by tile (each tile with the margin its
widest box needs), so each pixel costs the same whatever its width, only the two widths a
pixel needs are evaluated (no stack of filtered images), and fovea tiles are copied.
Even widths follow MATLAB's anchoring: the window of width ``n`` covers
``[x - floor((n - 1) / 2), x + ceil((n - 1) / 2)]``.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .foveation import per_pixel_sigma


def box_width_px(level: int) -> int:
    """Box-filter width of integer blur level ``level`` (notes section 3.3): ceil(4 level)."""
    return int(math.ceil(4 * level))


@numba.njit(cache=True, inline="always")
def _mirror(i, n):  # pragma: no cover - compiled
    """Symmetric border (MATLAB 'symmetric'): -1 -> 0, -2 -> 1, n -> n - 1."""
    if i < 0:
        i = -i - 1
    if i >= n:
        i = 2 * n - i - 1
    return min(max(i, 0), n - 1)


#: Side of the tiles the enhancement is computed in; each tile builds its own summed-area
#: table (small enough to stay in cache, and float64 sums stay small and exact).
TILE_PX = 128


@numba.njit(parallel=True, cache=True, fastmath=True)
def _enhance_tiles(img, sigma, f_e, tile):  # pragma: no cover - compiled
    h, w, c = img.shape
    out = np.empty_like(img)
    nty = (h + tile - 1) // tile
    ntx = (w + tile - 1) // tile
    for t in numba.prange(nty * ntx):
        y0 = (t // ntx) * tile
        x0 = (t % ntx) * tile
        y1 = min(y0 + tile, h)
        x1 = min(x0 + tile, w)
        smax = 0.0
        for y in range(y0, y1):
            for x in range(x0, x1):
                smax = max(smax, sigma[y, x])
        if smax <= 0.0:  # the fovea: nothing to do
            for y in range(y0, y1):
                for x in range(x0, x1):
                    for ch in range(c):
                        out[y, x, ch] = img[y, x, ch]
            continue
        # widest box this tile needs: level floor(smax) + 1
        m = int(math.ceil(4.0 * (int(math.floor(smax)) + 1))) // 2 + 1
        th, tw = y1 - y0 + 2 * m, x1 - x0 + 2 * m
        sat = np.zeros((c, th + 1, tw + 1), dtype=np.float64)
        for yy in range(th):
            sy = _mirror(y0 - m + yy, h)
            for ch in range(c):
                run = 0.0
                for xx in range(tw):
                    run += img[sy, _mirror(x0 - m + xx, w), ch]
                    sat[ch, yy + 1, xx + 1] = sat[ch, yy, xx + 1] + run
        for y in range(y0, y1):
            for x in range(x0, x1):
                s = sigma[y, x]
                if s <= 0.0:
                    for ch in range(c):
                        out[y, x, ch] = img[y, x, ch]
                    continue
                k0 = int(math.floor(s))
                frac = s - k0
                for ch in range(c):
                    out[y, x, ch] = 0.0
                for j in range(2):
                    k = k0 + j
                    wgt = (1.0 - frac) if j == 0 else frac
                    if wgt == 0.0:
                        continue
                    if k == 0:  # width 0: the pixel itself
                        for ch in range(c):
                            out[y, x, ch] += wgt * img[y, x, ch]
                        continue
                    n = int(math.ceil(4.0 * k))
                    lo = (n - 1) // 2
                    ya = y - y0 + m - lo
                    xa = x - x0 + m - lo
                    yb, xb = ya + n, xa + n
                    gain = f_e * (1.0 + k)
                    inv = 1.0 / (n * n)
                    for ch in range(c):
                        box = sat[ch, yb, xb] - sat[ch, ya, xb] - sat[ch, yb, xa] + sat[ch, ya, xa]
                        avg = box * inv
                        out[y, x, ch] += wgt * (avg + gain * (img[y, x, ch] - avg))
    return out


def contrast_enhance(linear: np.ndarray, sigma_map_px: np.ndarray, f_e: float) -> np.ndarray:
    """Release contrast enhancement of an (H, W) or (H, W, C) linear image (notes 3.3).

    ``sigma_map_px`` is the foveation sigma per pixel; ``f_e`` the enhancement factor
    (Table 2: 0.15 .. 0.28). The result may leave [0, 1]; the noise's clipping control
    accounts for that.
    """
    return per_pixel_sigma(
        linear, sigma_map_px,
        lambda img, sigma, _max, fe: _enhance_tiles(img, sigma, fe, TILE_PX), np.float32(f_e),
    )
