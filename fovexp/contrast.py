"""Contrast enhancement (Patney et al. 2016, as the authors' release applies it;
docs/METHOD.md, 5.3).

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

Per level the change is written ``out_k - in = (1 - f_e (1 + k)) (avg_k - in)`` (the same
formula; the weights of the two levels sum to 1), so a pixel whose box is one constant changes
by exactly 0. The box sums come from an exact integer summed-area table of the luminance in
fixed point (:data:`SAT_FRACTION_BITS`): ``avg_k - in`` is ``(box - n^2 q) / n^2`` with ``q``
the pixel in the same fixed point, an integer difference that is exactly 0 on a flat box. The
sums are then independent of their order (the GPU's, in another order, are the same numbers)
and do not lose precision on large frames as a float64 table's prefix sums do. The
quantisation, ``2**-37`` at most (7.3e-12 of linear luminance), is far below any output code.
The flat regions the enhancer skips (``EngineOptions.skip``) are exactly those whose change is
0. Each pixel costs the same whatever its width, and only the two widths a pixel needs are
evaluated (no stack of filtered images).
Even widths follow MATLAB's anchoring: the window of width ``n`` covers
``[x - floor((n - 1) / 2), x + ceil((n - 1) / 2)]``.

References
----------
.. [tariq] Tariq, T., Tursun, C., Didyk, P. (2022). Noise-based Enhancement for Foveated
   Rendering. ACM Transactions on Graphics 41(4) (SIGGRAPH 2022). doi:10.1145/3528223.3530101
.. [patney] Patney, A., Salvi, M., Kim, J., Kaplanyan, A., Wyman, C., Benty, N., Luebke, D.,
   Lefohn, A. (2016). Towards Foveated Rendering for Gaze-Tracked Virtual Reality. ACM
   Transactions on Graphics 35(6). doi:10.1145/2980179.2980246
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ._parallel import interleave
from .errors import FovexpError
from .foveation import SigmaOnBlocks, _float_array, per_pixel_sigma
from .jit import FASTMATH
from .pyramids import FLAT_BLOCK_LEVEL, blocks_reaching, level_scale

#: Box-filter width per integer blur level (docs/METHOD.md, 5.3): level k averages ceil(4 k) px.
BOX_WIDTH_PX_PER_LEVEL = 4


def box_width_px(level: int) -> int:
    """Box-filter width of integer blur level ``level`` (docs/METHOD.md, 5.3): ceil(4 level)."""
    return int(math.ceil(BOX_WIDTH_PX_PER_LEVEL * level))


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _symmetric(i, n):  # pragma: no cover - compiled
    """MATLAB 'symmetric' padding index (-1 -> 0, n -> n - 1), repeated past the edges as
    padarray does when the pad is wider than the image (period 2 n)."""
    i = i % (2 * n)  # Python semantics: in [0, 2n)
    return 2 * n - 1 - i if i >= n else i


#: Fixed-point fraction bits of the summed-area table: values are held in steps of 2**-36.
#: The table's largest entry is (H + 2 pad)(W + 2 pad) 2**36 max(v): an 8K frame (7680 x 4320,
#: pad <= 64 px: 3.5e7 px) of values <= 1 sums to 2.4e18, within int64's 9.2e18 (a margin of
#: 3.8); :func:`check_sat_fits` refuses a frame that would not fit.
SAT_FRACTION_BITS = 36
_SAT_SCALE = float(2**SAT_FRACTION_BITS)
_SAT_STEP = 1.0 / _SAT_SCALE
_INT64_MAX = 2**63 - 1


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _fixed(v):  # pragma: no cover - compiled
    """``v`` in the table's fixed point: round(v 2**36) (to nearest, ties to even)."""
    return np.int64(np.rint(np.float64(v) * _SAT_SCALE))


@numba.njit(parallel=True, cache=True, fastmath=FASTMATH, nogil=True)
def _sat_into(img, pad, y0, y1, x0, x1, s):  # pragma: no cover - compiled
    """:func:`_sat`, written into ``s`` ((y1 - y0 + 1, x1 - x0 + 1) int64)."""
    h, w = img.shape
    hp, wp = y1 - y0, x1 - x0
    # every entry past the leading zero row and column is written below: no memset of the
    # whole table (tens of MB at 4K, on one thread)
    s[0, :] = 0
    s[:, 0] = 0
    cols = np.empty(wp, dtype=np.int64)
    for x in range(wp):
        cols[x] = _symmetric(x0 + x - pad, w)
    for y in numba.prange(hp):  # row prefix sums, rows in parallel
        sy = _symmetric(y0 + y - pad, h)
        run = np.int64(0)
        for x in range(wp):
            run += _fixed(img[sy, cols[x]])
            s[y + 1, x + 1] = run
    nblk = (wp + 63) // 64
    for b in numba.prange(nblk):  # then column sums, blocks of columns in parallel
        x0 = b * 64 + 1
        x1 = min(x0 + 64, wp + 1)
        for y in range(1, hp + 1):
            for x in range(x0, x1):
                s[y, x] += s[y - 1, x]
    return s


def _sat(img: np.ndarray, pad: int, y0: int, y1: int, x0: int, x1: int) -> np.ndarray:
    """Exact summed-area table (int64, leading zero row and column) of a grey image in fixed
    point (:func:`_fixed`), padded by ``pad`` pixels with symmetric borders
    (:func:`_symmetric`), over rows [y0, y1) and columns [x0, x1) of the padded image (the
    sums start there: the boxes inside it are the same integers)."""
    return _sat_into(img, pad, y0, y1, x0, x1, np.empty((y1 - y0 + 1, x1 - x0 + 1), np.int64))


def check_sat_fits(shape: tuple[int, int], pad: int, max_value: float) -> None:
    """Refuse a frame whose summed-area table would overflow int64 (see
    :data:`SAT_FRACTION_BITS`): one clear error rather than wrong sums."""
    hp, wp = int(shape[0]) + 2 * pad, int(shape[1]) + 2 * pad
    if hp * wp * max(float(max_value), 1.0) * _SAT_SCALE >= _INT64_MAX:
        raise FovexpError(
            f"a {shape[1]}x{shape[0]} frame is too large for the contrast stage's exact sums "
            f"(at most about {_INT64_MAX / _SAT_SCALE / 1e6:.0f} million pixels with the blur "
            "border)"
        )


@numba.njit(cache=True, fastmath=FASTMATH, inline="always", nogil=True)
def _pixel_change(img, sigma, sat, y, x, oy, ox, pad, f_e):  # pragma: no cover - compiled
    """The change of pixel (y, x): per integer level ``k`` of the two bracketing its sigma,
    ``(1 - f_e (1 + k)) (avg_k - in)``, weighted by the linear interpolation; 0 where
    sigma = 0. ``sat`` starts at row ``oy``, column ``ox`` of the padded image. A box that
    is one constant gives exactly 0 (an integer difference of 0)."""
    s = sigma[y, x]
    if s <= 0.0:
        return 0.0
    k0 = int(s)
    t = np.float64(s) - k0
    qv = _fixed(img[y, x])
    acc = 0.0
    for j in range(2):
        k = k0 + j
        if k == 0:  # width 0: the pixel itself, no change
            continue
        wgt = (1.0 - t) if j == 0 else t
        # width n = box_width_px(k) (k is an integer), MATLAB anchoring:
        # [x - floor((n - 1) / 2), x + ceil((n - 1) / 2)]
        n = BOX_WIDTH_PX_PER_LEVEL * k
        ya = y + pad - (n - 1) // 2 - oy
        xa = x + pad - (n - 1) // 2 - ox
        yb = ya + n
        xb = xa + n
        box = sat[yb, xb] - sat[ya, xb] - sat[yb, xa] + sat[ya, xa]
        diff = box - n * n * qv  # exact: n^2 (avg - in), in fixed point
        acc += wgt * (1.0 - f_e * (1.0 + k)) * (np.float64(diff) / (n * n))
    return acc * _SAT_STEP


@numba.njit(parallel=True, cache=True, fastmath=FASTMATH, nogil=True)
def _change(img, sigma, sat, oy, ox, pad, f_e, add_input, out):  # pragma: no cover - compiled
    """:func:`_pixel_change` of every pixel (plus the input where ``add_input``), written
    into ``out`` (img's shape)."""
    h, w = img.shape
    for y in numba.prange(h):
        for x in range(w):
            change = _pixel_change(img, sigma, sat, y, x, oy, ox, pad, f_e)
            out[y, x] = (np.float64(img[y, x]) + change) if add_input else change
    return out


@numba.njit(parallel=True, cache=True, fastmath=FASTMATH, nogil=True)
def _change_blocks(img, sigma, sat, oy, ox, pad, f_e, flat, shift, out):  # pragma: no cover
    """:func:`_pixel_change` of the pixels whose ``2**shift`` square block ``flat`` does not
    mark, written into ``out`` (zeros: the others' boxes are one constant, their change is
    0), a run of consecutive blocks at a time. (A separate loop: with the block test, the
    loop over all pixels measured 35 % slower.)"""
    h, w = img.shape
    nbx = flat.shape[1]
    # rows in chunks of 8 (consecutive rows share the table's rows), the chunks interleaved:
    # flat chunks cost nothing, so the others are spread over the threads
    nch = (h + 7) // 8
    stride = interleave(nch)
    for i in numba.prange(nch * 8):
        y = ((i // 8) * stride) % nch * 8 + i % 8
        if y >= h:
            continue
        by = y >> shift
        bx = 0
        while bx < nbx:
            if flat[by, bx]:
                bx += 1
                continue
            b0 = bx  # a run of blocks to compute: one loop over its pixels, as _change's
            while bx < nbx and not flat[by, bx]:
                bx += 1
            for x in range(b0 << shift, min(bx << shift, w)):
                out[y, x] = _pixel_change(img, sigma, sat, y, x, oy, ox, pad, f_e)
    return out


def _flat_blocks(grey_flat: np.ndarray, max_sigma: float) -> np.ndarray:
    """Blocks whose every pixel's boxes lie in one constant region (change exactly 0), from
    the grey image's constant radius per level-3 block."""
    # the widest box reaches sat_pad_px from its pixel; symmetric padding reads inside it
    block = level_scale(FLAT_BLOCK_LEVEL)
    return grey_flat >= blocks_reaching(sat_pad_px(max_sigma), block)


def _enhance_channels(img: np.ndarray, sigma: np.ndarray, max_sigma: float, f_e: float):
    pad = sat_pad_px(max_sigma)
    out = np.empty_like(img)
    h, w = img.shape[:2]
    for ch in range(img.shape[2]):
        plane = np.ascontiguousarray(img[..., ch])
        check_sat_fits(plane.shape, pad, float(plane.max()))
        sat = _sat(plane, pad, 0, h + 2 * pad, 0, w + 2 * pad)
        out[..., ch] = _change(plane, sigma, sat, 0, 0, pad, f_e, True,
                               np.empty(plane.shape, plane.dtype))
    return out


def sat_pad_px(max_sigma: float) -> int:
    """Border the summed-area table needs: half the widest box (level floor(max) + 1)."""
    return box_width_px(int(max_sigma) + 1) // 2 + 1


def contrast_enhance(linear: np.ndarray, sigma_map_px: np.ndarray, f_e: float) -> np.ndarray:
    """Release contrast enhancement of an (H, W) or (H, W, C) linear image (docs/METHOD.md, 5.3).

    ``sigma_map_px`` is the foveation sigma per pixel; ``f_e`` the enhancement factor
    (Table 2: 0.15 .. 0.28). The result may leave [0, 1]; the noise's clipping control
    accounts for that.
    """
    return per_pixel_sigma(linear, sigma_map_px, _enhance_channels, float(f_e))


def contrast_change(
    grey: np.ndarray, sigma_map_px: np.ndarray, f_e: float,
    grey_flat: np.ndarray | None = None,
) -> np.ndarray:
    """``contrast_enhance(grey) - grey`` of an (H, W) linear luminance image, in one pass: the
    change the pipeline adds to every colour channel (the method works on luminance). Float32
    or float64 (the result has the image's dtype).

    ``grey_flat``: how far around each level-3 block the image is one constant
    (:func:`fovexp.pyramids.constant_radius_blocks` of its block extremes), to leave out the
    blocks whose boxes all lie in one constant region, where the change is exactly 0 (the
    enhancer's skipping; the result is the same bit for bit)."""
    img = _float_array(grey)
    sigma = _float_array(sigma_map_px)
    max_sigma = float(sigma.max()) if sigma.size else 0.0
    if max_sigma <= 0.0:
        return np.zeros(img.shape, dtype=img.dtype)
    flat = _flat_blocks(grey_flat, max_sigma) if grey_flat is not None else None
    return _change_outside(img, sigma, float(f_e), flat, max_sigma)


def contrast_change_where_needed(
    grey: np.ndarray, sigma_on_blocks: SigmaOnBlocks, max_sigma_px: float, f_e: float,
    grey_flat: np.ndarray,
) -> np.ndarray:
    """:func:`contrast_change` with skipping, asking for the sigma map only where the change
    is not known to be 0 (:data:`fovexp.foveation.SigmaOnBlocks`).
    ``max_sigma_px`` bounds the sigma map from above; it sets how far the boxes reach. The
    result is :func:`contrast_change`'s, bit for bit (the boxes' sums are exact integers,
    whatever border the table has)."""
    img = _float_array(grey)
    if max_sigma_px <= 0.0:
        return np.zeros(img.shape, dtype=img.dtype)
    flat = _flat_blocks(grey_flat, max_sigma_px)
    if flat.all():
        return np.zeros(img.shape, dtype=img.dtype)
    sigma = _float_array(sigma_on_blocks(~flat, FLAT_BLOCK_LEVEL))
    return _change_outside(img, sigma, float(f_e), flat, max_sigma_px)


def _change_outside(
    img: np.ndarray, sigma: np.ndarray, f_e: float, flat: np.ndarray | None, max_sigma: float,
) -> np.ndarray:
    """The change of every pixel outside the level-3 blocks ``flat`` marks (0 there); boxes up
    to level ``floor(max_sigma) + 1``."""
    pad = sat_pad_px(max_sigma)
    check_sat_fits(img.shape, pad, float(img.max()))
    h, w = img.shape
    f_e = np.float64(f_e)
    if flat is None or not flat.any():  # nothing to leave out
        return _change(img, sigma, _sat(img, pad, 0, h + 2 * pad, 0, w + 2 * pad), 0, 0, pad,
                       f_e, False, np.empty(img.shape, img.dtype))
    # the table only where the boxes of the pixels computed reach: their bounding box, and
    # pad around it (in the padded image's coordinates, [y_lo, y_hi + 2 pad])
    block = level_scale(FLAT_BLOCK_LEVEL)
    rows, cols = np.flatnonzero(~flat.all(axis=1)), np.flatnonzero(~flat.all(axis=0))
    if rows.size == 0:
        return np.zeros(img.shape, dtype=img.dtype)
    y0, y1 = min(rows[0] * block, h), min((rows[-1] + 1) * block, h) + 2 * pad
    x0, x1 = min(cols[0] * block, w), min((cols[-1] + 1) * block, w) + 2 * pad
    sat = _sat(img, pad, y0, y1, x0, x1)
    # NumPy's zeros: the flat blocks' pages are never written (calloc)
    out = np.zeros(img.shape, dtype=img.dtype)
    _change_blocks(img, sigma, sat, y0, x0, pad, f_e, flat, FLAT_BLOCK_LEVEL, out)
    return out
