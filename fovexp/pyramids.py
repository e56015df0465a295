
"""Image pyramids (paper sections 4.2, 4.3; docs/METHOD.md, 5.5, 5.7, 5.8).

Gaussian and Laplacian pyramids use the 5-tap binomial kernel [1, 4, 6, 4, 1] / 16 with
replicated borders, keeping every second sample (Burt and Adelson 1983), as the release does.
Sample ``j`` of level ``m`` sits on full-resolution pixel ``j * 2**m``.

Laplacian levels are counted from 1 (docs/METHOD.md, 3.2, erratum): ``L_1 = G_0 - expand(G_1)`` is
the finest band, 0.25..0.5 cycles/px, with centre ``2**-1.5``; level ``k`` has centre
``2**-(k + 0.5)`` cycles/px and lives on the grid of ``G_{k-1}``.

Min/max pyramids (paper section 4.2): level ``l`` holds the minimum (maximum) of each
``2**l x 2**l`` block of the full-resolution image.

References
----------
.. [tariq] Tariq, T., Tursun, C., Didyk, P. (2022). Noise-based Enhancement for Foveated
   Rendering. ACM Transactions on Graphics 41(4) (SIGGRAPH 2022). doi:10.1145/3528223.3530101
.. [burt] Burt, P. J., Adelson, E. H. (1983). The Laplacian Pyramid as a Compact Image Code.
   IEEE Transactions on Communications 31(4), 532-540. doi:10.1109/TCOM.1983.1095851
.. [keys] Keys, R. (1981). Cubic Convolution Interpolation for Digital Image Processing. IEEE
   Transactions on Acoustics, Speech, and Signal Processing 29(6), 1153-1160.
   doi:10.1109/TASSP.1981.1163711
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numba
import numpy as np
from scipy import ndimage

from ._parallel import interleave
from .jit import FASTMATH, flat_broadcast
from .memory import frame_empty

#: Burt-Adelson 5-tap binomial kernel; its variance is 1 px^2 at the level it filters.
BINOMIAL_5 = np.array([1.0, 4.0, 6.0, 4.0, 1.0], dtype=np.float32) / 16.0
#: :func:`expand`'s polyphase taps (zero insertion, then BINOMIAL_5 x 2): an even output takes
#: the kernel's even taps, at a[i-1], a[i], a[i+1] ([1, 6, 1] / 8), an odd output its odd
#: taps, at a[i], a[i+1] ([1, 1] / 2).
EXPAND_EVEN_TAPS = 2 * BINOMIAL_5[0::2]
EXPAND_ODD_TAPS = 2 * BINOMIAL_5[1::2]
# float32 scalars for the compiled loops (the kernels are symmetric)
_REDUCE_OUTER, _REDUCE_INNER = BINOMIAL_5[0], BINOMIAL_5[1]
_EXPAND_SIDE = EXPAND_EVEN_TAPS[0]
_EXPAND_HALF = EXPAND_ODD_TAPS[0]
_NINE = np.float32(9.0)


def level_scale(level: int) -> int:
    """Full-resolution pixels per sample of Gaussian level ``level``."""
    return 1 << level


def gaussian_sigma_px(level: int) -> float:
    """Effective Gaussian std (full-res px) of Gaussian level ``level``: sum of 4**j, j < level.

    Each reduce filters with variance 1 in its input's pixels, i.e. 4**j full-res px^2.
    """
    return float(np.sqrt((4.0**level - 1.0) / 3.0))


# The reduce and expand loops are written as "centre + weighted differences" (mathematically
# the same filters): a constant region then gives exactly its constant on every level, so
# |L| is exactly 0 there and the flat regions the enhancer skips are exactly those whose result
# is 0 (EngineOptions.skip). They are compiled without fast-math (no reassociation may undo
# the form); they vectorise all the same, having no reductions. Any float dtype: the
# constants are exact dyadic fractions, exact in float32 and float64 alike.


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _taps5(c, m2, m1, p1, p2):  # pragma: no cover - compiled
    """BINOMIAL_5 at centre ``c``: ``c + k0 ((m2 - c) + (p2 - c)) + k1 ((m1 - c) + (p1 - c))``."""
    return c + (_REDUCE_OUTER * ((m2 - c) + (p2 - c)) + _REDUCE_INNER * ((m1 - c) + (p1 - c)))


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _taps3(c, m1, p1):  # pragma: no cover - compiled
    """EXPAND_EVEN_TAPS at centre ``c``: ``c + side ((m1 - c) + (p1 - c))``."""
    return c + _EXPAND_SIDE * ((m1 - c) + (p1 - c))


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _taps2(c, p1):  # pragma: no cover - compiled
    """EXPAND_ODD_TAPS from ``c``: ``c + half (p1 - c)``."""
    return c + _EXPAND_HALF * (p1 - c)


#: Output rows :func:`_reduce_2d` and :func:`_reduce_hwc` compute one after the other on a thread.
_REDUCE_RUN_ROWS = 16


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _reduce_2d_span(img, r, j0, j1, row, dst):  # pragma: no cover - compiled
    """Outputs ``[j0, j1)`` of the :func:`reduce` row centred on source row ``r`` of ``img``
    (H, W): the column pass on the source columns they read (into ``row``, of W), then the
    pass along the row."""
    h, w = img.shape
    wo = dst.shape[0]
    xs, xe = max(2 * j0 - 2, 0), min(2 * (j1 - 1) + 2, w - 1) + 1
    # the five source rows as slices indexed from 0 (the loop vectorises)
    a0, am2, am1 = img[r, xs:xe], img[max(r - 2, 0), xs:xe], img[max(r - 1, 0), xs:xe]
    ap1, ap2 = img[min(r + 1, h - 1), xs:xe], img[min(r + 2, h - 1), xs:xe]
    part = row[xs:xe]
    for x in range(xe - xs):
        part[x] = _taps5(a0[x], am2[x], am1[x], ap1[x], ap2[x])
    # the interior outputs (no clamping) from slices indexed from 0, then the borders
    j_lo = min(max(j0, 1), j1)
    j_hi = max(min(max(min((w - 3) // 2 + 1, wo), 1), j1), j_lo)
    src, d = row[2 * j_lo - 2:2 * j_hi + 1], dst[j_lo:j_hi]
    for jj in range(j_hi - j_lo):
        b = 2 * jj
        d[jj] = _taps5(src[b + 2], src[b], src[b + 1], src[b + 3], src[b + 4])
    for j in range(j0, j1):
        if j_lo <= j < j_hi:
            continue
        c = 2 * j
        dst[j] = _taps5(row[c], row[max(c - 2, 0)], row[max(c - 1, 0)],
                        row[min(c + 1, w - 1)], row[min(c + 2, w - 1)])


@numba.njit(parallel=True, cache=True, fastmath=FASTMATH, nogil=True)
def _reduce_2d(img, flat, values, block):  # pragma: no cover - compiled
    """:func:`reduce` of one channel (H, W): its stride known, the pass along the row takes
    half the time it takes in :func:`_reduce_hwc` with C = 1.

    With ``flat`` and ``values`` of ``block`` px blocks (whether the 3 x 3 blocks around a
    block are one finite constant, and the blocks' minima; else both of shape (0, 0)), an
    output whose centre pixel's block is flat (its five-by-five taps all in those blocks) is
    ``v + 0``, what the taps give it (``v + k (0 + 0)``: -0.0 becomes +0.0), without reading
    the image; the others are computed in runs. Two neighbouring flat blocks share their
    constant (their 3 x 3 windows overlap): a run of them is one fill."""
    h, w = img.shape
    ho, wo = (h + 1) // 2, (w + 1) // 2
    out = np.empty((ho, wo), dtype=img.dtype)
    skip = flat.shape[0] > 0
    zero = img.dtype.type(0.0)
    # runs of consecutive rows (which share source rows in the cache), the runs spread over
    # the threads: the rows to compute may be all in one part of the frame (_reduce_hwc)
    runs = (ho + _REDUCE_RUN_ROWS - 1) // _REDUCE_RUN_ROWS
    stride = interleave(runs) if skip else 1
    for k in numba.prange(runs * _REDUCE_RUN_ROWS):
        i = ((k // _REDUCE_RUN_ROWS) * stride) % runs * _REDUCE_RUN_ROWS + k % _REDUCE_RUN_ROWS
        if i >= ho:
            continue
        r = 2 * i
        row = np.empty(w, dtype=img.dtype)
        dst = out[i]
        if not skip:
            _reduce_2d_span(img, r, 0, wo, row, dst)
            continue
        by = r // block
        flats = flat[by]
        nflat = 0
        for b in range(flats.shape[0]):  # it vectorises: a row without a flat block is one run
            nflat += flats[b]
        if nflat == 0:
            _reduce_2d_span(img, r, 0, wo, row, dst)
            continue
        j = 0
        while j < wo:
            bx = 2 * j // block
            is_flat = flats[bx]
            # the run of blocks alike: its outputs [j, je)
            while bx + 1 < flats.shape[0] and flats[bx + 1] == is_flat:
                bx += 1
            je = min(wo, ((bx + 1) * block + 1) // 2)  # the first output of the next block
            if is_flat:
                v = values[by, 2 * j // block] + zero
                run = dst[j:je]
                for jj in range(je - j):
                    run[jj] = v
            else:
                _reduce_2d_span(img, r, j, je, row, dst)
            j = je
    return out


@numba.njit(parallel=True, cache=True, fastmath=FASTMATH, nogil=True)
def _reduce_hwc(img, pad, lo, hi, out):  # pragma: no cover - compiled
    """:func:`reduce` of an (H, W, C) image with its border replicated ``pad`` px on every
    side (read through clamped indices: the padded copy is never made), its channels kept
    interleaved: the pass down the columns runs along whole rows of W C values (it
    vectorises, and no channel is copied out and back), the pass along the row on every
    second pixel. Replicated columns have the same column pass, so reading the real ones
    gives the padded image's result bit for bit. Written into ``out`` ((H + 2 pad + 1) // 2,
    (W + 2 pad + 1) // 2, C): of output row ``i`` only the columns ``[lo[i], hi[i])`` (the
    others are left as they are; :func:`wanted_columns`), and of the column pass only the
    source columns those read."""
    h, w, c = img.shape
    ho, wo = out.shape[0], out.shape[1]
    n = w * c
    rows = img.reshape((h, n))
    # runs of consecutive rows (which share source rows in the cache), the runs spread over
    # the threads: the rows with columns to compute may be all in one part of the frame
    runs = (ho + _REDUCE_RUN_ROWS - 1) // _REDUCE_RUN_ROWS
    stride = interleave(runs)
    for k in numba.prange(runs * _REDUCE_RUN_ROWS):
        i = ((k // _REDUCE_RUN_ROWS) * stride) % runs * _REDUCE_RUN_ROWS + k % _REDUCE_RUN_ROWS
        jl, jh = (max(lo[i], 0), min(hi[i], wo)) if i < ho else (0, 0)
        if jl >= jh:
            continue
        r = 2 * i - pad  # in the image's rows
        # the source columns the outputs [jl, jh) read (clamped: inside the image)
        xs = min(max(2 * jl - pad - 2, 0), w - 1)
        xe = min(max(2 * (jh - 1) - pad + 2, 0), w - 1) + 1
        # the five source rows as slices indexed from 0 (Numba then drops its wraparound
        # checks and the loop vectorises)
        a0 = rows[min(max(r, 0), h - 1), xs * c:xe * c]
        am2 = rows[min(max(r - 2, 0), h - 1), xs * c:xe * c]
        am1 = rows[min(max(r - 1, 0), h - 1), xs * c:xe * c]
        ap1 = rows[min(max(r + 1, 0), h - 1), xs * c:xe * c]
        ap2 = rows[min(max(r + 2, 0), h - 1), xs * c:xe * c]
        row = np.empty(n, dtype=img.dtype)
        part = row[xs * c:xe * c]
        for x in range((xe - xs) * c):
            part[x] = _taps5(a0[x], am2[x], am1[x], ap1[x], ap2[x])
        # then channel by channel (no loop over channels inside the loop over pixels)
        dst = out[i].reshape(wo * c)
        # interior outputs (all five taps inside the row: no clamping), from slices indexed
        # from 0; the border ones below
        j_lo = min(max((pad + 3) // 2, jl), jh)
        j_hi = max(min((w - 3 + pad) // 2 + 1, jh), j_lo)
        cnt = j_hi - j_lo
        if cnt > 0:
            base = (2 * j_lo - pad - 2) * c
            src = row[base:base + (2 * cnt + 3) * c]
            d = dst[j_lo * c:j_hi * c]
            c2 = 2 * c
            for ch in range(c):
                for jj in range(cnt):
                    b = jj * c2 + ch
                    d[jj * c + ch] = _taps5(src[b + c2], src[b], src[b + c], src[b + 3 * c],
                                            src[b + 2 * c2])
        for ch in range(c):
            for j in range(jl, jh):
                if j_lo <= j < j_hi:
                    continue
                q = 2 * j - pad
                dst[j * c + ch] = _taps5(
                    row[min(max(q, 0), w - 1) * c + ch], row[min(max(q - 2, 0), w - 1) * c + ch],
                    row[min(max(q - 1, 0), w - 1) * c + ch],
                    row[min(max(q + 1, 0), w - 1) * c + ch],
                    row[min(max(q + 2, 0), w - 1) * c + ch])
    return out


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _expand_row(a, y, x0, x1, row):  # pragma: no cover - compiled
    """The vertical pass of :func:`expand` for output row ``y``: ``row[x]`` for the columns
    ``x0 <= x < x1`` of ``a``."""
    h = a.shape[0]
    i = y // 2
    # rows sliced from column x0: indexed from 0, the loops vectorise (an index of unknown
    # sign keeps a loop scalar: fovexp/gabor.py)
    c, out = a[i, x0:x1], row[x0:x1]
    if y % 2 == 0:
        m1, p1 = a[max(i - 1, 0), x0:x1], a[min(i + 1, h - 1), x0:x1]
        for x in range(x1 - x0):
            out[x] = _taps3(c[x], m1[x], p1[x])
    else:
        p1 = a[min(i + 1, h - 1), x0:x1]
        for x in range(x1 - x0):
            out[x] = _taps2(c[x], p1[x])


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _expand_at(row, x, w):  # pragma: no cover - compiled
    """The horizontal pass of :func:`expand` at output column ``x`` (``w`` columns in ``row``)."""
    j = x // 2
    if x % 2 == 0:
        return _taps3(row[j], row[max(j - 1, 0)], row[min(j + 1, w - 1)])
    return _taps2(row[j], row[min(j + 1, w - 1)])


@numba.njit(parallel=True, cache=True, fastmath=FASTMATH, nogil=True)
def _expand_2d(a: np.ndarray, ho: int, wo: int) -> np.ndarray:  # pragma: no cover - compiled
    h, w = a.shape
    out = np.empty((ho, wo), dtype=a.dtype)
    for y in numba.prange(ho):
        row = np.empty(w, dtype=a.dtype)
        _expand_row(a, y, 0, w, row)
        for x in range(wo):
            out[y, x] = _expand_at(row, x, w)
    return out


def _per_channel(fn, image: np.ndarray, *args: int) -> np.ndarray:
    image = np.ascontiguousarray(image)
    if image.dtype not in (np.float32, np.float64):
        image = image.astype(np.float32)
    if image.ndim == 2:
        return fn(image, *args)
    return np.stack(
        [fn(np.ascontiguousarray(image[..., c]), *args) for c in range(image.shape[2])], axis=-1
    )


def reduce(
    image: np.ndarray, pad_px: int = 0,
    constant: tuple[np.ndarray, np.ndarray, int] | None = None,
) -> np.ndarray:
    """One Gaussian-pyramid step: binomial filter (replicated borders), keep every second sample.

    Works on (H, W) or (H, W, C) float32 or float64 images (the result has their dtype);
    a constant region gives exactly its constant. ``pad_px``: the step of the image with its
    border replicated that many px on every side (``np.pad(mode="edge")``), bit for bit,
    without making the padded copy.

    ``constant``: of an (H, W) image without padding, ``(radius, values, block)`` where it is
    known to be one constant (:func:`constant_radius_blocks` of its ``block`` px blocks and
    their minima): the outputs there are that constant, the same numbers, without reading
    those pixels.
    """
    if pad_px < 0:
        raise ValueError(f"pad_px must be >= 0, not {pad_px}")
    image = np.ascontiguousarray(image)
    if image.dtype not in (np.float32, np.float64):
        image = image.astype(np.float32)
    if image.ndim == 2 and pad_px == 0:
        if constant is None:
            return _reduce_2d(image, _NO_FLAT, np.zeros((0, 0), image.dtype), 1)
        radius, values, block = constant
        if int(block) < 2:  # the taps reach 2 px: within the next block only if it is as wide
            raise ValueError(f"constant blocks of at least 2 px, not {block}")
        grid = (-(-image.shape[0] // block), -(-image.shape[1] // block))
        if radius.shape != grid or values.shape != grid:
            raise ValueError(f"constant blocks of shape {radius.shape} and {values.shape} "
                             f"for {block} px blocks of a {image.shape} image")
        values = np.ascontiguousarray(values, image.dtype)
        flat = np.ascontiguousarray((np.asarray(radius) >= 1) & np.isfinite(values))
        if not flat.any():  # in order: consecutive runs of rows share their source rows
            return _reduce_2d(image, _NO_FLAT, np.zeros((0, 0), image.dtype), 1)
        return _reduce_2d(image, flat, values, int(block))
    if constant is not None:
        raise ValueError("constant blocks are for an (H, W) image without padding")
    if image.ndim == 2:
        return _reduce_padded(image[..., None], int(pad_px))[..., 0]
    return _reduce_padded(image, int(pad_px))


#: :func:`_reduce_2d`'s blocks when none is known constant.
_NO_FLAT = np.zeros((0, 0), np.bool_)


def _reduce_padded(
    image: np.ndarray, pad: int, out: np.ndarray | None = None,
    columns: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """:func:`_reduce_hwc` of a contiguous (H, W, C) float image: every output column, or
    those of ``columns`` (per output row, ``[lo, hi)``), into ``out`` or a new array."""
    h, w, c = image.shape
    ho, wo = (h + 2 * pad + 1) // 2, (w + 2 * pad + 1) // 2
    if out is None:
        out = np.empty((ho, wo, c), image.dtype)
    if columns is None:
        columns = np.zeros(ho, np.int64), np.full(ho, wo, np.int64)
    return _reduce_hwc(image, pad, columns[0], columns[1], out)


def expand(image: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Inverse step of :func:`reduce`: upsample to ``shape`` (the finer level's size).

    Zero insertion and filtering with the binomial kernel x 2, in polyphase form
    (:data:`EXPAND_EVEN_TAPS`, :data:`EXPAND_ODD_TAPS`): even outputs
    ``(a[i-1] + 6 a[i] + a[i+1]) / 8``, odd outputs ``(a[i] + a[i+1]) / 2``, borders replicated.
    """
    return _per_channel(_expand_2d, image, int(shape[0]), int(shape[1]))


def gaussian_pyramid(
    image: np.ndarray, levels: int, pad_px: int = 0,
    constant: tuple[np.ndarray, np.ndarray, int] | None = None,
) -> list[np.ndarray]:
    """``[G_0, ..., G_levels]`` with ``G_0`` the image itself (not copied). With ``pad_px``,
    ``G_1`` and up are those of the image with its border replicated ``pad_px`` px on every
    side (:func:`reduce`); ``G_0`` stays the image, unpadded. ``constant``: where the image is
    known to be one constant, for ``G_1`` (:func:`reduce`; the same numbers)."""
    pyr = [image]
    for m in range(levels):
        pad = pad_px if m == 0 else 0
        if min(pyr[-1].shape[:2]) + 2 * pad < 2:
            break
        pyr.append(reduce(pyr[-1], pad, constant if m == 0 else None))
    return pyr


def packed_pyramid(
    image: np.ndarray, levels: int, pad_px: int = 0,
    columns: Callable[[int, int, int], tuple[np.ndarray, np.ndarray]] | None = None,
    buffer: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """``G_1 .. G_levels`` of :func:`gaussian_pyramid` of a contiguous (H, W, C) float image,
    written into one flat buffer (no copy of the levels into it); returns it and a
    (levels + 1, 3) table of each level's (start, height, width) in it (row 0 unused:
    ``G_0`` is the image; a level too small to build, where :func:`gaussian_pyramid` stops,
    all zeros).
    ``columns(level, height, width)``: the ``[lo, hi)`` columns of each of that level's rows
    to compute (:func:`wanted_columns`); the others are left unset, for a reader that never
    reads them. ``buffer``: the buffer to write into (at least as large; a test fills it
    with NaN to show that nothing unset is read)."""
    h, w, c = image.shape
    shapes = []
    for m in range(levels):
        pad = pad_px if m == 0 else 0
        if min(h, w) + 2 * pad < 2:
            break
        h, w = (h + 2 * pad + 1) // 2, (w + 2 * pad + 1) // 2
        shapes.append((h, w))
    meta = np.zeros((levels + 1, 3), dtype=np.int64)
    start = 0
    for m, (lh, lw) in enumerate(shapes, start=1):
        meta[m] = (start, lh, lw)
        start += lh * lw * c
    buf = frame_empty((start,), image.dtype) if buffer is None else buffer[:start]
    src = image
    for m, (lh, lw) in enumerate(shapes, start=1):
        out = buf[meta[m, 0]:meta[m, 0] + lh * lw * c].reshape(lh, lw, c)
        _reduce_padded(src, pad_px if m == 1 else 0, out,
                       None if columns is None else columns(m, lh, lw))
        src = out
    return buf, meta


def wanted_columns(
    marks: np.ndarray, block: int, reach_px: int, level: int, pad_px: int, width: int,
    height: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Per row of pyramid level ``level`` (``height`` x ``width``, built on the image padded
    ``pad_px``: level pixel X lies at full-resolution X 2**level - pad_px), the columns
    ``[lo, hi)`` that cover every pixel of the row within ``reach_px`` (full-resolution px,
    along each axis) of a ``block`` px square block ``marks`` marks: the span from the first
    to the last such column, a superset (``lo = hi = 0``: none)."""
    s = level_scale(level)
    nby, nbx = marks.shape
    lo, hi = np.zeros(height, np.int64), np.zeros(height, np.int64)
    if not marks.any():
        return lo, hi
    any_ = marks.any(axis=1)
    first = np.where(any_, marks.argmax(axis=1), nbx)
    last = np.where(any_, nbx - 1 - marks[:, ::-1].argmax(axis=1), -1)
    # each block row's span over the block rows within reach (+1: a block spans its rows)
    r = -(-reach_px // block) + 1
    size = 2 * r + 1
    first = ndimage.minimum_filter1d(first, size, mode="constant", cval=nbx)
    last = ndimage.maximum_filter1d(last, size, mode="constant", cval=-1)
    y = np.arange(height, dtype=np.int64) * s - pad_px
    by = np.clip(y // block, 0, nby - 1)
    near = (y + reach_px >= 0) & (y - reach_px < nby * block)
    f, la = first[by], last[by]
    ok = near & (la >= f)
    # the level's columns X whose full-resolution X s - pad_px lies within reach of the span
    lo[ok] = np.clip((f[ok] * block - reach_px + pad_px) // s, 0, width)
    hi[ok] = np.clip(((la[ok] + 1) * block - 1 + reach_px + pad_px) // s + 1, 0, width)
    return lo, hi


#: Side (level pixels) of the tiles :func:`smoothed_abs_laplacian` computes or leaves out.
ABS_LAPLACIAN_TILE = 32


@numba.njit(parallel=True, cache=True, fastmath=FASTMATH, nogil=True)
def _abs_laplacian_tiles(fine, coarse, need, tile, zero_rest, out):
    # pragma: no cover - compiled
    """``|fine - expand(coarse)|`` smoothed by a 3 x 3 mean (borders replicated), written into
    ``out`` on the ``tile`` x ``tile`` tiles where ``need`` is true, and with ``zero_rest`` 0
    on the others (else they are not written). A tile is computed with a one-pixel border of
    the difference, so each value is the same whichever tiles run."""
    h, w = fine.shape
    wc = coarse.shape[1]
    th, tw = need.shape
    # the tiles left out get their zeros here, on the threads: a zeroed 4K level before the
    # pass was one thread's 33 MB write, 4.6 ms of a three-quarters-flat frame
    idle = np.flatnonzero(~need.ravel()) if zero_rest else np.zeros(0, np.int64)
    for i in numba.prange(idle.shape[0]):
        ty, tx = idle[i] // tw, idle[i] % tw
        y0, x0 = ty * tile, tx * tile
        y1, x1 = min(y0 + tile, h), min(x0 + tile, w)
        for y in range(y0, y1):
            dst = out[y, x0:x1]
            for x in range(x1 - x0):
                dst[x] = 0.0
    todo = np.flatnonzero(need.ravel())  # the tiles to compute, all of one cost
    for i in numba.prange(todo.shape[0]):
        ty, tx = todo[i] // tw, todo[i] % tw
        y0, x0 = ty * tile, tx * tile
        y1, x1 = min(y0 + tile, h), min(x0 + tile, w)
        ya, yb = max(y0 - 1, 0), min(y1 + 1, h)
        xa, xb = max(x0 - 1, 0), min(x1 + 1, w)
        # coarse columns the expansion of columns [xa, xb) reads
        ca, cb = max(xa // 2 - 1, 0), min((xb - 1) // 2 + 2, wc)
        row = np.empty(wc, dtype=fine.dtype)
        diff = np.empty((yb - ya, xb - xa), dtype=fine.dtype)
        for y in range(ya, yb):
            _expand_row(coarse, y, ca, cb, row)
            _abs_difference_row(fine[y], row, xa, xb, wc, diff[y - ya])
        # columns whose 3 x 3 window lies inside the image: no clamping, a loop that
        # vectorises; the image's first and last column and row take the clamped one
        xi0, xi1 = max(x0, 1), min(x1, w - 1)
        for y in range(y0, y1):
            inner = 0 < y < h - 1
            for x in range(x0, x1):
                if inner and xi0 <= x < xi1:
                    continue
                out[y, x] = _mean3x3_clamped(diff, y, x, ya, xa, h, w)
            if inner:
                # slices indexed from 0: an index of unknown sign keeps a loop scalar
                # (fovexp/gabor.py); column x - 1 of the image at index 0
                a, m = xi0 - 1 - xa, xi1 - xi0
                r0 = diff[y - 1 - ya, a:a + m + 2]
                r1 = diff[y - ya, a:a + m + 2]
                r2 = diff[y + 1 - ya, a:a + m + 2]
                dst = out[y, xi0:xi1]
                for c in range(m):
                    # the clamped loop's terms in its order (float addition is not
                    # associative: the same order gives the same bits)
                    acc = r0[c]
                    acc += r0[c + 1]
                    acc += r0[c + 2]
                    acc += r1[c]
                    acc += r1[c + 1]
                    acc += r1[c + 2]
                    acc += r2[c]
                    acc += r2[c + 1]
                    acc += r2[c + 2]
                    dst[c] = acc / _NINE
    return out


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _abs_difference_row(fine, row, xa, xb, wc, out):  # pragma: no cover - compiled
    """``out[x - xa] = |fine[x] - expand(row)[x]|`` for the columns [xa, xb) of one row
    (:func:`_expand_at` of the expanded coarse row ``row``, ``wc`` columns). The columns
    ``2 j, 2 j + 1`` whose taps lie inside ``row`` go in pairs, one loop without clamps or a
    parity test, indexed from 0, that vectorises; the few others as :func:`_expand_at` says.
    The same values."""
    x = xa
    while x < xb and (x % 2 == 1 or x < 2):
        out[x - xa] = abs(fine[x] - _expand_at(row, x, wc))
        x += 1
    j0 = x // 2
    m = max(min(xb // 2, wc - 1) - j0, 0)  # pairs with 2 j + 1 < xb and j + 1 < wc
    c, m1, p1 = row[j0:j0 + m], row[j0 - 1:j0 - 1 + m], row[j0 + 1:j0 + 1 + m]
    f, d = fine[2 * j0:2 * j0 + 2 * m], out[2 * j0 - xa:2 * j0 - xa + 2 * m]
    for t in range(m):
        d[2 * t] = abs(f[2 * t] - _taps3(c[t], m1[t], p1[t]))
        d[2 * t + 1] = abs(f[2 * t + 1] - _taps2(c[t], p1[t]))
    for x in range(2 * (j0 + m), xb):
        out[x - xa] = abs(fine[x] - _expand_at(row, x, wc))


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _mean3x3_clamped(diff, y, x, ya, xa, h, w):  # pragma: no cover - compiled
    """The 3 x 3 mean of the difference at (y, x), borders replicated (``diff`` starts at
    row ``ya``, column ``xa`` of the image)."""
    # the sum starts from its first term (0 + a == a), in the dtype of the image
    acc = diff[max(y - 1, 0) - ya, max(x - 1, 0) - xa]
    for dy in range(-1, 2):
        yy = min(max(y + dy, 0), h - 1) - ya
        for dx in range(-1, 2):
            if dy != -1 or dx != -1:
                acc += diff[yy, min(max(x + dx, 0), w - 1) - xa]
    return acc / _NINE


def pyramid_depth(shape: tuple[int, int], levels: int) -> int:
    """How many levels past G_0 :func:`gaussian_pyramid` builds for an image of ``shape``."""
    h, w = int(shape[0]), int(shape[1])
    n = 0
    while n < levels and min(h, w) >= 2:
        h, w, n = (h + 1) // 2, (w + 1) // 2, n + 1
    return n


def tile_grid(shape: tuple[int, int], tile: int = ABS_LAPLACIAN_TILE) -> tuple[int, int]:
    """Tiles per column and per row of an (H, W) grid cut into ``tile`` x ``tile`` tiles."""
    return -(-int(shape[0]) // tile), -(-int(shape[1]) // tile)


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _mark_taps_on(x, y, k, rows, cols, shift, offsets, tile_cols, marks):
    # pragma: no cover - compiled
    """The tiles of level ``k`` the taps at full-resolution (x, y) read, marked."""
    inv = 1.0 / np.float64(1 << (k - 1))  # 1 / level_scale(k - 1): exact
    n_y, n_x = rows[k], cols[k]
    ny = np.int64(math.floor(y * inv))
    nx = np.int64(math.floor(x * inv))
    # clamped to the grid, so >= 0: the shift is the floor division
    ty0 = min(max(ny - 1, 0), n_y - 1) >> shift
    ty1 = min(max(ny + 2, 0), n_y - 1) >> shift
    tx0 = min(max(nx - 1, 0), n_x - 1) >> shift
    tx1 = min(max(nx + 2, 0), n_x - 1) >> shift
    base, tc = offsets[k], tile_cols[k]
    marks[base + ty0 * tc + tx0] = True
    marks[base + ty0 * tc + tx1] = True
    marks[base + ty1 * tc + tx0] = True
    marks[base + ty1 * tc + tx1] = True


@numba.njit(cache=True, fastmath=FASTMATH, nogil=True)
def _mark_tiles_of_taps(x_px, y_px, k0, top, rows, cols, shift, offsets, tile_cols, marks):
    # pragma: no cover - compiled
    """:func:`tiles_of_taps` into ``marks``: level k's (tile rows, tile columns) grid flat
    from ``offsets[k]``, ``tile_cols[k]`` per row; level k's samples (rows[k], cols[k]);
    tiles of ``2**shift`` nodes. Powers of two as a multiply and shifts (a point's four
    integer divisions per level had been most of its time), the two levels written out
    (0.39 M points, one thread: 19.7 -> 8.4 ms)."""
    for i in range(k0.shape[0]):
        k = k0[i]
        if 1 <= k <= top:
            _mark_taps_on(x_px[i], y_px[i], k, rows, cols, shift, offsets, tile_cols, marks)
        if 1 <= k + 1 <= top:
            _mark_taps_on(x_px[i], y_px[i], k + 1, rows, cols, shift, offsets, tile_cols,
                          marks)


def tiles_of_taps(
    x_px: np.ndarray, y_px: np.ndarray, k0: np.ndarray, gaussian: list[np.ndarray], top: int,
    tile: int = ABS_LAPLACIAN_TILE,
) -> dict[int, np.ndarray]:
    """Per level k in 1..``top``, the ``tile`` x ``tile`` tiles of |L_k| (on level k - 1's
    grid, ``gaussian[k - 1]``) that bilinear taps at full-resolution points (``x_px``,
    ``y_px``) read on levels ``k0`` and ``k0 + 1``, with one more node each side as a margin
    (:func:`fovexp.amplitude.laplacian_amplitude_at`'s samples): the taps span at most two
    tiles each way. One compiled pass over the points. ``tile`` is a power of two."""
    if tile < 1 or tile & (tile - 1):
        raise ValueError(f"tiles of {tile} nodes: a power of two is needed")
    rows = np.zeros(top + 1, np.int64)
    cols = np.zeros(top + 1, np.int64)
    offsets = np.zeros(top + 2, np.int64)
    tile_cols = np.zeros(top + 1, np.int64)
    for k in range(1, top + 1):
        rows[k], cols[k] = gaussian[k - 1].shape[:2]
        ty, tx = tile_grid(gaussian[k - 1].shape, tile)
        tile_cols[k] = tx
        offsets[k + 1] = offsets[k] + ty * tx
    marks = np.zeros(int(offsets[top + 1]), np.bool_)
    _mark_tiles_of_taps(np.asarray(x_px, np.float64), np.asarray(y_px, np.float64),
                        np.asarray(k0, np.int64), int(top), rows, cols,
                        int(tile).bit_length() - 1, offsets, tile_cols, marks)
    return {k: marks[offsets[k]:offsets[k + 1]].reshape(tile_grid(gaussian[k - 1].shape, tile))
            for k in range(1, top + 1)}


def smoothed_abs_laplacian(
    gaussian: list[np.ndarray], levels: int, need: dict[int, np.ndarray] | None = None,
    zero_rest: bool = True,
) -> dict[int, np.ndarray]:
    """``|L_k|`` smoothed by a 3 x 3 mean on its own grid (docs/METHOD.md, 5.7),
    ``k = 1..levels``, in one fused pass per level: ``|G_{k-1} - expand(G_k)|`` then the mean.

    ``need[k]`` (bool, :func:`tile_grid` of level k's grid) limits level k to the tiles that
    are read (the enhancer's skipping); the others are 0, or with ``zero_rest=False`` not
    written at all (for a reader of the needed tiles only: the enhancer's, whose 4K level 1
    of a three-quarters-flat frame took 2 ms more with them). A tile's values are the same
    whichever tiles are computed. With the exact pyramid arithmetic, a tile whose
    neighbourhood of G_0 is constant (:func:`abs_laplacian_reach_px`) is exactly 0 anyway."""
    out = {}
    for k in range(1, min(levels, len(gaussian) - 1) + 1):
        fine = np.ascontiguousarray(gaussian[k - 1])
        coarse = np.ascontiguousarray(gaussian[k])
        mask = need.get(k) if need is not None else None
        if mask is None:
            mask = np.ones(tile_grid(fine.shape), dtype=np.bool_)
        out[k] = frame_empty(fine.shape, fine.dtype)
        _abs_laplacian_tiles(fine, coarse, mask, ABS_LAPLACIAN_TILE, zero_rest, out[k])
    return out


def abs_laplacian_reach_px(level: int | np.ndarray) -> int | np.ndarray:
    """How far (full-resolution px) the image reaches into a bilinear sample of the smoothed
    ``|L_level|`` (:func:`smoothed_abs_laplacian`, :func:`sample_bilinear`): the sample at
    ``p`` depends only on G_0 within ``p +- (9 s - 2)``, ``s = 2**(level - 1)``: node ``j``
    of G_{k-1} depends on G_0 within ``s j +- 2 (s - 1)`` (the reduces), the expansion and the
    3 x 3 mean on G_{k-1} within ``j - 6 .. j + 5``, the bilinear taps lie within ``p +- s``.
    Clamped borders read inside the same window. So a sample whose window of G_0 is constant
    is exactly 0."""
    return 9 * np.left_shift(1, np.asarray(level) - 1) - 2


#: Level of the blocks the skipping's flatness tests work on (EngineOptions.skip): the 8 x 8
#: blocks of the min/max pyramid's level 3 (section 4.2).
FLAT_BLOCK_LEVEL = 3


def constant_blocks(lo: np.ndarray, hi: np.ndarray, radius_blocks: int) -> np.ndarray:
    """Blocks of a block-extremes grid (:func:`block_extremes`) around which the image is one
    constant: the minimum of ``lo`` equals the maximum of ``hi`` over the ``(2 radius + 1)^2``
    blocks centred on each (clamped at the image's edges, as the image's own borders are),
    in every channel of (bh, bw, C) extremes (:func:`channel_block_extremes`)."""
    return constant_radius_blocks(lo, hi) >= int(radius_blocks)


def constant_radius_blocks(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The largest radius (in blocks) at which each block is :func:`constant_blocks`, int32:
    -1 where the block itself is not one constant, 2**30 where the whole image is (NaN is
    never constant).
    One pass answers every radius: the window of radius ``r >= 1`` around a block is one
    constant exactly when every block within ``r - 1`` of it has a constant 3 x 3 window
    (those windows overlap, so they share one value, and together they cover the larger
    window), i.e. when its chessboard distance to the nearest block whose 3 x 3 window is
    not constant is at least ``r``."""
    # channels first, each channel's rows contiguous (the kernel's loops vectorise)
    lo3 = lo[None] if lo.ndim == 2 else np.moveaxis(lo, -1, 0)
    hi3 = hi[None] if hi.ndim == 2 else np.moveaxis(hi, -1, 0)
    if lo3.shape[1] == 0 or lo3.shape[2] == 0:  # no block: the kernel's rows assume one
        return np.zeros(lo3.shape[1:], np.int32)
    return _constant_radius(np.ascontiguousarray(lo3), np.ascontiguousarray(hi3))


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _row_constant(l, u, x, xn):  # pragma: no cover - compiled
    """Whether block ``x`` of a row (``l``, ``u`` its minima and maxima) is one constant and
    block ``xn`` has that same constant."""
    v = l[x]
    return (u[x] == v) & (l[xn] == v) & (u[xn] == v)  # NaN: never equal


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _distance_from_row(cur, prev):  # pragma: no cover - compiled
    """``cur = min(cur, 1 + the least of prev's three blocks above or below each)``: a
    raster pass's step across rows (0 stays 0: distances are not negative)."""
    w = cur.shape[0]
    if w == 1:
        cur[0] = min(cur[0], prev[0] + 1)
        return
    cur[0] = min(cur[0], min(prev[0], prev[1]) + 1)
    cur[w - 1] = min(cur[w - 1], min(prev[w - 2], prev[w - 1]) + 1)
    c, pm, pc, pp = cur[1:], prev[0:], prev[1:], prev[2:]  # indexed from 0: it vectorises
    for x in range(w - 2):
        c[x] = min(c[x], min(min(pm[x], pc[x]), pp[x]) + 1)


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _distance_along_row(r, backward):  # pragma: no cover - compiled
    """A raster pass's step along a row: ``r[x] = min(r[x], r[x -+ 1] + 1)`` in the pass's
    order (forward, or ``backward``)."""
    w = r.shape[0]
    m = r[w - 1] if backward else r[0]
    for i in range(1, w):
        x = w - 1 - i if backward else i
        m = min(r[x], m + 1)
        r[x] = m


@numba.njit(cache=True, fastmath=FASTMATH, nogil=True)
def _constant_radius(lo, hi):  # pragma: no cover - compiled
    """:func:`constant_radius_blocks` of (C, bh, bw) extremes. Row by row, each loop over a
    row's blocks without a dependence between them (they vectorise), but the distance's
    step along the row: 1.2-1.8 -> ~0.3 ms for a 4K frame's 480 x 270 blocks."""
    nc, bh, bw = lo.shape
    far = np.int32(2**30)
    # the 3 x 3 window one constant in every channel: each block one constant (lo == hi), and
    # equal to its neighbours along the row (then along the column of those row windows)
    row = np.ones((bh, bw), dtype=np.bool_)
    for y in range(bh):
        ok = row[y]
        for ch in range(nc):
            l, u = lo[ch, y], hi[ch, y]
            if bw == 1:
                ok[0] &= u[0] == l[0]
                continue
            ok[0] &= _row_constant(l, u, 0, 1)
            ok[bw - 1] &= _row_constant(l, u, bw - 1, bw - 2)
            # interior blocks as slices indexed from 0: block x + 1 and its two neighbours
            lm, lc, lp, uc = l[0:], l[1:], l[2:], u[1:]
            um, up, okc = u[0:], u[2:], ok[1:]
            for x in range(bw - 2):
                v = lc[x]
                okc[x] &= ((uc[x] == v) & (lm[x] == v) & (um[x] == v)
                           & (lp[x] == v) & (up[x] == v))
    d = np.empty((bh, bw), dtype=np.int32)
    for y in range(bh):
        ok = row[y].copy()
        for yy in (y - 1, y + 1):
            if 0 <= yy < bh:
                other = row[yy]
                for x in range(bw):
                    ok[x] &= other[x]
                for ch in range(nc):
                    here, there = lo[ch, y], lo[ch, yy]
                    for x in range(bw):
                        ok[x] &= there[x] == here[x]
        dy = d[y]
        for x in range(bw):
            dy[x] = far if ok[x] else 0
    # chessboard distance to the nearest 0: two raster passes (exact for this metric), each
    # row first from the row before it in the pass (final by then), then along the row
    for y in range(bh):
        if y > 0:
            _distance_from_row(d[y], d[y - 1])
        _distance_along_row(d[y], False)
    for y in range(bh - 1, -1, -1):
        if y < bh - 1:
            _distance_from_row(d[y], d[y + 1])
        _distance_along_row(d[y], True)
    for y in range(bh):  # radius 0: the block alone
        dy = d[y]
        one = np.ones(bw, dtype=np.bool_)
        for ch in range(nc):
            l, u = lo[ch, y], hi[ch, y]
            for x in range(bw):
                one[x] &= l[x] == u[x]
        for x in range(bw):
            if dy[x] == 0:
                dy[x] = 0 if one[x] else -1
    return d


def blocks_reaching(radius_px: int | np.ndarray, block: int) -> int | np.ndarray:
    """Block radius (:func:`constant_blocks`) that covers ``radius_px`` (whole px)
    around every pixel of a block: ceil(radius / block), and one block more for the pixel's
    place in its block."""
    return -(-np.asarray(radius_px) // block) + 1


def laplacian_levels(gaussian: list[np.ndarray], levels: int) -> dict[int, np.ndarray]:
    """Laplacian bands ``{k: G_{k-1} - expand(G_k)}`` for ``k = 1..levels``
    (docs/METHOD.md, 3.2)."""
    out = {}
    for k in range(1, min(levels, len(gaussian) - 1) + 1):
        fine = gaussian[k - 1]
        out[k] = fine - expand(gaussian[k], fine.shape[:2])
    return out


@numba.njit(parallel=True, cache=True, fastmath=FASTMATH, nogil=True)
def _block_extremes(img, add, block, known, known_lo, known_hi):  # pragma: no cover
    """Extremes of ``img + add`` over every channel of each block, the rows streamed in order
    (a block row's rows one after the other: prefetched, where a block's own rows were a
    jump of a row each); RGB with its channel count a constant the compiler unrolls. The
    blocks ``known`` marks ((0, 0): none) are not read: their extremes are
    ``known_lo + 0.0`` and ``known_hi + 0.0``."""
    h, w, c = img.shape
    bh, bw = (h + block - 1) // block, (w + block - 1) // block
    lo = np.empty((bh, bw), dtype=img.dtype)
    hi = np.empty((bh, bw), dtype=img.dtype)
    some = known.shape[0] > 0
    none = np.zeros(0, np.bool_)
    # block rows spread over the threads: the known ones, often all in one part of the
    # frame, cost nothing
    stride = interleave(bh)
    for i in numba.prange(bh):
        by = (i * stride) % bh
        skip = known[by] if some else none
        if c == 3:
            _block_row_extremes(img, add, block, by, 3, skip, lo[by], hi[by])
        elif c == 1:  # luminance (the paper's rule)
            _block_row_extremes(img, add, block, by, 1, skip, lo[by], hi[by])
        else:
            _block_row_extremes(img, add, block, by, c, skip, lo[by], hi[by])
        if some:
            for bx in range(bw):
                if skip[bx]:
                    # + 0.0: the sum's zero (-0.0 + 0.0 is +0.0), as a block read would give
                    lo[by, bx] = known_lo[by, bx] + 0.0
                    hi[by, bx] = known_hi[by, bx] + 0.0
    return lo, hi


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _block_row_extremes(img, add, block, by, c, skip, lo, hi):  # pragma: no cover - compiled
    """:func:`_block_extremes` of block row ``by`` into ``lo`` and ``hi`` (bw,), but for the
    blocks ``skip`` marks (empty: none)."""
    h, w = img.shape[0], img.shape[1]
    bw = lo.shape[0]
    some = skip.shape[0] > 0
    ya, yb = by * block, min(by * block + block, h)
    for y in range(ya, yb):
        src, grey = img[y].reshape(-1), add[y]
        for bx in range(bw):
            if some and skip[bx]:
                continue
            xa, xb = bx * block, min(bx * block + block, w)
            mn = src[xa * c] + grey[xa] if y == ya else lo[bx]
            mx = mn if y == ya else hi[bx]
            for x in range(xa, xb):
                g = grey[x]
                for ch in range(c):
                    v = src[x * c + ch] + g
                    mn = min(mn, v)
                    mx = max(mx, v)
            lo[bx] = mn
            hi[bx] = mx


def block_extremes(
    image: np.ndarray, level: int, add: np.ndarray | None = None,
    known: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Level ``level`` of the min and max pyramids (paper section 4.2): the minimum and maximum
    of each ``2**level x 2**level`` block (over all channels of an (H, W, C) image), of
    ``image + add`` when a grey (H, W) ``add`` is given (added to every channel).

    The paper builds the level from 2 x 2 neighbourhoods level by level; the extreme of the
    block is the same number, computed here in one pass (edge blocks are the partial ones).
    ``known``: ``(mask, lo, hi)`` block grids: the blocks ``mask`` marks are not read, their
    extremes are ``lo`` and ``hi`` (plus 0.0): what the caller knows they are (the flat
    blocks the enhancer skips).
    """
    img = np.ascontiguousarray(image if image.ndim == 3 else image[..., None])
    if add is None:  # a zero image broadcast (no memory): a stride-0 view
        grey = np.broadcast_to(np.zeros(1, img.dtype).reshape(1, 1), img.shape[:2])
    else:
        grey = np.ascontiguousarray(add, dtype=img.dtype)
    block = level_scale(level)
    if known is None:
        mask, klo, khi = (np.zeros((0, 0), np.bool_),) + (np.zeros((0, 0), img.dtype),) * 2
    else:
        grid = (-(-img.shape[0] // block), -(-img.shape[1] // block))
        if any(np.shape(a) != grid for a in known):
            raise ValueError(f"known block grids must have shape {grid}")
        mask = np.ascontiguousarray(known[0], dtype=np.bool_)
        klo, khi = (np.ascontiguousarray(a, dtype=img.dtype) for a in known[1:])
    return _block_extremes(img, grey, block, mask, klo, khi)


@numba.njit(parallel=True, cache=True, fastmath=FASTMATH, nogil=True)
def _window_extremes_at(lo, hi, xs, ys, r):  # pragma: no cover - compiled
    # min and max are exact in any order: fast-math only lets the reductions vectorise
    h, w = lo.shape
    n = xs.shape[0]
    out_lo = np.empty(n, dtype=lo.dtype)
    out_hi = np.empty(n, dtype=hi.dtype)
    for i in numba.prange(n):
        x0 = min(max(int(math.ceil(xs[i] - r)), 0), w - 1)
        x1 = max(min(int(math.floor(xs[i] + r)), w - 1), x0)
        y0 = min(max(int(math.ceil(ys[i] - r)), 0), h - 1)
        y1 = max(min(int(math.floor(ys[i] + r)), h - 1), y0)
        mn = lo[y0, x0]
        mx = hi[y0, x0]
        for y in range(y0, y1 + 1):
            for x in range(x0, x1 + 1):
                mn = min(mn, lo[y, x])
                mx = max(mx, hi[y, x])
        out_lo[i] = mn
        out_hi[i] = mx
    return out_lo, out_hi


def window_extremes(
    lo: np.ndarray, hi: np.ndarray, radius_px: float, x_px: np.ndarray | None = None,
    y_px: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Exact neighbourhood extremes: the minimum of ``lo`` and the maximum of ``hi`` (H, W)
    over the pixels a square of half-side ``radius_px`` centred on each point covers, clipped
    to the image: at the points ``(x_px, y_px)``, or at every pixel (an (H, W) map; at an
    integer point the square covers ``2 floor(r) + 1`` pixels, a separable min/max filter).
    The exact counterpart of the min/max pyramid's blocks (section 4.2;
    ``EngineOptions.extremes``)."""
    if x_px is None:
        size = 2 * int(math.floor(radius_px)) + 1
        return (ndimage.minimum_filter(lo, size, mode="nearest"),
                ndimage.maximum_filter(hi, size, mode="nearest"))
    x = np.ascontiguousarray(x_px, dtype=np.float64).ravel()
    y = np.ascontiguousarray(y_px, dtype=np.float64).ravel()
    return _window_extremes_at(np.ascontiguousarray(lo), np.ascontiguousarray(hi), x, y,
                               float(radius_px))


@numba.njit(parallel=True, cache=True, fastmath=FASTMATH, nogil=True)
def _channel_block_extremes(img, block):  # pragma: no cover - compiled
    """Per block row: the extremes down its rows for every value of a row at once (whole
    rows of W C values, streamed in order), then along each block's columns per channel.
    Min and max are exact, so this order gives the same values as a block at a time, whose
    inner loops ran down a block's columns a value at a time at a stride of C (measured on
    a 4K RGB frame, one thread: 31 -> 19 ms)."""
    h, w, c = img.shape
    bh, bw = (h + block - 1) // block, (w + block - 1) // block
    n = w * c
    rows = img.reshape((h, n))
    lo = np.empty((bh, bw, c), dtype=img.dtype)
    hi = np.empty((bh, bw, c), dtype=img.dtype)
    for by in numba.prange(bh):
        ya, yb = by * block, min(by * block + block, h)
        col_lo = np.empty(n, dtype=img.dtype)
        col_hi = np.empty(n, dtype=img.dtype)
        first = rows[ya]
        for j in range(n):
            col_lo[j] = first[j]
            col_hi[j] = first[j]
        for y in range(ya + 1, yb):
            row = rows[y]
            for j in range(n):
                col_lo[j] = min(col_lo[j], row[j])
                col_hi[j] = max(col_hi[j], row[j])
        for bx in range(bw):
            xa, xb = bx * block, min(bx * block + block, w)
            for ch in range(c):
                mn = col_lo[xa * c + ch]
                mx = col_hi[xa * c + ch]
                for x in range(xa + 1, xb):
                    mn = min(mn, col_lo[x * c + ch])
                    mx = max(mx, col_hi[x * c + ch])
                lo[by, bx, ch] = mn
                hi[by, bx, ch] = mx
    return lo, hi


def channel_block_extremes(image: np.ndarray, level: int) -> tuple[np.ndarray, np.ndarray]:
    """Like :func:`block_extremes`, but per channel: the minimum and maximum of each channel
    of an (H, W, C) image over each ``2**level`` square block, (bh, bw, C) each."""
    return _channel_block_extremes(np.ascontiguousarray(image), level_scale(level))


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def bilinear_at(grid, x, y, scale):  # pragma: no cover - compiled
    """:func:`sample_bilinear` of one point, in float64 (compiled code's): its coordinates
    on the grid (full-resolution ones over ``scale``) clamped to its extent (borders held),
    then the two taps each way."""
    h, w = grid.shape
    fy = min(max(y / scale, 0.0), h - 1.0)
    fx = min(max(x / scale, 0.0), w - 1.0)
    iy = min(int(fy), max(h - 2, 0))
    ix = min(int(fx), max(w - 2, 0))
    ty, tx = fy - iy, fx - ix
    iy1, ix1 = min(iy + 1, h - 1), min(ix + 1, w - 1)
    top = (1.0 - tx) * np.float64(grid[iy, ix]) + tx * np.float64(grid[iy, ix1])
    bottom = (1.0 - tx) * np.float64(grid[iy1, ix]) + tx * np.float64(grid[iy1, ix1])
    return (1.0 - ty) * top + ty * bottom


@numba.njit(parallel=True, cache=True, fastmath=FASTMATH, nogil=True)
def _bilinear(grid, x, y, scale, out):  # pragma: no cover - compiled
    """:func:`sample_bilinear` (:func:`bilinear_at` of each point)."""
    for i in numba.prange(x.shape[0]):
        out[i] = bilinear_at(grid, x[i], y[i], scale)


def sample_bilinear(grid: np.ndarray, x_px: np.ndarray, y_px: np.ndarray, level: int) -> np.ndarray:
    """Bilinear sample of a level-``level`` grid at full-resolution coordinates (borders held),
    in the grid's dtype (what ``scipy.ndimage.map_coordinates(order=1, mode="nearest")``
    gives, to rounding; compiled, in parallel: the enhancer samples every impulse)."""
    x = np.ascontiguousarray(x_px, dtype=np.float64).ravel()
    y = np.ascontiguousarray(y_px, dtype=np.float64).ravel()
    out = np.empty(x.shape, dtype=grid.dtype)
    _bilinear(np.ascontiguousarray(grid), x, y, float(level_scale(level)), out)
    return out.reshape(np.shape(x_px))


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def block_shift(block):  # pragma: no cover - compiled
    """``log2(block)`` for a power-of-two ``block``, else -1 (:func:`nearest_cell`)."""
    if block & (block - 1) != 0:
        return -1
    shift = 0
    while (1 << shift) < block:
        shift += 1
    return shift


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def nearest_cell(v, block, shift, n):  # pragma: no cover - compiled
    """The cell of ``block`` px (``shift``: :func:`block_shift`) along one axis of ``n``
    cells that holds full-resolution coordinate ``v`` (:func:`sample_nearest`):
    ``int64(v + 0.5)`` truncates as NumPy's ``astype`` does, ``//`` floors as NumPy's (for a
    power-of-two block an arithmetic shift, which floors too, negative values included),
    then the clip to the grid."""
    i = np.int64(v + 0.5)
    i = i >> shift if shift >= 0 else i // block
    return min(max(i, 0), n - 1)


@numba.njit(cache=True, fastmath=FASTMATH, nogil=True)
def _nearest(grid, x, y, block, out):  # pragma: no cover - compiled
    """:func:`sample_nearest` of 1-D points (:func:`nearest_cell`)."""
    h, w = grid.shape
    shift = block_shift(block)
    for i in range(x.shape[0]):
        out[i] = grid[nearest_cell(y[i], block, shift, h), nearest_cell(x[i], block, shift, w)]


def sample_nearest(grid: np.ndarray, x_px: np.ndarray, y_px: np.ndarray, block: int) -> np.ndarray:
    """The value of the ``block`` x ``block`` cell that contains each full-resolution pixel
    (one compiled pass; 0.4 M points 6.5 -> 0.9 ms, NumPy's five passes and a gather before)."""
    shape, (x, y) = flat_broadcast(x_px, y_px)
    out = np.empty(x.shape, dtype=grid.dtype)
    _nearest(np.ascontiguousarray(grid), x, y, int(block), out)
    return out.reshape(shape)


#: Keys (1981) cubic-convolution parameter: a = -0.5 is MATLAB's imresize 'bicubic', with which
#: the release brings the level-3 gradients to full size (docs/METHOD.md, 5.5).
KEYS_A = -0.5


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _keys_weight(t):  # pragma: no cover - compiled
    """Keys' cubic-convolution kernel W(t), a = KEYS_A (interpolating: W(0) = 1, W(+-1) = 0)."""
    t = abs(t)
    a = KEYS_A
    if t <= 1.0:
        return ((a + 2.0) * t - (a + 3.0)) * t * t + 1.0
    if t < 2.0:
        return ((a * t - 5.0 * a) * t + 8.0 * a) * t - 4.0 * a
    return 0.0


@numba.njit(parallel=True, cache=True, fastmath=FASTMATH, nogil=True)
def _sample_cubic(ga, gb, u, v, out):  # pragma: no cover - compiled
    """:func:`sample_cubic` of two grids of one shape at the points ``(u, v)`` (grid
    coordinates) into ``out`` (2, points): a point's sixteen taps and their weights found
    once for both (a pass per grid found them for each, and each weight again for each tap:
    the gradients' pair at 0.4 M points, 7.5 -> 5.4 ms). The weights and columns are
    written out: a tuple indexed in a loop, or a stack of grids, went through memory."""
    h, w = ga.shape
    for i in numba.prange(u.shape[0]):
        iu = int(np.floor(u[i]))
        iv = int(np.floor(v[i]))
        fu = u[i] - iu
        fv = v[i] - iv
        w0, w1 = _keys_weight(fu + 1.0), _keys_weight(fu + 1.0 - 1)
        w2, w3 = _keys_weight(fu + 1.0 - 2), _keys_weight(fu + 1.0 - 3)
        x0, x1 = min(max(iu - 1, 0), w - 1), min(max(iu, 0), w - 1)
        x2, x3 = min(max(iu + 1, 0), w - 1), min(max(iu + 2, 0), w - 1)
        a = 0.0
        b = 0.0
        for j in range(4):
            wy = _keys_weight(fv + 1.0 - j)
            yy = min(max(iv - 1 + j, 0), h - 1)
            a += wy * w0 * ga[yy, x0]
            a += wy * w1 * ga[yy, x1]
            a += wy * w2 * ga[yy, x2]
            a += wy * w3 * ga[yy, x3]
            b += wy * w0 * gb[yy, x0]
            b += wy * w1 * gb[yy, x1]
            b += wy * w2 * gb[yy, x2]
            b += wy * w3 * gb[yy, x3]
        out[0, i] = a
        out[1, i] = b


def sample_cubic(grid: np.ndarray, x_px: np.ndarray, y_px: np.ndarray, level: int) -> np.ndarray:
    """Bicubic sample (Keys cubic convolution, a = -0.5, borders held) of a level-``level``
    grid at full-resolution coordinates: MATLAB's imresize 'bicubic' kernel (docs/METHOD.md, 5.5),
    evaluated only at the points asked for. Returns float64 of the points' shape; for a
    pair of grids (2, h, w), both grids' samples, (2, *the points' shape), from one pass."""
    s = float(level_scale(level))
    x = np.asarray(x_px, dtype=np.float64)
    y = np.asarray(y_px, dtype=np.float64)
    x, y = np.broadcast_arrays(x, y)
    grids = np.asarray(grid)
    pair = grids.ndim == 3
    if pair and grids.shape[0] != 2:
        raise ValueError(f"a grid (h, w) or a pair of grids (2, h, w), not {grids.shape}")
    ga, gb = (grids[0], grids[1]) if pair else (grids, grids)
    ga, gb = (np.ascontiguousarray(g if g.dtype == np.float64 else g.astype(np.float32))
              for g in (ga, gb))
    out = np.empty((2, x.size))
    _sample_cubic(ga, gb, x.ravel() / s, y.ravel() / s, out)
    return out.reshape((2,) + x.shape) if pair else out[0].reshape(x.shape)
