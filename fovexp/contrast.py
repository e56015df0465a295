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
import threading
from typing import Literal, overload

import numba
import numpy as np

from ._parallel import interleave
from .errors import FovexpError
from .foveation import SigmaOnBlocks, _float_array, per_pixel_sigma
from .jit import FASTMATH, MAGIC_EXACT_BELOW, int64_to_float64, rint_to_int64
from .memory import WrittenRows, frame_empty, frame_zeros
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
    """``v`` in the table's fixed point: round(v 2**36) (to nearest, ties to even), exact for
    the values :func:`check_sat_fits` admits."""
    return rint_to_int64(np.float64(v) * _SAT_SCALE)


#: Image rows per strip of the contrast's summed-area tables (at least; a strip is at least
#: as tall as its border of 2 ``pad`` rows, so that no more than half its table is border).
#: Each strip's table ((rows + 2 pad + 1) x (W + 2 pad + 1) int64: 3.6 MB at 4K with a 25 px
#: border) stays in the cache while its boxes are read; one table of the whole frame (70 MB)
#: went to memory and back, twice (measured in the pipeline, 2 cores: the table and its boxes
#: 80 ms of a 4K frame, the strips about 70 ms; standalone 57 -> 51 ms).
STRIP_ROWS = 64


@numba.njit(cache=True, fastmath=FASTMATH, nogil=True)
def _table_into(img, pad, y0, y1, x0, x1, scratch, s):  # pragma: no cover - compiled
    """The exact summed-area table of rows [y0, y1) and columns [x0, x1) of the padded image
    (symmetric borders, :func:`_symmetric`) in fixed point (:func:`_fixed`), written into
    ``s[:y1 - y0 + 1, :x1 - x0 + 1]`` with its leading zero row and column, in one pass
    (each row's prefix sums added to the row above's, still in the cache). ``scratch`` is
    (2, at least ``x1 - x0``) ints. Returns the largest magnitude summed.

    Each row is converted to fixed point first, in a loop of its own that vectorises (the
    image's columns are contiguous between the borders); only the prefix sum is a chain. The
    largest magnitude is tracked on the fixed-point values (an integer maximum vectorises, a
    float one does not); a value the fixed point cannot hold (NaN, inf, 2**15 or more) makes
    it ``2**51`` or more, and that value itself is then returned, so that the caller's error
    names it."""
    h, w = img.shape
    hp, wp = y1 - y0, x1 - x0
    cols, fixed = scratch[0], scratch[1]
    for x in range(wp):
        cols[x] = _symmetric(x0 + x - pad, w)
    lo = min(wp, max(0, pad - x0))  # the columns [lo, hi) read the image's [x0 + lo - pad, ...)
    hi = max(lo, min(wp, w + pad - x0))
    first = s[0]
    for x in range(wp + 1):
        first[x] = 0
    largest = np.int64(0)
    for y in range(hp):
        src = img[_symmetric(y0 + y - pad, h)]
        for x in range(lo):
            fixed[x] = _fixed(src[cols[x]])
        for x in range(hi, wp):
            fixed[x] = _fixed(src[cols[x]])
        inner, out = src[x0 + lo - pad:x0 + hi - pad], fixed[lo:hi]  # indexed from 0
        for x in range(hi - lo):
            out[x] = _fixed(inner[x])
        for x in range(wp):
            largest = max(largest, abs(fixed[x]))
        if largest >= MAGIC_EXACT_BELOW:  # a value not held exactly: return it
            for x in range(wp):
                v = abs(np.float64(src[cols[x]]))
                if not v < MAGIC_EXACT_BELOW * _SAT_STEP:  # NaN, inf or too large
                    return v
        above, row = s[y], s[y + 1]
        row[0] = 0
        run = np.int64(0)
        for x in range(wp):
            run += fixed[x]
            row[x + 1] = above[x + 1] + run
    return np.float64(largest) * _SAT_STEP


#: Each thread's strip tables, kept from frame to frame: tables in fresh pages cost several ms
#: more than tables written again (fovexp/jit.py).
_SCRATCH = threading.local()


def _tables(parts: int, rows: int, cols: int) -> np.ndarray:
    """``parts`` (rows, cols) int64 tables, one per thread of a kernel: this thread's kept
    ones, grown when too small."""
    buf = getattr(_SCRATCH, "tables", None)
    if buf is None or buf.size < parts * rows * cols:
        buf = _SCRATCH.tables = np.empty(parts * rows * cols, np.int64)
    return buf[: parts * rows * cols].reshape(parts, rows, cols)


def _sat(
    img: np.ndarray, pad: int, y0: int, y1: int, x0: int, x1: int,
) -> tuple[np.ndarray, float]:
    """The summed-area table of rows [y0, y1) and columns [x0, x1) of the padded image, as a
    new array (the kernels build one per strip, :func:`_table_into`), and the largest
    magnitude it sums; refuses what :func:`check_sat_fits` refuses."""
    sat = np.empty((y1 - y0 + 1, x1 - x0 + 1), np.int64)
    largest = _table_into(img, pad, y0, y1, x0, x1, np.empty((2, x1 - x0), np.int64), sat)
    check_sat_fits(img.shape, pad, largest)
    return sat, largest


def check_sat_fits(shape: tuple[int, int], pad: int, max_value: float) -> None:
    """Refuse a frame whose summed-area table would overflow int64 (see
    :data:`SAT_FRACTION_BITS`), or whose values the fixed point cannot hold exactly
    (``2**51`` in steps of ``2**-36``: 32768): one clear error rather than wrong sums."""
    hp, wp = int(shape[0]) + 2 * pad, int(shape[1]) + 2 * pad
    if not max_value * _SAT_SCALE < MAGIC_EXACT_BELOW:
        raise FovexpError(
            f"luminance {max_value:g} is too large for the contrast stage's exact sums "
            f"(at most {MAGIC_EXACT_BELOW / _SAT_SCALE:g}; linear light is at most 1)"
        )
    if hp * wp * max(float(max_value), 1.0) * _SAT_SCALE >= _INT64_MAX:
        raise FovexpError(
            f"a {shape[1]}x{shape[0]} frame is too large for the contrast stage's exact sums "
            f"(at most about {_INT64_MAX / _SAT_SCALE / 1e6:.0f} million pixels with the blur "
            "border)"
        )


@numba.njit(cache=True, fastmath=FASTMATH, nogil=True)
def _box_sums_exact_as_float(pad, max_value):  # pragma: no cover - compiled
    """Whether every box sum (and its difference from ``n^2`` times the pixel) converts to
    float64 by :func:`fovexp.jit.int64_to_float64`: below ``2**51`` for the widest box
    (``2 pad - 2`` px, :func:`sat_pad_px`). Otherwise the kernels convert the slow way."""
    n = 2 * pad
    return n * n * max(max_value, 1.0) * _SAT_SCALE < MAGIC_EXACT_BELOW


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _to_float(i, magic):  # pragma: no cover - compiled
    return int64_to_float64(i) if magic else np.float64(i)


@numba.njit(cache=True, fastmath=FASTMATH, nogil=True)
def _row_change(img, sigma, sat, y, xs, xe, oy, ox, pad, f_e, add_input, magic, out):
    # pragma: no cover - compiled
    """The change of pixels [xs, xe) of row ``y``: per integer level ``k`` of the two
    bracketing a pixel's sigma, ``(1 - f_e (1 + k)) (avg_k - in)``, weighted by the linear
    interpolation; 0 where sigma = 0. Written into ``out`` (plus the input where
    ``add_input``). ``sat`` starts at row ``oy``, column ``ox`` of the padded image. A box
    that is one constant gives exactly 0: ``box - n^2 q`` is an integer difference of 0.

    The pixels go in runs of one integer level (sigma changes slowly along a row): within a
    run both levels' box widths, table rows and weights are fixed, the box corners are
    contiguous in memory, and the loop vectorises (``magic``: the int64 to float64
    conversion is :func:`fovexp.jit.int64_to_float64`)."""
    x = xs
    while x < xe:
        k0 = int(sigma[y, x])
        r = x + 1
        while r < xe and int(sigma[y, r]) == k0:
            r += 1
        # level k0 + 1; level k0 too unless it is 0 (width 0: the pixel itself, no change)
        # width n = box_width_px(k), MATLAB anchoring: [x - floor((n - 1) / 2), x + ceil(...)]
        n1 = BOX_WIDTH_PX_PER_LEVEL * (k0 + 1)
        c1 = (1.0 - f_e * (1.0 + (k0 + 1))) / (n1 * n1)
        a1 = y + pad - (n1 - 1) // 2 - oy
        top1, bottom1 = sat[a1], sat[a1 + n1]
        o1 = pad - (n1 - 1) // 2 - ox
        nn1 = np.float64(n1 * n1)
        n0 = BOX_WIDTH_PX_PER_LEVEL * max(k0, 1)
        c0 = (1.0 - f_e * (1.0 + k0)) / (n0 * n0) if k0 > 0 else 0.0
        a0 = y + pad - (n0 - 1) // 2 - oy
        top0, bottom0 = sat[a0], sat[a0 + n0]
        o0 = pad - (n0 - 1) // 2 - ox
        nn0 = np.float64(n0 * n0)
        # the run's rows and table rows as slices indexed from 0: indices of unknown sign
        # make Numba wrap negative ones, which keeps a loop scalar
        m = r - x
        sg, im, ot = sigma[y, x:r], img[y, x:r], out[y, x:r]
        t1a, t1b = top1[x + o1:x + o1 + m], top1[x + o1 + n1:x + o1 + n1 + m]
        b1a, b1b = bottom1[x + o1:x + o1 + m], bottom1[x + o1 + n1:x + o1 + n1 + m]
        t0a, t0b = top0[x + o0:x + o0 + m], top0[x + o0 + n0:x + o0 + n0 + m]
        b0a, b0b = bottom0[x + o0:x + o0 + m], bottom0[x + o0 + n0:x + o0 + n0 + m]
        for i in range(m):
            s = np.float64(sg[i])
            t = s - k0
            v = im[i]
            q = np.rint(np.float64(v) * _SAT_SCALE)  # _fixed(v), as a float64: exact
            # n^2 (avg - in) in fixed point: exact in float64 (integers below 2**53)
            d1 = _to_float(b1b[i] - t1b[i] - b1a[i] + t1a[i], magic) - nn1 * q
            d0 = _to_float(b0b[i] - t0b[i] - b0a[i] + t0a[i], magic) - nn0 * q
            # from +0.0, as a sum: a flat box's change is +0.0, never -0.0 (the skipped blocks')
            change = (0.0 + (1.0 - t) * c0 * d0 + t * c1 * d1) * _SAT_STEP if s > 0.0 else 0.0
            ot[i] = (np.float64(v) + change) if add_input else change
        x = r


@numba.njit(parallel=True, cache=True, fastmath=FASTMATH, nogil=True)
def _change_strips(img, sigma, pad, f_e, flat, shift, add_input, tables, largest, out):
    # pragma: no cover - compiled
    """:func:`_row_change` of every pixel whose ``2**shift`` square block ``flat`` does not
    mark (``flat`` of shape (0, 0): every pixel), written into ``out``, and 0 between them
    in a row: each row is written from its first block to compute to its last
    (:func:`_written_spans`), nothing elsewhere (those blocks are left out: their boxes are
    one constant, their change is 0; :class:`fovexp.memory.WrittenRows`). The rows go in strips
    of ``tables.shape[1] - 2 pad - 1``, each summed into a table of its own
    (:func:`_table_into`, ``tables[p]`` for part ``p``; columns from the first to the last
    block it computes), which stays in the cache while its boxes are read. The strips are
    spread over the parts in an interleaved order (flat strips cost nothing). ``largest``
    (one per strip) gets the largest magnitude each table sums (-1 for a strip left out):
    the caller refuses the frame when it is too large to sum exactly."""
    h, w = img.shape
    parts, rows = tables.shape[0], tables.shape[1] - 2 * pad - 1
    nst = (h + rows - 1) // rows
    stride = interleave(nst)
    skip = flat.shape[0] > 0
    nbx = flat.shape[1]
    for p in numba.prange(parts):
        table = tables[p]
        scratch = np.empty((2, tables.shape[2]), np.int64)
        for j in range(p, nst, parts):
            st = (j * stride) % nst
            y0, y1 = st * rows, min(h, (st + 1) * rows)
            x0, x1 = 0, w
            if skip:  # the columns of the blocks to compute, if any
                b0, b1 = nbx, -1
                for by in range(y0 >> shift, ((y1 - 1) >> shift) + 1):
                    for bx in range(nbx):
                        if not flat[by, bx]:
                            b0, b1 = min(b0, bx), max(b1, bx)
                            break
                    for bx in range(nbx - 1, b1, -1):
                        if not flat[by, bx]:
                            b1 = bx
                            break
                if b1 < 0:  # a strip left out: its change is 0
                    largest[st] = -1.0
                    continue
                x0, x1 = b0 << shift, min((b1 + 1) << shift, w)
            top = _table_into(img, pad, y0, y1 + 2 * pad, x0, x1 + 2 * pad, scratch, table)
            largest[st] = top
            magic = _box_sums_exact_as_float(pad, top)
            for y in range(y0, y1):
                if not skip:
                    _row_change(img, sigma, table, y, 0, w, y0, 0, pad, f_e, add_input, magic,
                                out)
                    continue
                by = y >> shift
                bx = 0
                done = -1  # where the row's last run ended (none yet)
                while bx < nbx:  # runs of consecutive blocks to compute, 0 between them
                    if flat[by, bx]:
                        bx += 1
                        continue
                    c0 = bx
                    while bx < nbx and not flat[by, bx]:
                        bx += 1
                    if done >= 0:
                        _zero(out[y, done:c0 << shift])
                    done = min(bx << shift, w)
                    _row_change(img, sigma, table, y, c0 << shift, done, y0, x0, pad, f_e,
                                False, magic, out)
    return out


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _zero(row):  # pragma: no cover - compiled
    """``row[:] = 0`` (a slice indexed from 0: the loop vectorises)."""
    for x in range(row.shape[0]):
        row[x] = 0.0


def unchanged_blocks(grey_flat: np.ndarray, max_sigma: float) -> np.ndarray:
    """The level-3 blocks whose every pixel's boxes, up to level ``floor(max_sigma) + 1``,
    lie in one constant region: their change is exactly +0.0 (the blocks skipping leaves
    out), and their luminance that constant. From the grey image's constant radius per
    block (:func:`fovexp.pyramids.constant_radius_blocks`)."""
    # the widest box reaches sat_pad_px from its pixel; symmetric padding reads inside it
    block = level_scale(FLAT_BLOCK_LEVEL)
    return grey_flat >= blocks_reaching(sat_pad_px(max_sigma), block)


def _enhance_channels(img: np.ndarray, sigma: np.ndarray, max_sigma: float, f_e: float):
    out = np.empty_like(img)
    for ch in range(img.shape[2]):
        plane = np.ascontiguousarray(img[..., ch])
        out[..., ch] = _strips(plane, sigma, f_e, None, max_sigma, True,
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


@overload
def contrast_change(
    grey: np.ndarray, sigma_map_px: np.ndarray, f_e: float,
    grey_flat: np.ndarray | None = None, written: Literal[False] = False,
) -> np.ndarray: ...


@overload
def contrast_change(
    grey: np.ndarray, sigma_map_px: np.ndarray, f_e: float,
    grey_flat: np.ndarray | None = None, *, written: Literal[True],
) -> WrittenRows: ...


def contrast_change(
    grey: np.ndarray, sigma_map_px: np.ndarray, f_e: float,
    grey_flat: np.ndarray | None = None, written: bool = False,
) -> np.ndarray | WrittenRows:
    """``contrast_enhance(grey) - grey`` of an (H, W) linear luminance image, in one pass: the
    change the pipeline adds to every colour channel (the method works on luminance). Float32
    or float64 (the result has the image's dtype).

    ``grey_flat``: how far around each level-3 block the image is one constant
    (:func:`fovexp.pyramids.constant_radius_blocks` of its block extremes), to leave out the
    blocks whose boxes all lie in one constant region, where the change is exactly 0 (the
    enhancer's skipping; the result is the same bit for bit). ``written``: the change as
    a :class:`fovexp.memory.WrittenRows`, its zeros outside each row's span not written."""
    img = _float_array(grey)
    sigma = _float_array(sigma_map_px)
    max_sigma = float(sigma.max()) if sigma.size else 0.0
    if max_sigma <= 0.0:
        return _unchanged(img, written)
    flat = unchanged_blocks(grey_flat, max_sigma) if grey_flat is not None else None
    change = _change_outside(img, sigma, float(f_e), flat, max_sigma)
    return change if written else change.full()


@overload
def contrast_change_where_needed(
    grey: np.ndarray, sigma_on_blocks: SigmaOnBlocks, max_sigma_px: float, f_e: float,
    grey_flat: np.ndarray, written: Literal[False] = False,
) -> np.ndarray: ...


@overload
def contrast_change_where_needed(
    grey: np.ndarray, sigma_on_blocks: SigmaOnBlocks, max_sigma_px: float, f_e: float,
    grey_flat: np.ndarray, *, written: Literal[True],
) -> WrittenRows: ...


def contrast_change_where_needed(
    grey: np.ndarray, sigma_on_blocks: SigmaOnBlocks, max_sigma_px: float, f_e: float,
    grey_flat: np.ndarray, written: bool = False,
) -> np.ndarray | WrittenRows:
    """:func:`contrast_change` with skipping, asking for the sigma map only where the change
    is not known to be 0 (:data:`fovexp.foveation.SigmaOnBlocks`).
    ``max_sigma_px`` bounds the sigma map from above; it sets how far the boxes reach. The
    result is :func:`contrast_change`'s, bit for bit (the boxes' sums are exact integers,
    whatever border the table has); ``written`` as there."""
    img = _float_array(grey)
    if max_sigma_px <= 0.0:
        return _unchanged(img, written)
    flat = unchanged_blocks(grey_flat, max_sigma_px)
    if flat.all():
        return _unchanged(img, written)
    sigma = _float_array(sigma_on_blocks(~flat, FLAT_BLOCK_LEVEL))
    change = _change_outside(img, sigma, float(f_e), flat, max_sigma_px)
    return change if written else change.full()


def _unchanged(img: np.ndarray, written: bool) -> np.ndarray | WrittenRows:
    """A change of 0 everywhere: zeros, or with ``written`` none written."""
    if not written:
        return frame_zeros(img.shape, img.dtype)
    return WrittenRows(frame_empty(img.shape, img.dtype), np.zeros((img.shape[0], 2), np.int64))


def _written_spans(flat: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Each row's [start, stop) from its first level-3 block ``flat`` does not mark to its
    last (empty where it marks them all): what :func:`_change_strips` writes."""
    h, w = shape
    block = level_scale(FLAT_BLOCK_LEVEL)
    need = ~flat
    some = need.any(axis=1)
    first = np.argmax(need, axis=1)
    last = need.shape[1] - 1 - np.argmax(need[:, ::-1], axis=1)
    spans = np.zeros((need.shape[0], 2), np.int64)
    spans[some, 0] = first[some] * block
    spans[some, 1] = np.minimum((last[some] + 1) * block, w)
    return np.repeat(spans, block, axis=0)[:h]


def _change_outside(
    img: np.ndarray, sigma: np.ndarray, f_e: float, flat: np.ndarray | None, max_sigma: float,
) -> WrittenRows:
    """The change of every pixel outside the level-3 blocks ``flat`` marks (0 there, written
    only between two blocks computed in a row); boxes up to level ``floor(max_sigma) + 1``."""
    out = frame_empty(img.shape, img.dtype)
    if flat is None or not flat.any():  # nothing to leave out
        return WrittenRows.whole(_strips(img, sigma, f_e, None, max_sigma, False, out))
    _strips(img, sigma, f_e, flat, max_sigma, False, out)
    return WrittenRows(out, _written_spans(flat, img.shape))


def _strips(
    img: np.ndarray, sigma: np.ndarray, f_e: float, flat: np.ndarray | None, max_sigma: float,
    add_input: bool, out: np.ndarray,
) -> np.ndarray:
    """:func:`_change_strips` into ``out``, on this thread's kept tables; refuses a frame
    whose values the exact sums cannot hold (:func:`check_sat_fits`)."""
    pad = sat_pad_px(max_sigma)
    h, w = img.shape
    rows = max(STRIP_ROWS, 2 * pad)
    parts = numba.get_num_threads()
    tables = _tables(parts, rows + 2 * pad + 1, w + 2 * pad + 1)
    largest = np.empty((h + rows - 1) // rows, np.float64)
    blocks = np.zeros((0, 0), np.bool_) if flat is None else np.ascontiguousarray(flat)
    _change_strips(img, sigma, pad, np.float64(f_e), blocks, FLAT_BLOCK_LEVEL, add_input,
                   tables, largest, out)
    # NaN fails the check as too large, as it should
    check_sat_fits(img.shape, pad, float(largest.max()) if largest.size else 0.0)
    return out
