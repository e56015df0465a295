"""Noise amplitude K from the Laplacian pyramid, and the clipping control (paper section 4.2).

The blur attenuates a frequency f by ``exp(-f^2 / (2 sigma_f^2))``, ``sigma_f = 1 / (2 pi
sigma)``. It falls to the attenuation cut-off ``a`` at (docs/METHOD.md, 3.1, erratum of eq. 7)::

    f_c = sigma_f sqrt(-2 ln a) = sqrt(-2 ln a) / (2 pi sigma)

The Laplacian level whose centre ``2**-(l + 0.5)`` (levels from 1, docs/METHOD.md, 3.2) equals f_c
is (eq. 8, corrected)::

    l_a = log2(1 / f_c) - 0.5,   at least 1

and (eq. 9) ``K = s_k |L_{l_a}|``, with a non-integer ``l_a`` interpolated linearly between the
two bracketing levels in the log-frequency domain (the level index is log2 of frequency). As in
the release (docs/METHOD.md, 5.7), ``|L_k|`` is smoothed by a 3 x 3 mean on its own grid, sampled
bilinearly, and K carries the release's gain 3.5722, so that ``s_k`` of Table 2 means the
same thing (the noise's local std is K / 6, see :mod:`fovexp.gabor`).

Clipping control (section 4.2): with local minimum ``N_min`` and maximum ``N_max`` of the image
the noise is added to, ``K`` is reduced so that ``N_max + K / 2 <= 1`` and
``N_min - K / 2 >= 0`` (K / 2 is three noise standard deviations), and never below 0. Where
``N_min`` and ``N_max`` are taken is a rule of its own (:data:`CLIPPING_RULES`,
:func:`clipping_extremes`; docs/METHOD.md, 6.6; measured side by side in
benchmarks/CLIPPING.md):

``"paper"``
    Section 4.2 as written: the level-3 min/max pyramids, one 8 x 8 block, of the luminance
    the method processes (section 4.5).
``"widened"``
    Every level-3 block the kernel reaches, over the colour channels.
``"release"``
    The release's 25 x 25 px box of grey (docs/METHOD.md, 5.8).
``"exact"``
    The true extremes over the channels of the pixels each impulse's kernel covers.
``"off"``
    No clipping control (the uncapped K of eq. 9): a reference, not a method.

References
----------
.. [tariq] Tariq, T., Tursun, C., Didyk, P. (2022). Noise-based Enhancement for Foveated
   Rendering. ACM Transactions on Graphics 41(4) (SIGGRAPH 2022). doi:10.1145/3528223.3530101
.. [burt] Burt, P. J., Adelson, E. H. (1983). The Laplacian Pyramid as a Compact Image Code.
   IEEE Transactions on Communications 31(4), 532-540. doi:10.1109/TCOM.1983.1095851
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal, get_args

import numba
import numpy as np
from scipy import ndimage

from .jit import FASTMATH, as_dtype_of, flat_broadcast
from .params import ClippingRule
from .pyramids import (
    abs_laplacian_reach_px,
    bilinear_at,
    block_extremes,
    block_shift,
    level_scale,
    nearest_cell,
    window_extremes,
)

#: Where the clipping control takes N_min and N_max (module docstring).
CLIPPING_RULES: tuple[str, ...] = get_args(ClippingRule)

#: The release's amplitude gain (docs/METHOD.md, 5.7); part of what Table 2's s_k means.
RELEASE_AMPLITUDE_GAIN = 3.5722


def attenuation_cutoff_cpp(sigma_px: np.ndarray, attenuation: float) -> np.ndarray:
    """Frequency (cycles/px) the blur attenuates to ``attenuation`` (eq. 7, corrected)."""
    sigma_px = np.asarray(sigma_px, dtype=np.float64)
    with np.errstate(divide="ignore"):
        return np.sqrt(-2.0 * np.log(attenuation)) / (2.0 * np.pi * sigma_px)


def band_centre_cpp(level: np.ndarray | float) -> np.ndarray:
    """Centre frequency of Laplacian level ``level`` (from 1): ``2**-(level + 0.5)`` (eq. 6;
    levels counted from 1, docs/METHOD.md, 3.2)."""
    return 2.0 ** -(np.asarray(level, dtype=np.float64) + 0.5)


def laplacian_level(sigma_px: np.ndarray, attenuation: float) -> np.ndarray:
    """Continuous level ``l_a`` whose centre the blur attenuates by ``attenuation`` (eq. 8),
    clamped to at least 1 (the finest band). Infinite sigma-free pixels get level 1."""
    f_c = attenuation_cutoff_cpp(sigma_px, attenuation)
    with np.errstate(divide="ignore"):
        level = np.log2(1.0 / f_c) - 0.5
    return np.maximum(np.nan_to_num(level, nan=1.0, neginf=1.0), 1.0)


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def bracket(level, top):  # pragma: no cover - compiled
    """:func:`bracketing_levels` of one level (compiled: a kernel's own loop calls it)."""
    lv = min(level, np.float64(top))
    k0 = min(np.int64(math.floor(lv)), top - 1) if top > 1 else np.int64(1)
    return k0, min(max(lv - k0, 0.0), 1.0)


@numba.njit(cache=True, fastmath=FASTMATH, nogil=True)
def _brackets(level, top, k0, t):  # pragma: no cover - compiled
    for i in range(level.shape[0]):
        k0[i], t[i] = bracket(level[i], top)


def bracketing_levels(level: np.ndarray, top: int) -> tuple[np.ndarray, np.ndarray]:
    """``(k0, t)``: the Laplacian levels ``k0`` and ``k0 + 1`` (at most ``top``, the coarsest
    built) between which continuous ``level`` lies, and its weight ``t`` on ``k0 + 1`` (eq. 9's
    interpolation in the log-frequency domain). Compiled (:func:`bracket`): the amplitude's
    pass (:func:`laplacian_amplitude_at`) takes each point's levels the same way."""
    shape, (flat,) = flat_broadcast(level)
    k0, t = np.empty(flat.shape, np.int64), np.empty(flat.shape)
    _brackets(flat, int(top), k0, t)
    return k0.reshape(shape), t.reshape(shape)


def laplacian_reach_px(k0: np.ndarray, top: int) -> np.ndarray:
    """How far (full-resolution px) the image reaches into :func:`laplacian_amplitude_at` at
    bracketing level ``k0``: the reach of its coarser level (:func:`fovexp.pyramids.
    abs_laplacian_reach_px`). Where the image is one constant that far, |L| is exactly 0."""
    return abs_laplacian_reach_px(np.minimum(np.asarray(k0) + 1, top))


@numba.njit(parallel=True, cache=True, fastmath=FASTMATH, nogil=True)
def _laplacian_at(grids, scales, top, level, x, y, out):  # pragma: no cover - compiled
    """:func:`laplacian_amplitude_at` of each point: ``grids[k - 1]`` is |L_k|, on the grid
    of ``scales[k - 1]`` full-resolution px per sample; ``top`` the coarsest built. Each
    sample is held in its grid's dtype before the interpolation, as
    :func:`fovexp.pyramids.sample_bilinear` returns it."""
    for i in numba.prange(x.shape[0]):
        k0, t = bracket(level[i], top)
        g0 = grids[k0 - 1]
        lo = as_dtype_of(g0, bilinear_at(g0, x[i], y[i], scales[k0 - 1]))
        hi = lo
        if k0 + 1 <= top:
            g1 = grids[k0]
            hi = as_dtype_of(g1, bilinear_at(g1, x[i], y[i], scales[k0]))
        out[i] = (1.0 - t) * np.float64(lo) + t * np.float64(hi)


def laplacian_amplitude_at(
    abs_levels: dict[int, np.ndarray], level: np.ndarray, x_px: np.ndarray, y_px: np.ndarray
) -> np.ndarray:
    """``|L|`` at continuous ``level`` (eq. 9, before ``s_k``), interpolated between the two
    bracketing levels, each sampled bilinearly at full-resolution coordinates (level k lives
    on G_{k-1}'s grid). ``abs_levels``: |L_k| for k = 1 .. its largest key, one dtype.

    One compiled pass over the points (:func:`_laplacian_at`), in parallel: each point's
    levels and samples, the numbers the grouping by level, two samplings per level and the
    interpolation in NumPy gave (0.4 M points at 4K, 64 impulses: 11.5-13.6 -> 5.9 ms)."""
    top = max(abs_levels)
    grids = [np.ascontiguousarray(abs_levels[k]) for k in range(1, top + 1)]
    # one tuple length (a kernel per length otherwise): the levels past the coarsest built
    # are never read
    grids += [grids[-1]] * (max(MAX_LAPLACIAN_LEVEL, top) - top)
    scales = np.array([level_scale(k - 1) for k in range(1, len(grids) + 1)], np.float64)
    shape, (x, y, lv) = flat_broadcast(x_px, y_px, level)
    out = np.empty(x.shape)
    _laplacian_at(tuple(grids), scales, int(top), lv, x, y, out)
    return out.reshape(shape)


#: Coarsest Laplacian level built: centre 2**-8.5 cycles/px, selected (a = 0.25) for sigmas up to
#: about 94 px, far past any foveation in the paper; coarser sigmas read this level.
MAX_LAPLACIAN_LEVEL = 8


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _limit_at(n_min, n_max, like):  # pragma: no cover - compiled
    """:func:`headroom_limit` of one point, in the dtype of the array ``like`` (float32
    arithmetic for float32 extremes, as NumPy's with its weak Python scalars); NaN passes
    through and ``-0.0`` stays, as with NumPy's minimum and maximum."""
    zero = as_dtype_of(like, 0.0)
    a = as_dtype_of(like, 1.0) - n_max
    m = a if (a <= n_min or a != a) else n_min
    v = as_dtype_of(like, 2.0) * m
    return v if (v >= zero or v != v) else zero


@numba.njit(cache=True, fastmath=FASTMATH, nogil=True)
def _limits(n_min, n_max, out):  # pragma: no cover - compiled
    for i in range(out.shape[0]):
        out[i] = _limit_at(n_min[i], n_max[i], out)


def headroom_limit(n_min: np.ndarray, n_max: np.ndarray) -> np.ndarray:
    """Largest K that keeps ``N_max + K/2 <= 1`` and ``N_min - K/2 >= 0``; never negative.
    In the extremes' common dtype (float32 for float32 extremes)."""
    dtype = np.result_type(np.asarray(n_min), np.asarray(n_max), np.float32)
    shape, (lo, hi) = flat_broadcast(n_min, n_max, dtype=dtype)
    out = np.empty(lo.shape, dtype)
    _limits(lo, hi, out)
    return out.reshape(shape)


@numba.njit(parallel=True, cache=True, fastmath=FASTMATH, nogil=True)
def _limit_in_cells(lo, hi, block, x, y, out):  # pragma: no cover - compiled
    """:func:`headroom_at` of points on cells of ``block`` px, in one pass: each point's
    float32 position clipped at 0, its cell (:func:`fovexp.pyramids.nearest_cell`), the
    limit there (:func:`_limit_at`), in parallel: NumPy's conversions, clips, two samplings
    and the limit's passes took 6 ms at 4K and 64 impulses (0.4 M points), this pass 1 ms."""
    h, w = lo.shape
    shift = block_shift(block)
    zero = np.float32(0.0)
    for i in numba.prange(out.shape[0]):
        xv, yv = np.float32(x[i]), np.float32(y[i])
        xv = xv if (xv >= zero or xv != xv) else zero  # np.clip(v, 0, None): np.maximum
        yv = yv if (yv >= zero or yv != yv) else zero
        iy = nearest_cell(np.float64(yv), block, shift, h)
        ix = nearest_cell(np.float64(xv), block, shift, w)
        out[i] = _limit_at(lo[iy, ix], hi[iy, ix], out)


@dataclass(frozen=True)
class Extremes:
    """N_min and N_max of a clipping rule, as :func:`headroom_at` reads them: on a grid of
    ``block`` x ``block`` px cells (``kind="blocks"``; 1: per pixel), per pixel to be reduced
    over each kernel's square (``kind="window"``), or none (``kind="off"``)."""

    kind: Literal["blocks", "window", "off"]
    lo: np.ndarray | None = None
    hi: np.ndarray | None = None
    block: int = 1


def clipping_extremes(
    rule: str, foveated: np.ndarray, luma: np.ndarray, delta: np.ndarray, *,
    kernel_radius_px: float, level: int = 3, box_px: int = 25,
    known: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> Extremes:
    """N_min and N_max under ``rule`` (section 4.2; module docstring) of the image the noise
    is added to: the linear ``foveated`` image (H, W) or (H, W, C) plus the grey contrast
    change ``delta`` (H, W), whose luminance is ``luma + delta`` (the luma weights sum to 1).
    ``level``: the min/max pyramids' level (the paper's third: 8 x 8 blocks);
    ``kernel_radius_px``: the Gabor kernel's reach (the widened rule's and the exact rule's
    neighbourhood); ``box_px``: the release's box. ``known``: for the paper's rule, the
    blocks of ``level`` whose extremes of ``luma + delta`` are known, and those extremes
    (:func:`fovexp.pyramids.block_extremes`); the other rules read every pixel."""
    if rule == "paper":
        lo, hi = block_extremes(luma, level, add=delta, known=known)
        return Extremes("blocks", lo, hi, level_scale(level))
    if rule == "widened":
        block = level_scale(level)
        reach = 2 * math.ceil(kernel_radius_px / block) + 1
        lo, hi = block_extremes(foveated, level, add=delta)
        return Extremes("blocks", ndimage.minimum_filter(lo, reach, mode="nearest"),
                        ndimage.maximum_filter(hi, reach, mode="nearest"), block)
    if rule == "release":
        grey = luma + delta
        return Extremes("blocks", ndimage.minimum_filter(grey, box_px, mode="nearest"),
                        ndimage.maximum_filter(grey, box_px, mode="nearest"), 1)
    if rule == "exact":
        lo, hi = block_extremes(foveated, 0, add=delta)
        return Extremes("window", lo, hi, 1)
    if rule == "off":
        return Extremes("off")
    raise ValueError(f"unknown clipping rule {rule!r} (choose from {', '.join(CLIPPING_RULES)})")


def headroom_at(
    ext: Extremes, kernel_radius_px: float, x_px: np.ndarray | None = None,
    y_px: np.ndarray | None = None, shape: tuple[int, int] | None = None,
) -> np.ndarray:
    """The clipping control's largest K (:func:`headroom_limit`) at the points
    ``(x_px, y_px)``, or, with ``shape`` instead, at every pixel of an (H, W) map; +inf
    everywhere under the rule ``"off"``."""
    if x_px is None:
        if shape is None:
            raise ValueError("headroom_at needs points or a shape")
        if ext.kind == "off":
            return np.full(shape, np.inf)
        if ext.kind == "window":  # every pixel's square: the separable filter
            return headroom_limit(*window_extremes(ext.lo, ext.hi, kernel_radius_px))
        yy, xx = np.mgrid[0:shape[0], 0:shape[1]].astype(np.float64)
        return headroom_at(ext, kernel_radius_px, xx.ravel(), yy.ravel()).reshape(shape)
    if ext.kind == "off":
        return np.full(np.shape(x_px), np.inf)
    if ext.kind == "window":
        return headroom_limit(*window_extremes(ext.lo, ext.hi, kernel_radius_px, x_px, y_px))
    # the cell an impulse reads is decided at its float32 position, as the GPU holds it (and
    # p + 0.5 is exact in float32 below 2**23): a position within a float32 step of a cell's
    # edge reads the same cell on both backends, where neighbouring cells' caps may differ
    dtype = np.result_type(ext.lo, ext.hi)
    lo, hi = (np.ascontiguousarray(e, dtype) for e in (ext.lo, ext.hi))
    shape, (x, y) = flat_broadcast(x_px, y_px)
    out = np.empty(x.shape, dtype)
    _limit_in_cells(lo, hi, int(ext.block), x, y, out)
    return out.reshape(shape)
