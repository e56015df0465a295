"""Colour: display transfer functions and luminance (paper section 4.5, docs/METHOD.md, 5.1, 5.4).

The method processes luminance only: the input is linearised with the display's transfer
function, the noise is computed from linear luminance and added to every channel of the linear
colour image (a change of BT.601 luma Y with Cb, Cr kept adds the same amount to R, G and B),
and the result is re-encoded.

References
----------
.. [tariq] Tariq, T., Tursun, C., Didyk, P. (2022). Noise-based Enhancement for Foveated
   Rendering. ACM Transactions on Graphics 41(4) (SIGGRAPH 2022). doi:10.1145/3528223.3530101
.. [bt601] ITU-R Recommendation BT.601, Studio encoding parameters of digital television (the
   luma weights 0.299, 0.587, 0.114)
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ._parallel import interleave, power
from .jit import FASTMATH, MAGIC_F64, _bits_as_float64, _float64_bits, fma, two_to_the
from .memory import WrittenRows, frame_empty
from .pyramids import channel_block_extremes, level_scale

#: BT.601 luma weights. The release's Y of YCbCr, normalised as (Y - 16/255) / (219/255), equals
#: 0.299 R + 0.587 G + 0.114 B (docs/METHOD.md, 5.4); its grey for orientation uses the same
#: weights rounded as MATLAB's rgb2gray (0.2989, 0.5870, 0.1140).
LUMA_BT601_F64 = np.array([0.299, 0.587, 0.114])
LUMA_BT601 = LUMA_BT601_F64.astype(np.float32)

#: The release's hybrid transfer (docs/METHOD.md, 5.1): ((v + 0.055) / 1.055) ** 2.2.
_RELEASE_OFFSET = 0.055


# ------------------------------------------------------------------ the transfer's power
# The power of the transfer function is a polynomial here, not libm's pow: NumPy's pow runs
# one value at a time (no vector pow without Intel's SVML), and the frame's two transfers
# were a quarter of its time. log2 from the float's exponent and an odd series in
# t = (m - 1) / (m + 1) of its mantissa m in [sqrt(1/2), sqrt(2)); exp2 of the fractional part
# in [-1/2, 1/2] by its Taylor series; in float64, so every float32 result is within one unit
# in the last place of pow's, and 99.9 % the same (tests/enhancer/test_colour.py). It
# vectorises (fovexp/jit.py's exact conversions).
_SQRT2 = math.sqrt(2.0)
_LN2 = math.log(2.0)
_LOG2E = 1.0 / _LN2
_MANTISSA = 0x000FFFFFFFFFFFFF
_EXPONENT_OF_ONE = 0x3FF0000000000000
#: e^x's Taylor coefficients 1 / k! from k = 8 down to 0 (the x^9 one starts Horner's rule).
_EXP_TAYLOR = tuple(1.0 / math.factorial(k) for k in range(8, -1, -1))


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _pow01(v, p):  # pragma: no cover - compiled
    """``v ** p`` for float64 ``v`` in [0, 1] and ``p`` > 0 (a display's gamma or its
    inverse), relative error below 1e-10: 0 at 0, exactly 1 at 1."""
    bits = _float64_bits(v)
    e = np.float64((bits >> 52) - 1023)
    m = _bits_as_float64((bits & _MANTISSA) | _EXPONENT_OF_ONE)  # in [1, 2)
    big = m > _SQRT2
    m = m * 0.5 if big else m
    e = e + 1.0 if big else e
    t = (m - 1.0) / (m + 1.0)  # |t| <= 0.172: ln m = 2 (t + t^3/3 + ...), to t^11
    t2 = t * t
    q = fma(t2, 1.0 / 11.0, 1.0 / 9.0)  # Horner's rule, each step one rounding (jit.fma)
    q = fma(t2, q, 1.0 / 7.0)
    q = fma(t2, q, 1.0 / 5.0)
    q = fma(t2, q, 1.0 / 3.0)
    ln_m = 2.0 * t * fma(t2, q, 1.0)
    y = p * fma(ln_m, _LOG2E, e)  # log2(v ** p)
    shifted = y + MAGIC_F64  # rounds y to the nearest integer n
    n = shifted - MAGIC_F64
    x = (y - n) * _LN2  # |x| <= ln(2) / 2: e^x to x^9
    poly = 1.0 / 362880.0
    for c in _EXP_TAYLOR:  # 1 / 8!, ..., 1 / 1!, 1 (unrolled: a tuple)
        poly = fma(x, poly, c)
    two_n = two_to_the(shifted)
    return poly * two_n if v > 0.0 else 0.0


#: :func:`_transfer_runs`' ``bits`` when no maximum is asked for.
_NO_BITS = np.zeros(0, np.uint32)
#: The largest float32 bit pattern of a value in [+0, 1]: 1.0's. -0.0 (0x80000000), the
#: negatives, infinities and NaNs are all above it as unsigned integers.
ONE_F32_BITS = 0x3F800000
#: Values per run of :func:`_transfer_runs`: 256 RGB pixels (long enough that the power's
#: loop keeps its vector speed).
_RUN = 768
#: The period a run is compared at: one RGB pixel (a grey image's equal values repeat too).
_PERIOD = 3
#: The largest code of a quantised input's table (:func:`code_table`): 16 bits. An 8-bit
#: file's k / 255 is 257 k / 65535, the same number, so one table serves both.
_TOP_CODE = int(np.iinfo(np.uint16).max)
#: :func:`_transfer_runs`' tables when there are none (the inverse transfer's).
_NO_TABLE = np.zeros(0, np.float32)


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _code(u):  # pragma: no cover - compiled
    """The index k of the code ``k / 65535`` nearest ``u`` (0 below 0, the top above 1 and
    for NaN, which max passes on and the comparison sends to the top): the table's entry to
    compare ``u`` with, always inside it. Unsigned: no negative index to wrap."""
    x = max(u * np.float32(_TOP_CODE), np.float32(0.0))
    return np.uint32((x if x <= np.float32(_TOP_CODE) else np.float32(_TOP_CODE))
                     + np.float32(0.5))


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _table_run(run_in, run_out, codes_in, codes_out):  # pragma: no cover - compiled
    """``run_out = codes_out[k]`` where ``run_in`` is ``codes_in[k]`` exactly, for a whole
    run; False (``run_out`` partly written) when any value is not a code. Three values are
    tried first, so that a frame of other numbers (a renderer's) pays three look-ups per
    run, not one per value."""
    m = run_in.shape[0]
    for i in (0, m // 2, m - 1):
        if codes_in[_code(run_in[i])] != run_in[i]:
            return False
    misses = 0
    for i in range(m):  # no early exit
        u = run_in[i]
        k = _code(u)
        misses += codes_in[k] != u
        run_out[i] = codes_out[k]
    return misses == 0


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _transfer_runs(src, dst, p, offset, inverse, bits, codes_in, codes_out):
    # pragma: no cover - compiled
    """``dst = T(src)`` of flat float32 runs: :func:`linearize`'s ``((v + offset) / (1 +
    offset)) ** p``, or with ``inverse`` :func:`encode`'s ``v ** p`` then the offset and a
    clip. A run of :data:`_RUN` values that repeats the :data:`_PERIOD` before it value for
    value (a flat region: grey, or one colour) copies their results, the same numbers (a
    value's result depends on the value alone); the others go through the power (it
    vectorises). A flat region then costs a comparison and a copy, not the power.

    ``bits``: ``src`` viewed as uint32, or empty; the largest of them is returned (0 when
    empty), taken run by run while the run is in the cache (:func:`linearize_checked`).

    ``codes_in``, ``codes_out``: :func:`code_table`'s (else empty): a run whose values are
    all codes ``k / 65535`` (an 8- or 16-bit file's) takes their results from it, the same
    numbers as the power's; any other run goes through the power."""
    n = src.shape[0]
    lo, hi = np.float32(0.0), np.float32(1.0)
    scale = np.float32(1.0 / (1.0 + offset))
    gain, off = np.float32(1.0 + offset), np.float32(offset)
    top = np.uint32(0)
    s = 0
    repeated = False  # whether the run before this one repeated its period
    while s < n:
        e = min(n, s + _RUN)
        if bits.shape[0] > 0:
            run_bits = bits[s:e]
            for i in range(e - s):  # an integer maximum: it vectorises
                top = max(top, run_bits[i])
        run_in, run_out = src[s:e], dst[s:e]  # indexed from 0: the loops vectorise
        if codes_in.shape[0] > 0 and _table_run(run_in, run_out, codes_in, codes_out):
            # codes: a look-up per value costs what a repeat's comparison and copy do
            repeated = False
            s = e
            continue
        repeats = s >= _PERIOD
        if repeats:
            now, before = src[s:e], src[s - _PERIOD:e - _PERIOD]
            for i in range(e - s):  # one pass, no early exit: it vectorises
                repeats &= now[i] == before[i]
        if repeats and repeated:
            # the run before repeated the same period (its last values are this run's), and
            # _RUN is a multiple of it: its results are this run's, copied as one run
            prev = dst[s - _RUN:e - _RUN]
            for i in range(e - s):
                run_out[i] = prev[i]
        elif repeats:
            p0, p1, p2 = dst[s - 3], dst[s - 2], dst[s - 1]
            for i in range(0, e - s - 2, 3):
                run_out[i], run_out[i + 1], run_out[i + 2] = p0, p1, p2
            for i in range((e - s) // 3 * 3, e - s):
                run_out[i] = run_out[i - 3]
        else:
            for i in range(e - s):
                u = run_in[i]
                if offset != 0.0 and not inverse:
                    u = np.float32(u + off) * scale
                v = np.float32(_pow01(np.float64(u), p))
                if offset != 0.0 and inverse:
                    v = min(max(v * gain - off, lo), hi)
                run_out[i] = v
        repeated = repeats
        s = e
    return top


@numba.njit(parallel=True, cache=True, fastmath=FASTMATH, nogil=True)
def _linearize_into(encoded, p, offset, out, bits, tops, codes_in, codes_out):
    # pragma: no cover - compiled
    """``out = ((encoded + offset) / (1 + offset)) ** p`` of flat float32 arrays (offset 0:
    the plain power), in float32 up to the power, as NumPy computed it; in parts in
    parallel, each in runs (:func:`_transfer_runs`; ``bits``, ``encoded`` as uint32 or
    empty: each part's largest into ``tops``, one per part; ``codes_in``, ``codes_out``:
    :func:`code_table`'s, or empty)."""
    n = encoded.size
    parts = tops.shape[0]  # no reductions: the thread count does not change a value
    # each thread's parts spread over the frame: a textured region costs the power, a flat
    # one a copy, and a thread given one half of a half-flat frame waited for the other
    stride = interleave(parts)
    for i in numba.prange(parts):
        k = (i * stride) % parts
        # slices indexed from 0 (an index of unknown sign keeps a loop scalar: fovexp/gabor.py)
        src = encoded[n * k // parts:n * (k + 1) // parts]
        dst = out[n * k // parts:n * (k + 1) // parts]
        part_bits = bits[n * k // parts:n * (k + 1) // parts] if bits.shape[0] > 0 else bits
        tops[k] = _transfer_runs(src, dst, p, offset, False, part_bits, codes_in, codes_out)
    return out


def linearize_checked(
    encoded: np.ndarray, gamma: float, transfer: str = "power",
) -> np.ndarray | None:
    """:func:`linearize` of a float32 array, in the pass that also tells whether every value
    is in [+0, 1] (finite, not NaN, not -0.0): the largest of the values' bit patterns as
    unsigned integers, :data:`ONE_F32_BITS` or less. The linear image when they are all
    there, else None: the caller's own check then says what is wrong (or accepts -0.0). An
    image check and the linearisation had read the frame twice."""
    out, top = _linearize_f32(np.ascontiguousarray(encoded, dtype=np.float32), gamma, transfer,
                              checked=True)
    return out if top <= ONE_F32_BITS else None


def _linearize_f32(src: np.ndarray, gamma: float, transfer: str,
                   checked: bool) -> tuple[np.ndarray, int]:
    """:func:`_linearize_into` of a C-contiguous float32 array: the linear array and, when
    ``checked``, the largest of the values' bit patterns (else 0)."""
    out = frame_empty(src.shape, np.float32)
    tops = np.zeros(_LINEAR_PARTS, np.uint32)
    flat = src.reshape(-1)
    p, offset = np.float64(np.float32(gamma)), _offset(transfer)
    _linearize_into(flat, p, offset, out.reshape(-1),
                    flat.view(np.uint32) if checked else _NO_BITS, tops, *code_table(p, offset))
    return out, int(tops.max())


_CODE_TABLES: dict[tuple[float, float], tuple[np.ndarray, np.ndarray]] = {}


def code_table(p: float, offset: float) -> tuple[np.ndarray, np.ndarray]:
    """The linearisation of every code ``k / 65535`` (k = 0 .. 65535, float32, divided by
    the function :func:`fovexp.io.read_image` divides a 16-bit file's samples with; an
    8-bit file's ``k / 255`` are among them): ``(codes, linear)``, each float32 (65536,), ``linear``
    computed by the power itself (:func:`_transfer_runs`), so a value looked up in it is
    the number the power gives. Made once per power and offset (512 KB; an 8-bit frame
    reads 256 entries of each). A frame read from an image file is codes only, and its
    linearisation then costs a look-up per value, not the power."""
    key = (float(p), float(offset))
    table = _CODE_TABLES.get(key)
    if table is None:
        from .io import _to_unit_float  # the reader's own division: the codes it gives

        codes = _to_unit_float(np.arange(_TOP_CODE + 1, dtype=np.uint16))
        linear = np.empty_like(codes)
        _linearize_into(codes, np.float64(p), offset, linear, _NO_BITS,
                        np.zeros(1, np.uint32), _NO_TABLE, _NO_TABLE)
        table = _CODE_TABLES.setdefault(key, (codes, linear))
    return table


def _offset(transfer: str) -> float:
    return _RELEASE_OFFSET if transfer == "release" else 0.0


#: The parts :func:`_linearize_into` splits a frame into (a constant: the thread count does
#: not change a value).
_LINEAR_PARTS = 64


def linearize(
    encoded: np.ndarray, gamma: float, transfer: str = "power", dtype: type = np.float32
) -> np.ndarray:
    """Display-encoded values in [0, 1] to linear light in [0, 1] (float32, or ``dtype``).

    ``power``: ``v ** gamma`` (the display profile's gamma). ``release``: the release's
    ``((v + 0.055) / 1.055) ** 2.2`` (docs/METHOD.md, 5.1). Float32 through the polynomial
    power (within one unit in the last place of pow's); float64 through NumPy's pow.
    """
    scalar = np.dtype(dtype).type
    src = np.ascontiguousarray(encoded, dtype=dtype)
    if scalar is np.float32:
        return _linearize_f32(src, gamma, transfer, checked=False)[0]
    if transfer != "release":  # straight from the input: no copy
        return power(src, scalar(gamma))
    out = np.array(src, dtype=dtype)  # a copy: worked on in place below
    out += scalar(_RELEASE_OFFSET)
    out *= scalar(1.0 / (1.0 + _RELEASE_OFFSET))
    return power(out, scalar(gamma), out)


#: Pixels per run of :func:`_encode_kept`: a run whose change is 0 throughout copies the input
#: (256 RGB pixels, :data:`_RUN` values).
_RUN_PX = _RUN // _PERIOD


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _add_clip_power(lin, g, c, p, offset, clipped, out):  # pragma: no cover - compiled
    """``out = T^-1(clip(lin + g, 0, 1))`` of a run of pixels (``c`` channels interleaved,
    ``g`` their grey change, ``clipped`` scratch of ``lin``'s size): the add and the clip,
    then the power in runs (:func:`_transfer_runs`)."""
    lo, hi = np.float32(0.0), np.float32(1.0)
    for x in range(g.shape[0]):
        for ch in range(c):
            clipped[x * c + ch] = min(max(lin[x * c + ch] + g[x], lo), hi)
    _transfer_runs(clipped, out, p, offset, True, _NO_BITS, _NO_TABLE, _NO_TABLE)


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _encode_kept(src, g, kept, w, c, p, offset, clipped, row):  # pragma: no cover - compiled
    """One row of :func:`_encode_into` with ``kept``: ``row = T^-1(clip(src + g))`` (``g`` the
    row's grey change, ``clipped`` scratch of the row's size) except where ``g`` of a pixel
    is exactly 0: there the pixel is ``kept``'s (the encoded input ``src`` is the
    linearisation of). A run of :data:`_RUN_PX` pixels without a change is one copy: no
    add, clip or power, and ``src`` not read."""
    s = 0
    while s < w:
        e = min(w, s + _RUN_PX)
        # indexed from 0: the loops vectorise
        gs, ks, out = g[s:e], kept[s * c:e * c], row[s * c:e * c]
        changed = 0
        for x in range(e - s):  # no early exit: it vectorises
            changed += gs[x] != 0.0
        if changed:
            _add_clip_power(src[s * c:e * c], gs, c, p, offset, clipped[s * c:e * c], out)
            if changed < e - s:  # some pixels unchanged (the pixel loop branches on each)
                for x in range(e - s):
                    if gs[x] == 0.0:
                        for ch in range(c):
                            out[x * c + ch] = ks[x * c + ch]
        else:
            for i in range((e - s) * c):
                out[i] = ks[i]
        s = e


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _encode_runs(src, g, w, c, p, offset, clipped, row):  # pragma: no cover - compiled
    """One row of :func:`_encode_into` without ``kept``: ``row = T^-1(clip(src + g))`` (``g``
    the row's grey change, ``clipped`` scratch of the row's size), in runs of
    :data:`_RUN_PX` pixels. A run whose change is exactly 0, as is the pixel's before it, and
    whose pixels repeat that pixel value for value (a flat region the enhancement left as it
    was) has that pixel's results: a copy, not the add, the clip and the power's run (the
    same numbers: a pixel's result depends on its values alone, and ``v + 0`` differs from
    ``v`` only at 0, which the power sends to 0 either way). Any other run is added, clipped
    and raised to the power in runs (:func:`_transfer_runs`)."""
    s = 0
    while s < w:
        e = min(w, s + _RUN_PX)
        # indexed from 0: the loops vectorise
        gs, lin, out = g[s:e], src[s * c:e * c], row[s * c:e * c]
        changed = 0
        for x in range(e - s):  # no early exit: it vectorises
            changed += gs[x] != 0.0
        if changed == 0 and s > 0 and g[s - 1] == 0.0:
            before = src[s * c - c:e * c - c]
            differ = 0
            for i in range((e - s) * c):
                differ += lin[i] != before[i]
            if differ == 0:
                if c == 3:  # the pixel before's results in registers: strided stores
                    p0, p1, p2 = row[s * 3 - 3], row[s * 3 - 2], row[s * 3 - 1]
                    for x in range(e - s):
                        out[3 * x], out[3 * x + 1], out[3 * x + 2] = p0, p1, p2
                else:
                    for i in range((e - s) * c):
                        out[i] = row[s * c - c + i % c]
                s = e
                continue
        _add_clip_power(lin, gs, c, p, offset, clipped[s * c:e * c], out)
        s = e


@numba.njit(parallel=True, cache=True, fastmath=FASTMATH, nogil=True)
def _encode_into(img, a, b, n_grey, spans_a, spans_b, p, offset, kept, out):
    # pragma: no cover - compiled
    """:func:`encode` of float32 (H, W, C) ``img`` in one pass: clip(img + a + b, 0, 1) (the
    first ``n_grey`` of the grey (H, W) images ``a``, ``b`` added to every channel; each read
    on its row's span only, ``spans_a[y]``, ``spans_b[y]``, and 0 elsewhere), to the
    power ``p``, then the release's offset (``offset`` > 0) and a clip. Each row's grey change
    is summed into a row of its own first, then the row goes in runs: added, clipped and
    raised to the power (:func:`_transfer_runs`), or copied where it repeats a pixel the
    change left as it was (:func:`_encode_runs`). With ``kept`` of ``img``'s shape (the
    encoded image ``img`` was linearised from; shape (0, 0, 0): none), a pixel whose grey
    images add exactly 0 is ``kept``'s (:func:`_encode_kept`), and the columns before the
    first span's start and after the last span's end are ``kept``'s row copied, without a
    grey row or runs."""
    h, w, c = img.shape
    keep = kept.shape[0] > 0 and n_grey > 0
    stride = interleave(h)  # each thread's rows spread over the frame (:func:`_linearize_into`)
    for i in numba.prange(h):
        y = (i * stride) % h
        # the columns a grey image changes: [x0, x1), the smallest range holding both spans
        x0, x1 = w, 0
        if n_grey >= 1 and min(spans_a[y, 1], w) > max(spans_a[y, 0], 0):
            x0, x1 = max(spans_a[y, 0], 0), min(spans_a[y, 1], w)
        if n_grey == 2 and min(spans_b[y, 1], w) > max(spans_b[y, 0], 0):
            x0, x1 = min(x0, max(spans_b[y, 0], 0)), max(x1, min(spans_b[y, 1], w))
        if keep:
            # outside [x0, x1) nothing is added: the kept pixels, as rows of values (a flat
            # region's rows need no grey row and no runs: a constant 4K frame 10.5 -> 7.5 ms)
            ky, oy = kept[y].reshape(-1), out[y].reshape(-1)
            xa = min(x0, x1)
            head, head_out = ky[0:xa * c], oy[0:xa * c]
            for k in range(xa * c):
                head_out[k] = head[k]
            xb = max(x1, xa)
            tail, tail_out = ky[xb * c:], oy[xb * c:]
            for k in range((w - xb) * c):
                tail_out[k] = tail[k]
            if x1 <= x0:
                continue
        else:
            x0, x1 = 0, w
        clipped = np.empty((x1 - x0) * c, np.float32)
        # the row's grey change on [x0, x1): a + b where both are written, either where one
        # is, 0 where neither (a + 0 is a, but for -0.0, which the power and the kept pixels
        # treat as 0)
        g = np.empty(x1 - x0, np.float32)
        for x in range(x1 - x0):
            g[x] = 0.0
        if n_grey >= 1:
            xa, xb = max(spans_a[y, 0], x0), min(spans_a[y, 1], x1)
            if xb > xa:
                ga, ay = g[xa - x0:xb - x0], a[y, xa:xb]  # indexed from 0: the loops vectorise
                for x in range(xb - xa):
                    ga[x] = ay[x]
        if n_grey == 2:
            xa, xb = max(spans_b[y, 0], x0), min(spans_b[y, 1], x1)
            if xb > xa:
                gb, by = g[xa - x0:xb - x0], b[y, xa:xb]
                for x in range(xb - xa):
                    gb[x] = gb[x] + by[x]
        src, dst = img[y].reshape(-1)[x0 * c:x1 * c], out[y].reshape(-1)[x0 * c:x1 * c]
        # RGB with its channel count a constant the compiler unrolls (measured: 4K encode
        # 114 -> 84 ms, 2 cores); any other as it comes
        if keep:
            ks = kept[y].reshape(-1)[x0 * c:x1 * c]
            if c == 3:
                _encode_kept(src, g, ks, x1 - x0, 3, p, offset, clipped, dst)
            else:
                _encode_kept(src, g, ks, x1 - x0, c, p, offset, clipped, dst)
        elif c == 3:
            _encode_runs(src, g, w, 3, p, offset, clipped, dst)
        else:
            _encode_runs(src, g, w, c, p, offset, clipped, dst)
    return out


@numba.njit(parallel=True, cache=True, fastmath=FASTMATH, nogil=True)
def _add_grey_clip(img, a, b, out):  # pragma: no cover - compiled
    """out = clip(img + a + b, 0, 1), a and b grey (H, W) added to every channel."""
    h, w, c = img.shape
    for y in numba.prange(h):
        for x in range(w):
            g = a[y, x] + b[y, x]
            for ch in range(c):
                out[y, x, ch] = min(max(img[y, x, ch] + g, np.float32(0.0)), np.float32(1.0))


def encode(
    linear: np.ndarray, gamma: float, transfer: str = "power", *grey: np.ndarray | WrittenRows,
    unchanged: np.ndarray | None = None,
) -> np.ndarray:
    """Inverse of :func:`linearize`, after adding up to two grey (H, W) images (the contrast
    change, the noise) to every channel; values outside [0, 1] are clipped first (a display
    shows nothing else). Float32 in one pass (the add, the clip and the polynomial power of
    :func:`linearize`); float64 when ``linear`` is, through NumPy's pow. A grey image given as
    a :class:`fovexp.memory.WrittenRows` is read on its rows' spans only (0 elsewhere).

    ``unchanged``: the display-encoded image ``linear`` is the linearisation of (``linear``'s
    shape). Where the grey images add exactly 0 that pixel is returned as it
    was, not through the round trip (which gives it back within one float32 unit in the
    last place): the fovea and the flat regions of an already-foveated frame are left
    exactly as rendered, and a run of such pixels costs a copy, not the power."""
    lin = np.asarray(linear)
    if lin.dtype != np.float64:
        lin = lin.astype(np.float32, copy=False)
    dtype = lin.dtype
    scalar = dtype.type
    if len(grey) > 2:
        raise ValueError("encode adds at most two grey images")
    if dtype != np.float32:
        grey = tuple(g.full() if isinstance(g, WrittenRows) else g for g in grey)
    if unchanged is not None:
        unchanged = np.asarray(unchanged)
        if unchanged.shape != lin.shape:
            raise ValueError(f"unchanged has shape {unchanged.shape}, linear {lin.shape}")
        if not grey:  # nothing added anywhere: the encoded image itself
            return np.array(unchanged, dtype=dtype)
    out = frame_empty(lin.shape, dtype)
    three = lin.ndim == 3
    if dtype == np.float32:
        # contiguous: on strided views the compiled loops measured 7x slower than a copy
        # as (H, W, C): grey (H, W) with one channel, any other shape as one row
        hwc = lin.shape if three else lin.shape + (1,) if lin.ndim == 2 else (1, lin.size, 1)
        whole = np.empty((hwc[0], 2), np.int64)
        whole[:, 0], whole[:, 1] = 0, hwc[1]
        ga, spans = [], []
        for g in grey:
            if isinstance(g, WrittenRows):
                ga.append(np.ascontiguousarray(g.values, dtype=dtype).reshape(hwc[:2]))
                spans.append(np.ascontiguousarray(g.spans, np.int64))
            else:
                ga.append(np.ascontiguousarray(g, dtype=dtype).reshape(hwc[:2]))
                spans.append(whole)
        zero = np.zeros((1, 1), dtype)
        a, b = (ga + [zero, zero])[:2]
        sa, sb = (spans + [whole, whole])[:2]
        kept = (np.zeros((0, 0, 0), dtype) if unchanged is None
                else np.ascontiguousarray(unchanged, dtype=dtype).reshape(hwc))
        _encode_into(np.ascontiguousarray(lin).reshape(hwc), a, b, len(ga), sa, sb,
                     np.float64(np.float32(1.0 / gamma)),
                     _RELEASE_OFFSET if transfer == "release" else 0.0, kept, out.reshape(hwc))
        return out
    if grey:
        a = np.ascontiguousarray(grey[0], dtype=dtype)
        b = (np.ascontiguousarray(grey[1], dtype=dtype) if len(grey) == 2
             else np.zeros(a.shape, dtype))
        _add_grey_clip(np.ascontiguousarray(lin if three else lin[..., None]), a, b,
                       out if three else out[..., None])
    else:
        np.clip(lin, 0.0, 1.0, out=out)
    power(out, scalar(1.0 / gamma), out)
    if transfer == "release":
        out *= scalar(1.0 + _RELEASE_OFFSET)
        out -= scalar(_RELEASE_OFFSET)
        np.clip(out, 0.0, 1.0, out=out)
    if unchanged is not None:
        added = sum(np.asarray(g, dtype) for g in grey)
        np.copyto(out, unchanged, where=(added == 0)[..., None] if three else added == 0)
    return out


@numba.njit(parallel=True, cache=True, fastmath=FASTMATH, nogil=True)
def _luma_into(rgb, weights, out):  # pragma: no cover - compiled
    """``out = (w0 R + w1 G) + w2 B`` of an (H, W, 3) image, in its dtype, row by row."""
    for y in numba.prange(out.shape[0]):
        _luma_row(rgb, weights, y, out)
    return out


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _luma_row(rgb, weights, y, out):  # pragma: no cover - compiled
    """Row ``y`` of :func:`luminance`: ``(w0 R + w1 G) + w2 B``, in the image's dtype."""
    w0, w1, w2 = weights[0], weights[1], weights[2]
    src, dst = rgb[y].reshape(-1), out[y]  # indexed from 0: the loop vectorises
    for x in range(dst.shape[0]):
        dst[x] = (w0 * src[3 * x] + w1 * src[3 * x + 1]) + w2 * src[3 * x + 2]


@numba.njit(parallel=True, cache=True, fastmath=FASTMATH, nogil=True)
def _luma_blocks_into(rgb, weights, block, out, lo, hi, encoded, p, offset, bits, tops,
                      codes_in, codes_out):  # pragma: no cover - compiled
    """:func:`_luma_into` block row by block row, with each ``block`` square's extremes of
    the luminance taken as its rows are written (down the block row's columns, then along
    each block, as :func:`fovexp.pyramids.channel_block_extremes` takes them: min and max
    are exact, the same numbers), not in a second pass over the frame. With ``encoded``
    (shape (H, W * 3); else empty), each block row of ``rgb`` is first its linearisation
    (:func:`_linearize_into`'s numbers) and ``tops[by]`` the largest of the block row's
    ``bits`` (``encoded`` as uint32): the rows are read once for the three."""
    h, w = out.shape
    bh, bw = lo.shape
    linearise = encoded.shape[0] > 0
    # block rows spread over the threads (:func:`_linearize_into`): a flat block row's runs
    # cost a comparison and a copy, a textured one the power; in order, the thread given the
    # top half of a frame textured at the top waited for the other (a three-quarters-flat 4K
    # frame: 22.8 -> 20.0 ms, its linearisation and luminance pass)
    stride = interleave(bh)
    for i in numba.prange(bh):
        by = (i * stride) % bh
        ya, yb = by * block, min(by * block + block, h)
        col_lo = np.empty(w, dtype=out.dtype)
        col_hi = np.empty(w, dtype=out.dtype)
        top = np.uint32(0)
        if linearise:
            # the block row's rows as one run of values: a row's first values repeat the
            # last of the row above where the frame is flat (a run per row cost the power
            # of every row's first 256 pixels: a constant 4K frame 16.5 -> 14.5 ms)
            n = (yb - ya) * encoded.shape[1]
            top = _transfer_runs(encoded[ya:yb].reshape(n), rgb[ya:yb].reshape(n), p, offset,
                                 False, bits[ya:yb].reshape(n), codes_in, codes_out)
        for y in range(ya, yb):
            _luma_row(rgb, weights, y, out)
            dst = out[y]
            if y == ya:
                for x in range(w):
                    col_lo[x] = dst[x]
                    col_hi[x] = dst[x]
            else:
                for x in range(w):
                    col_lo[x] = min(col_lo[x], dst[x])
                    col_hi[x] = max(col_hi[x], dst[x])
        for bx in range(bw):
            xa, xb = bx * block, min(bx * block + block, w)
            mn, mx = col_lo[xa], col_hi[xa]
            for x in range(xa + 1, xb):
                mn = min(mn, col_lo[x])
                mx = max(mx, col_hi[x])
            lo[by, bx] = mn
            hi[by, bx] = mx
        if linearise:
            tops[by] = top


def luminance_and_block_extremes(
    linear: np.ndarray, level: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`luminance` of an image and the minimum and maximum of it over each
    ``2**level`` px square block ((bh, bw) each: :func:`fovexp.pyramids.channel_block_extremes`
    of the luminance). Of a float32 (H, W, 3) image in one pass, the same numbers as the two
    apart without reading the luminance back (the enhancer's skipping takes where the
    luminance is flat from them); of another image through the two apart."""
    rgb = np.asarray(linear)
    if rgb.dtype != np.float32 or rgb.ndim != 3 or rgb.shape[2] != 3:
        luma = luminance(linear)
        lo, hi = channel_block_extremes(luma[..., None], level)
        return luma, lo[..., 0], hi[..., 0]
    luma, lo, hi, _ = _luma_blocks(np.ascontiguousarray(rgb), level)
    return luma, lo, hi


def _luma_blocks(
    rgb: np.ndarray, level: int, encoded: np.ndarray | None = None, gamma: float = 0.0,
    transfer: str = "power",
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """:func:`_luma_blocks_into` of a C-contiguous float32 (H, W, 3) ``rgb``: the luminance,
    its ``2**level`` px block extremes and, with ``encoded`` (written into ``rgb`` first, its
    linearisation), the largest of its values' bit patterns (else 0)."""
    h, w = rgb.shape[:2]
    block = level_scale(level)
    grid = (-(-h // block), -(-w // block))
    luma = frame_empty((h, w), np.float32)
    lo, hi = np.empty(grid, np.float32), np.empty(grid, np.float32)
    tops = np.zeros(grid[0], np.uint32)
    rows = (np.zeros((0, 0), np.float32) if encoded is None
            else encoded.reshape(h, w * 3))
    p, offset = np.float64(np.float32(gamma)), _offset(transfer)
    codes = code_table(p, offset) if encoded is not None else (_NO_TABLE, _NO_TABLE)
    _luma_blocks_into(rgb, LUMA_BT601, block, luma, lo, hi, rows, p, offset,
                      rows.view(np.uint32), tops, *codes)
    return luma, lo, hi, int(tops.max()) if tops.size else 0


def linearize_luminance_checked(
    encoded: np.ndarray, gamma: float, transfer: str, level: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """:func:`linearize_checked` of a float32 (H, W, 3) image and, in the same pass,
    :func:`luminance_and_block_extremes` of the result: ``(linear, luma, lo, hi)``, the same
    numbers as the three apart, when every value is in [+0, 1]; else None. An
    already-foveated frame's luminance is its linearisation's: each row is read once."""
    src = np.ascontiguousarray(encoded, dtype=np.float32)
    if src.ndim != 3 or src.shape[2] != 3:
        raise ValueError(f"an (H, W, 3) image, not {src.shape}")
    linear = frame_empty(src.shape, np.float32)
    luma, lo, hi, top = _luma_blocks(linear, level, src, gamma, transfer)
    return None if top > ONE_F32_BITS else (linear, luma, lo, hi)


def luminance(linear: np.ndarray) -> np.ndarray:
    """Linear luma ``0.299 R + 0.587 G + 0.114 B`` of an (H, W, 3) image; grey passes through.
    Float32, or float64 (with the weights in float64) when ``linear`` is.

    A compiled loop, not NumPy's ``tensordot``: that is a BLAS call, and OpenBLAS's threads
    spin for a while after one, taking a core from the parallel kernels that follow (measured
    on 2 cores: an already-foveated 4K frame 0.42 -> 0.29 s, the contrast stage after it
    118 -> 49 ms), with the bits ``tensordot`` gave on the frames compared."""
    dtype = np.float64 if np.asarray(linear).dtype == np.float64 else np.float32
    if linear.ndim == 2:
        return np.asarray(linear, dtype=dtype)
    if linear.ndim != 3 or linear.shape[2] != 3:
        raise ValueError(f"luminance of an (H, W, 3) image or a grey one, not {linear.shape}")
    weights = LUMA_BT601_F64 if dtype == np.float64 else LUMA_BT601
    rgb = np.ascontiguousarray(linear, dtype=dtype)
    return _luma_into(rgb, weights, frame_empty(rgb.shape[:2], dtype))
