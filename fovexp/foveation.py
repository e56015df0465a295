"""Foveation: the spatially varying Gaussian blur that simulates foveated rendering.

Paper section 5.2: inside the fovea (8 deg) the image is full resolution; past it the standard
deviation of a Gaussian blur grows linearly with eccentricity at the *blur-rate* (arcmin of
sigma per degree of eccentricity)::

    sigma(e) = blur_rate * max(0, e - fovea)          [arcmin]

converted to pixels with the local pixels per degree (docs/METHOD.md, 4: blur-rate 0.34 at 40 deg
gives 10.9 arcmin, about 9 px on the paper's display).

:func:`foveate` is the fast method: a stack of Gaussian blurs at fixed sigmas, each computed on
the coarsest Gaussian-pyramid level that still resolves it (the residual blur there is at least
~1.9 level pixels, so the pyramid's aliasing is filtered away) and only over the region whose
sigmas need it; each pixel then interpolates linearly between the two stack levels that bracket
its sigma, sampling them bilinearly. :func:`foveate_exact` is the exact per-pixel spatially
varying convolution it is measured against (``benchmarks/run.py``; results in
``benchmarks/RESULTS.md``; and the tests).

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
from collections.abc import Callable
from dataclasses import dataclass

import numba
import numpy as np

from ._parallel import interleave
from .errors import FovexpError
from .geometry import ARCMIN_PER_DEG, ViewingGeometry, _angle_deg32, _ppd_at
from .jit import FASTMATH, flat_broadcast
from .memory import frame_empty
from .pyramids import (
    FLAT_BLOCK_LEVEL,
    blocks_reaching,
    channel_block_extremes,
    constant_blocks,
    gaussian_sigma_px,
    level_scale,
    packed_pyramid,
    wanted_columns,
)

#: The largest padded image (the frame with the blur stack's replicated border) the blur stack
#: may work on, past which the blur is far beyond any real display's (a 4K frame at the
#: largest blur-rate, gaze in a corner: sigma 370 px, pad 2048 px, 0.55 GiB in float32; an 8K
#: frame in float64 4.4 GiB). The border is read in place, never copied; the pyramid built on
#: it takes a third of this.
MAX_PADDED_BYTES = 8 * 2**30
#: Gaussians are truncated at 4 sigma, as scipy.ndimage.gaussian_filter does.
TRUNCATE_SIGMAS = 4.0


def sigma_px(
    ecc_deg: np.ndarray, ppd: np.ndarray, blur_rate: float, fovea_deg: float,
    dtype: type = np.float32,
) -> np.ndarray:
    """Blur std in pixels: ``blur_rate / 60 * max(0, e - fovea) * ppd`` (paper section 5.2).

    ``blur_rate`` is in arcmin per degree; ``ppd`` the local pixels per degree. With the
    release preset (fovea 12 deg, 42.67 px/deg) blur-rate 0.46875 gives the release's
    "6 px at 30 deg". Float32 (or ``dtype``): in float32, each step rounded as float32
    arithmetic rounds it (:func:`_sigma_at`).
    """
    # float32 maps stay float32 (no float64 copy): the formula converts each value exactly
    inputs = np.float32 if np.result_type(ecc_deg, ppd) == np.float32 else np.float64
    shape, (e, p) = flat_broadcast(ecc_deg, ppd, dtype=inputs)
    out = np.empty(e.shape)
    # + 0.0: a blur-rate of -0.0 is 0, and its map +0.0 (no blur), not -0.0
    _sigma_points(e, p, float(blur_rate) + 0.0, float(fovea_deg), np.dtype(dtype) == np.float32,
                  out)
    return out.reshape(shape).astype(dtype, copy=False)


@numba.njit(cache=True, inline="always", nogil=True, fastmath=FASTMATH)
def _round(v, single):  # pragma: no cover - compiled
    return np.float64(np.float32(v)) if single else v


_DEG_PER_ARCMIN = 1.0 / ARCMIN_PER_DEG


@numba.njit(cache=True, inline="always", nogil=True, fastmath=FASTMATH)
def _sigma_at(ecc, ppd, blur_rate, fovea, single):  # pragma: no cover - compiled
    """:func:`sigma_px` of one point, in float64. ``single``: the float32 result, each step
    (the inputs included) rounded to float32: a step computed in float64 and rounded is the
    float32 step's own result (double rounding is innocuous for +, -, *, / since
    53 >= 2 * 24 + 2), so the compiled per-block map and the map of float32 grids agree bit
    for bit."""
    e, fov = _round(ecc, single), _round(fovea, single)
    a = _round(e - fov, single)
    if a == a and a < 0.0:  # NaN stays NaN, as with np.maximum (and raises no warning)
        a = 0.0
    a = _round(a * _round(blur_rate, single), single)  # arcmin
    # in float32, a / 60 is a times float64(1 / 60), rounded: that product is within 2**-52
    # (relative) of the quotient, which is 2**-29 or more from every float32 rounding
    # boundary (a / 60 = m 2**e / 15 with m < 2**24 odd: never a midpoint, and never
    # nearer one than a fifteenth of 2**-24), so both round to the same float32; the
    # multiplication is the loop's one division less
    a = _round(a * _DEG_PER_ARCMIN if single else a / ARCMIN_PER_DEG, single)
    return _round(a * ppd, single)


@numba.njit(cache=True, nogil=True, fastmath=FASTMATH)
def _sigma_points(ecc, ppd, blur_rate, fovea, single, out):  # pragma: no cover - compiled
    """:func:`_sigma_at` of 1-D arrays of points (see :func:`fovexp.jit.flat_broadcast`)."""
    for i in range(out.shape[0]):
        out[i] = _sigma_at(ecc[i], ppd[i], blur_rate, fovea, single)


@numba.njit(cache=True, nogil=True, fastmath=FASTMATH, error_model="numpy")
def _exact_terms_row(ux, uy, vx, vy, d, pitch, x0, x1, ecc, ppd, ppd_row):  # pragma: no cover
    """The float32 eccentricity and ppd maps' values (eccentricity_and_ppd_maps) of the
    pixels [x0, x1) of the row at ``uy``, into ``ecc`` and ``ppd`` from index 0; the ppd
    read from ``ppd_row`` (the row of :meth:`~fovexp.geometry.ViewingGeometry.ppd_map`)
    when it is not empty. A loop of its own: it vectorises (geometry._atan2_upper), where
    the sigma formula's float32 steps kept the loop they shared scalar (measured 4x
    slower)."""
    cols = ux[x0:x1]  # indexed from 0: an index of unknown sign keeps a loop scalar
    if ppd_row.shape[0] > 0:
        kept = ppd_row[x0:x1]
        for i in range(cols.shape[0]):
            ecc[i] = _angle_deg32(cols[i], uy, vx, vy, d)
            ppd[i] = kept[i]
        return
    for i in range(cols.shape[0]):
        ecc[i] = _angle_deg32(cols[i], uy, vx, vy, d)
        ppd[i] = np.float32(_ppd_at(cols[i], uy, d, pitch))


@numba.njit(parallel=True, cache=True, nogil=True, fastmath=FASTMATH)
def _exact_sigma_blocks(
    ux, uy, vx, vy, d, pitch, blur_rate, fovea, need, shift, ppd_map, out
):  # pragma: no cover - compiled
    h, w = uy.shape[0], ux.shape[0]
    stride = interleave(h)  # the blocks needed may be all in one part of the frame
    nbx = need.shape[1]
    have_ppd = ppd_map.shape[0] > 0
    none = np.empty(0, np.float32)
    for i in numba.prange(h):
        y = (i * stride) % h
        by = y >> shift
        ecc = np.empty(w, np.float32)
        ppd = np.empty(w, np.float32)
        bx = 0
        while bx < nbx:  # runs of consecutive blocks needed
            if not need[by, bx]:
                bx += 1
                continue
            b0 = bx
            while bx < nbx and need[by, bx]:
                bx += 1
            x0, x1 = b0 << shift, min(bx << shift, w)
            _exact_terms_row(ux, uy[y], vx, vy, d, pitch, x0, x1, ecc, ppd,
                             ppd_map[y] if have_ppd else none)
            dst = out[y, x0:x1]
            for j in range(x1 - x0):  # (not i: the parallel loop's index)
                dst[j] = _sigma_at(ecc[j], ppd[j], blur_rate, fovea, True)


def sigma_on_blocks(
    geom: ViewingGeometry, gaze_px: tuple[float, float], blur_rate: float, fovea_deg: float,
    need: np.ndarray | None = None, shift: int = 0, out: np.ndarray | None = None,
    ppd_map: np.ndarray | None = None,
) -> np.ndarray:
    """The float32 sigma map of the ``exact`` geometry model: :func:`sigma_px` of
    :meth:`~fovexp.geometry.ViewingGeometry.eccentricity_and_ppd_maps`, bit for bit, in one
    parallel pass with no eccentricity map. ``need``: a boolean map of ``2**shift`` px
    square blocks; only the pixels of the blocks it marks are evaluated, and the others left
    as they are: 0, or what ``out`` (float32, the image's shape, written in place) holds.
    ``ppd_map``: :meth:`~fovexp.geometry.ViewingGeometry.ppd_map` of ``geom``, which does
    not depend on the gaze; read, not evaluated again (a third of the map's time: a square
    root and a division per pixel)."""
    if geom.model != "exact":
        raise ValueError("sigma_on_blocks evaluates the exact geometry model")
    if ppd_map is None:
        ppd_map = np.zeros((0, 0), np.float32)
    elif ppd_map.shape != geom.shape or ppd_map.dtype != np.float32:
        raise ValueError(f"ppd_map must be float32 of shape {geom.shape}")
    if need is None:
        need, shift = np.ones((1, 1), np.bool_), 62  # one block: the whole frame
    if out is None:  # every pixel written when every block is asked for (fresh zeros cost)
        out = (np.empty if need.all() else np.zeros)(geom.shape, np.float32)
    ux, uy, vx, vy, d, pitch = geom.exact_terms(gaze_px)
    _exact_sigma_blocks(ux, uy, vx, vy, d, pitch, float(blur_rate) + 0.0, float(fovea_deg),
                        np.ascontiguousarray(need, dtype=np.bool_), int(shift),
                        np.ascontiguousarray(ppd_map), out)
    return out


def sigma_bound_px(
    geom: ViewingGeometry, gaze_px: tuple[float, float], blur_rate: float, fovea_deg: float,
) -> float:
    """An upper bound of :func:`sigma_px` over the image without evaluating the map: sigma
    grows with eccentricity and ppd, each largest at a corner
    (:meth:`~fovexp.geometry.ViewingGeometry.max_eccentricity_and_ppd`). The margins cover
    the map's float32 arithmetic: eight float32 steps of the eccentricity (its float32
    angle is within five, :func:`fovexp.geometry._angle_deg32`; they matter where the
    largest eccentricity is just past the fovea: e - fovea is then a few steps), a
    relative 1e-4 for the products and 1e-3 px, which also cover a GPU's less exact
    trigonometry (its map is not read back). The blur stack and the contrast's boxes are
    sized by it (both backends), so that the map need not be evaluated where the image is
    flat; a bound a little high only makes them reach a little farther."""
    ecc, ppd = geom.max_eccentricity_and_ppd(gaze_px)
    ecc += 8.0 * float(np.spacing(np.float32(ecc)))
    bound = float(sigma_px(np.float64(ecc), np.float64(ppd), blur_rate, fovea_deg, np.float64))
    return bound * (1.0 + 1e-4) + 1e-3


#: Ratio of consecutive blur-stack sigmas past 1.5 px (the speed / error trade-off:
#: benchmarks/RESULTS.md measures 2**0.25 against 2**0.5 and 2**0.125).
STACK_RATIO = 2.0**0.25


def stack_sigmas_px(max_sigma_px: float, ratio: float = STACK_RATIO) -> np.ndarray:
    """The blur-stack sigmas: 0.25 px apart up to 1.5 px, then a constant ``ratio``.

    The linear interpolation between two Gaussians of std s1 < s2 differs from the Gaussian at
    s in between by about (s2 - s1)^2 / s^2 of the local contrast (second derivative in sigma);
    a constant ratio keeps that error the same at every scale. The spacing was chosen from the
    measured error (benchmarks/RESULTS.md).
    """
    levels = [0.0, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5]
    while levels[-1] < max_sigma_px:
        levels.append(levels[-1] * ratio)
    return np.array(levels, dtype=np.float64)


#: Residual blur (in level pixels) below which a stack level moves to a finer pyramid level.
MIN_RESIDUAL_LEVEL_PX = 1.25


def _pyramid_level_for(sigma: float, min_residual_px: float = MIN_RESIDUAL_LEVEL_PX) -> int:
    """Coarsest Gaussian level on which a blur of ``sigma`` (full-res px) is still well sampled:
    the blur left to do there is at least ``min_residual_px`` level pixels."""
    m = 0
    while math.sqrt(max(sigma**2 - gaussian_sigma_px(m + 1) ** 2, 0.0)) / level_scale(m + 1) >= (
        min_residual_px
    ):
        m += 1
    return m


def _float_array(a: np.ndarray) -> np.ndarray:
    """``a`` contiguous, float64 kept, any other type as float32 (the stages' two dtypes)."""
    a = np.ascontiguousarray(a)
    return a if a.dtype in (np.float32, np.float64) else a.astype(np.float32)


#: A sigma map asked for block by block: ``sigma_on_blocks(need, shift)`` gives an (H, W) map
#: that is the sigma map (px) on the ``2**shift`` px square blocks ``need`` marks (anything
#: elsewhere), for the filters that know where their result is not needed (flat regions).
SigmaOnBlocks = Callable[[np.ndarray, int], np.ndarray]


def per_pixel_sigma(
    linear: np.ndarray, sigma_map_px: np.ndarray | SigmaOnBlocks,
    run: Callable[..., np.ndarray], *args: object, max_sigma_px: float | None = None,
) -> np.ndarray:
    """Shared shell of the sigma-driven filters (foveation, contrast): run
    ``run(image (H, W, C), sigma, max_sigma, *args)`` (float32, or float64 kept) and give
    back the input's shape; an image with no sigma above 0 is returned as a copy, untouched.
    ``max_sigma`` is ``max_sigma_px`` when given (an upper bound of the map), else the map's
    maximum; ``sigma`` is the map, or a :data:`SigmaOnBlocks` (``max_sigma_px`` then
    required) that ``run`` calls."""
    grey = linear.ndim == 2
    img = _float_array(linear[..., None] if grey else linear)
    if callable(sigma_map_px):
        if max_sigma_px is None:
            raise ValueError("a sigma map asked for by blocks needs max_sigma_px")
        sigma = sigma_map_px
    else:
        sigma = _float_array(sigma_map_px)
    if max_sigma_px is not None:
        max_sigma = float(max_sigma_px)
    else:
        max_sigma = float(sigma.max()) if sigma.size else 0.0
    if max_sigma <= 0.0:
        return img[..., 0].copy() if grey else img.copy()
    out = run(img, sigma, max_sigma, *args)
    return out[..., 0] if grey else out


def gaussian_kernel(sigma: float, dtype: type = np.float32) -> np.ndarray:
    """Sampled, normalised 1-D Gaussian truncated at 4 sigma (scipy.ndimage's kernel); exactly
    symmetric (the blur adds its taps in pairs)."""
    r = int(TRUNCATE_SIGMAS * sigma + 0.5)
    d = np.arange(-r, r + 1, dtype=np.float64)
    g = np.exp(-0.5 * d * d / (sigma * sigma))
    return (g / g.sum()).astype(dtype)


# The blur and the accumulation are written as "centre + weighted differences" (the same
# filters, their weights summing to 1): a constant region then comes out exactly as its
# constant, so the flat regions foveate() skips are exactly those it would leave unchanged.
# Compiled with fast-math but no reassociation, which could rewrite the form away (the loops
# have no reductions: they vectorise without it).

#: Row elements the blur's passes work on at a time: a tap loop then runs over slices indexed
#: from 0 that stay in the L1 cache (whole rows of a wide run are up to 46 kB; measured on
#: 4K Sponza: the blur stack's bands 350 -> 250 ms, the same bits).
_STRIP = 1024


@numba.njit(cache=True, fastmath=FASTMATH, nogil=True)
def _blur_patch(src, ly0, ly1, lx0, lx1, g):  # pragma: no cover - compiled
    """Separable Gaussian of ``src`` (h, w, c) over rows [ly0, ly1), cols [lx0, lx1);
    samples outside ``src`` replicate its border. ``src``'s dtype (float32 or float64)."""
    h, w, c = src.shape
    r = g.shape[0] // 2
    ph, pw = ly1 - ly0, lx1 - lx0
    th, tw = ph + 2 * r, pw + 2 * r
    n = tw * c
    # the source block with its border replicated, contiguous, so both passes vectorise
    blk = np.empty((th, n), dtype=src.dtype)
    # columns inside src copied as one contiguous run per row, from slices indexed from 0 (an
    # index of unknown sign kept the copy scalar: measured on 4K Sponza, one thread, the
    # foveation 315 -> 279 ms with the border loops below), the replicated border columns
    # one by one
    xa, xb = min(max(r - lx0, 0), tw), max(min(w - lx0 + r, tw), 0)
    xa = min(xa, xb)
    for yy in range(th):
        sy = min(max(ly0 - r + yy, 0), h - 1)
        row = src[sy].reshape(-1)
        s0 = (lx0 - r + xa) * c
        dst, run = blk[yy, xa * c:xb * c], row[s0:s0 + (xb - xa) * c]  # indexed from 0
        for j in range((xb - xa) * c):
            dst[j] = run[j]
        for xx in range(xa):  # the replicated border columns, left then right
            sx = min(max(lx0 - r + xx, 0), w - 1)
            for ch in range(c):
                blk[yy, xx * c + ch] = src[sy, sx, ch]
        for xx in range(xb, tw):
            sx = min(max(lx0 - r + xx, 0), w - 1)
            for ch in range(c):
                blk[yy, xx * c + ch] = src[sy, sx, ch]
    # the kernel is symmetric: taps k and 2r - k in pairs, (a + b) - 2 centre (exactly 0 on a
    # constant: c + c = 2c)
    tmp = np.empty((ph, n), dtype=src.dtype)
    twice = np.empty(_STRIP, dtype=src.dtype)
    for yy in range(ph):
        for j0 in range(0, n, _STRIP):
            m = min(_STRIP, n - j0)
            t_row = tmp[yy, j0 : j0 + m]
            c_row = blk[yy + r, j0 : j0 + m]
            for j in range(m):
                t_row[j] = c_row[j]
                twice[j] = c_row[j] + c_row[j]
            for k in range(r):
                gk = g[k]
                a_row = blk[yy + k, j0 : j0 + m]
                b_row = blk[yy + 2 * r - k, j0 : j0 + m]
                for j in range(m):
                    t_row[j] += gk * ((a_row[j] + b_row[j]) - twice[j])
    out = np.empty((ph, pw * c), dtype=src.dtype)
    centre = r * c
    nn = pw * c
    for yy in range(ph):
        for j0 in range(0, nn, _STRIP):
            m = min(_STRIP, nn - j0)
            o_row = out[yy, j0 : j0 + m]
            c_row = tmp[yy, centre + j0 : centre + j0 + m]
            for j in range(m):
                o_row[j] = c_row[j]
                twice[j] = c_row[j] + c_row[j]
            for k in range(r):
                gk = g[k]
                a_row = tmp[yy, k * c + j0 : k * c + j0 + m]
                b_row = tmp[yy, (2 * r - k) * c + j0 : (2 * r - k) * c + j0 + m]
                for j in range(m):
                    o_row[j] += gk * ((a_row[j] + b_row[j]) - twice[j])
    return out


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _accumulate(img, patch, kk, tt, y0, y1, xa, xb, lv, off, sc, ly0, ly1, lx0, lx1, c, out):
    # pragma: no cover - compiled
    """Stack level ``lv``'s blurred ``patch`` (its level grid's rows [ly0, ly1), columns
    [lx0, lx1), channels interleaved), added into ``out`` at the pixels of rows [y0, y1)
    and columns [xa, xb] that bracket their sigma with it (``kk`` the lower level, ``tt``
    the weight of the upper): ``wgt (S - v)``, ``S`` the bilinear sample of the level,
    ``v`` the pixel's own value. ``S`` is interpolated along x once per patch row (rows of
    the run's full-resolution columns), then between two such rows per output row, each
    step as ``a + f (b - a)`` (a constant level gives exactly its constant: ``S - v`` is
    then 0). Every loop runs over slices indexed from 0 with the weight per value, the
    pixels outside the bracket selected, not branched around, so that the loops vectorise.
    Inlined: a constant ``c`` unrolls the channel loops."""
    npx = xb + 1 - xa
    m = npx * c
    wv = np.empty(m, img.dtype)  # the weight of each value of a row (0: not bracketed)
    inv_sc = 1.0 / sc  # a power of two: multiplying by it is the division, exactly
    if sc == 1:
        up = patch  # full resolution: the sample is the patch's own pixel
    else:
        # each column's tap and weight on the level grid, the same on every row
        ixs = np.empty(npx, np.int64)
        axs = np.empty(npx, img.dtype)
        pw = lx1 - lx0
        for i in range(npx):
            fx = (xa + i + off) * inv_sc - lx0
            ix = min(int(fx), pw - 2)
            ixs[i] = ix * c
            axs[i] = fx - ix
        # the patch's rows interpolated along x at the run's columns
        up = np.empty((ly1 - ly0, m), img.dtype)
        for ly in range(ly1 - ly0):
            p_row, u_row = patch[ly], up[ly]
            for i in range(npx):
                j, ax = ixs[i], axs[i]
                for ch in range(c):
                    lo = p_row[j + ch]
                    u_row[i * c + ch] = lo + ax * (p_row[j + c + ch] - lo)
    for y in range(y0, y1):
        k_row, t_row = kk[y - y0, xa : xb + 1], tt[y - y0, xa : xb + 1]
        hit = False
        for i in range(npx):
            k = k_row[i]
            t = t_row[i]
            wgt = (1.0 - t) if k == lv else (t if k == lv - 1 else 0.0)
            hit |= wgt != 0.0
            for ch in range(c):
                wv[i * c + ch] = wgt
        if not hit:
            continue
        o_row = out[y].reshape(-1)[xa * c : xa * c + m]
        v_row = img[y].reshape(-1)[xa * c : xa * c + m]
        if sc == 1:
            s_row = up[y - y0]
            for i in range(m):
                o = o_row[i]
                wi = wv[i]
                o_row[i] = o + wi * (s_row[i] - v_row[i]) if wi != 0.0 else o
        else:
            fy = (y + off) * inv_sc - ly0
            iy = min(int(fy), ly1 - ly0 - 2)
            ay = fy - iy
            u0, u1 = up[iy], up[iy + 1]
            for i in range(m):
                o = o_row[i]
                wi = wv[i]
                lo = u0[i]
                o_row[i] = o + wi * ((lo + ay * (u1[i] - lo)) - v_row[i]) if wi != 0.0 else o


#: :func:`_accumulate` called, not inlined, for channel counts other than 3 (grey): an inlined
#: second copy in :func:`_foveate_bands` cost seconds of every compilation.
_accumulate_any = numba.njit(cache=True, fastmath=FASTMATH, nogil=True)(_accumulate.py_func)


@numba.njit(parallel=True, cache=True, fastmath=FASTMATH, nogil=True)
def _foveate_bands(
    img, sigma, levels, lvl_m, kbuf, kmeta, pbuf, pmeta, pad, band_h, flat, shift, out
):  # pragma: no cover - compiled
    """Blur stack evaluated band by band: for each band of rows and each stack level, blur
    only the runs of columns whose sigmas need that level, then accumulate the per-pixel
    linear interpolation between the two levels bracketing each sigma, as the pixel's own
    value plus the weighted differences of the levels from it (the weights sum to 1; level
    0 is the pixel itself). Pixels whose ``2**shift`` square block ``flat`` marks (their
    neighbourhood is one constant) are left as they are: what the blur gives there. Written
    into ``out`` (img's shape: NumPy's allocation, :mod:`fovexp.jit`)."""
    h, w, c = img.shape
    n = levels.shape[0]
    nb = (h + band_h - 1) // band_h
    stride = interleave(nb)  # bands of the fovea or of flat regions cost little: spread them
    for i in numba.prange(nb):
        b = (i * stride) % nb
        y0 = b * band_h
        y1 = min(h, y0 + band_h)
        # bracket index and weight per pixel of the band
        kk = np.empty((y1 - y0, w), dtype=np.int64)
        tt = np.empty((y1 - y0, w), dtype=img.dtype)
        # per stack level, the columns where it has a non-zero weight (levels k and k + 1)
        needs = np.zeros((n, w), dtype=np.bool_)
        for y in range(y0, y1):
            # the row copied as one run (it vectorises), then each pixel's bracket
            src_row, out_row = img[y].reshape(w * c), out[y].reshape(w * c)
            for j in range(w * c):
                out_row[j] = src_row[j]
            s_row, k_row, t_row = sigma[y], kk[y - y0], tt[y - y0]
            flat_row = flat[y >> shift]
            k = 0  # the bracket found last: the sigma map is smooth along a row
            bx0 = 0
            while bx0 < w:  # block by block: a flat one is left as it is, its sigma not read
                bx1 = min(w, ((bx0 >> shift) + 1) << shift)
                if flat_row[bx0 >> shift]:
                    kf, tf = k_row[bx0:bx1], t_row[bx0:bx1]  # indexed from 0: they vectorise
                    for x in range(bx1 - bx0):
                        kf[x] = -1
                        tf[x] = 0.0
                    bx0 = bx1
                    continue
                for x in range(bx0, bx1):
                    s = s_row[x]
                    if s <= 0.0:
                        k_row[x] = -1
                        t_row[x] = 0.0
                        continue
                    # numpy.searchsorted(levels, s) - 1 (the levels below s, less one), walked
                    # to from the last pibx1l's instead of searched for: one or two comparisons
                    # (NaN sorts above every level there)
                    if s != s:
                        k = n - 1
                    while k + 1 < n and levels[k + 1] < s:
                        k += 1
                    while k >= 0 and levels[k] >= s:
                        k -= 1
                    kb = min(k, n - 2)
                    t = min((s - levels[kb]) / (levels[kb + 1] - levels[kb]), 1.0)
                    k_row[x] = kb
                    t_row[x] = t
                    needs[kb, x] = True
                    needs[kb + 1, x] = True
                bx0 = bx1
        for lv in range(1, n):
            need = needs[lv]
            if not need.any():
                continue
            m = lvl_m[lv]
            sc = 1 << m
            off = pad if m > 0 else 0
            if m == 0:
                src = img
            else:
                ps, ph_, pw_ = pmeta[m, 0], pmeta[m, 1], pmeta[m, 2]
                src = pbuf[ps : ps + ph_ * pw_ * c].reshape((ph_, pw_, c))
            g = kbuf[kmeta[lv, 0] : kmeta[lv, 0] + 2 * kmeta[lv, 1] + 1]
            gap = 2 * kmeta[lv, 1] * sc + 32
            x = 0
            while x < w:
                if not need[x]:
                    x += 1
                    continue
                xa = x
                xb = x
                while x < w and (need[x] or x - xb <= gap):
                    if need[x]:
                        xb = x
                    x += 1
                # level-grid patch covering rows [y0, y1) and cols [xa, xb] (+1 for bilinear)
                ly0 = (y0 + off) // sc
                ly1 = (y1 - 1 + off) // sc + 2
                lx0 = (xa + off) // sc
                lx1 = (xb + off) // sc + 2
                patch = _blur_patch(src, ly0, ly1, lx0, lx1, g)
                # RGB with its channel count a constant the compiler unrolls; any other as
                # it comes
                if c == 3:
                    _accumulate(img, patch, kk, tt, y0, y1, xa, xb, lv, off, sc, ly0, ly1,
                                lx0, lx1, 3, out)
                else:
                    _accumulate_any(img, patch, kk, tt, y0, y1, xa, xb, lv, off, sc, ly0, ly1,
                                    lx0, lx1, c, out)
    return out


#: Rows per band of the banded evaluation (a band's work fits in cache; bands run in parallel).
BAND_ROWS = 32


def foveate(
    linear: np.ndarray, sigma_map_px: np.ndarray | SigmaOnBlocks, ratio: float = STACK_RATIO,
    min_residual_px: float = MIN_RESIDUAL_LEVEL_PX, skip: bool = True,
    max_sigma_px: float | None = None,
) -> np.ndarray:
    """Spatially varying Gaussian blur of a linear image, ``sigma_map_px`` per pixel (fast).

    Works on (H, W) or (H, W, C) float32 (or float64) images; returns the same shape and
    dtype. Pixels with sigma 0 are returned unchanged (bit-exact), and so are pixels whose
    neighbourhood is one constant in every channel (the blur of a constant is that constant,
    exactly, in this arithmetic); with ``skip`` those are found from 8 x 8 block extremes and
    not computed (the result is the same bit for bit). ``ratio`` and ``min_residual_px``
    trade speed for accuracy; error against :func:`foveate_exact`: ``benchmarks/RESULTS.md``.

    The blur stack covers sigmas up to ``max_sigma_px`` (at least the map's maximum; by
    default that maximum). With it, ``sigma_map_px`` may be a :data:`SigmaOnBlocks`: the
    map is then asked for only on the blocks that are not flat (all of them without
    ``skip``).
    """
    return per_pixel_sigma(linear, sigma_map_px, _foveate, ratio, min_residual_px, skip,
                           max_sigma_px=max_sigma_px)


@dataclass(frozen=True)
class BlurStackPlan:
    """What the fast foveation computes for a given largest sigma (shared by the CPU and GPU
    backends): the stack sigmas, the Gaussian-pyramid level each is blurred on, the residual
    kernel there, and the replicated border the pyramid is built with."""

    sigmas_px: np.ndarray  # float64 (n,)
    pyramid_level: np.ndarray  # int64 (n,)
    kernels: tuple[np.ndarray, ...]  # float32 (or the dtype asked), one per stack level
    pad_px: int  # full-resolution border replicated before the pyramid (0 when top == 0)

    @property
    def top(self) -> int:
        return int(self.pyramid_level.max())

    def reach_px(self) -> int:
        """How far (full-resolution px) the input reaches into an output pixel, at most: on
        pyramid level m (scale s = 2**m) the reduces reach 2 (s - 1), the residual kernel
        r s and the bilinear taps s. Where the input is one constant that far, the output is
        that constant."""
        return max(level_scale(int(m)) * (g.size // 2 + 1) + 2 * (level_scale(int(m)) - 1)
                   for m, g in zip(self.pyramid_level, self.kernels, strict=True))


def blur_stack_plan(
    max_sigma_px: float, ratio: float = STACK_RATIO, min_residual_px: float = MIN_RESIDUAL_LEVEL_PX,
    dtype: type = np.float32,
) -> BlurStackPlan:
    """The blur stack for sigmas up to ``max_sigma_px`` (see the module docstring)."""
    levels = stack_sigmas_px(max_sigma_px, ratio)
    lvl_m = np.array([_pyramid_level_for(float(s), min_residual_px) for s in levels],
                     dtype=np.int64)
    top = int(lvl_m.max())
    # Replicate borders at full resolution (as the exact convolution does) by padding before
    # the pyramid; a multiple of 2**top keeps the level grids aligned with the image's.
    step = level_scale(top)
    pad = -(-int(TRUNCATE_SIGMAS * max_sigma_px + 2 * step) // step) * step if top else 0
    kernels = [np.ones(1, dtype)]
    for k in range(1, levels.size):
        m = int(lvl_m[k])
        residual = math.sqrt(max(levels[k] ** 2 - gaussian_sigma_px(m) ** 2, 0.0)) / level_scale(m)
        kernels.append(gaussian_kernel(residual, dtype) if residual > 0 else np.ones(1, dtype))
    return BlurStackPlan(levels, lvl_m, tuple(kernels), pad)


def _flat_blocks(img: np.ndarray, reach_px: int) -> np.ndarray:
    """8 x 8 blocks around which every channel of ``img`` (H, W, C) is one constant over
    ``reach_px``."""
    block = level_scale(FLAT_BLOCK_LEVEL)
    radius = blocks_reaching(reach_px, block)
    return constant_blocks(*channel_block_extremes(img, FLAT_BLOCK_LEVEL), radius)


def _pyramid_reach_px(plan: BlurStackPlan, level: int) -> int:
    """How far (full-resolution px, along either axis) from a pixel that is not flat the
    blur stack may read pyramid level ``level``, or read it through a coarser level's
    reduce: a band's patch spans the band's rows (:data:`BAND_ROWS`) and the run of columns
    it merges (columns between needed ones: within the span :func:`wanted_columns` gives),
    widened by the residual kernel and the bilinear taps on each level it is made on
    (:meth:`BlurStackPlan.reach_px`). Each coarser level's columns reach one of its pixels
    past their own reach (:func:`wanted_columns` rounds down), and its reduce two pixels of
    the level below farther: ``2 ** (k + 1)`` full-resolution px for level k, and a block
    more."""
    chain = sum(2 * level_scale(k) + level_scale(FLAT_BLOCK_LEVEL)
                for k in range(level + 1, plan.top + 1))
    return plan.reach_px() + BAND_ROWS + chain


def _foveate(
    img: np.ndarray, sigma: np.ndarray | SigmaOnBlocks, max_sigma: float, ratio: float,
    min_residual_px: float, skip: bool,
) -> np.ndarray:
    plan = blur_stack_plan(max_sigma, ratio, min_residual_px, img.dtype.type)
    if skip:
        flat, shift = _flat_blocks(img, plan.reach_px()), FLAT_BLOCK_LEVEL
    else:  # one block, never flat
        flat, shift = np.zeros((1, 1), np.bool_), 62
    if callable(sigma):
        if flat.all():  # every pixel is its input
            return img.copy()
        sigma = _float_array(sigma(~flat, shift))
    pad, top = plan.pad_px, plan.top
    padded_bytes = (img.shape[0] + 2 * pad) * (img.shape[1] + 2 * pad) * img.shape[2] \
        * img.itemsize
    if padded_bytes > MAX_PADDED_BYTES:
        raise FovexpError(
            f"the foveation's blur reaches sigma = {max_sigma:.4g} px on a {img.shape[1]}x"
            f"{img.shape[0]} image: its padded image would take {padded_bytes / 2**30:.3g} GiB "
            f"(at most {MAX_PADDED_BYTES / 2**30:g}); the display profile's size, resolution "
            "and viewing distance with the blur-rate give this blur"
        )
    # the pyramid of the image padded by `pad` (its first step reads the image through
    # clamped indices: no padded copy); level 0 is the image itself, read unpadded (its
    # borders replicate by clamping), the coarser levels are written into one buffer. When
    # blocks are flat, only the columns the blur patches can read (_pyramid_reach_px) are
    # computed: on a mostly flat frame the pyramid was a third of the foveation
    columns = None
    if top and flat.any():
        need = ~flat
        columns = lambda m, lh, lw: wanted_columns(  # noqa: E731
            need, level_scale(shift), _pyramid_reach_px(plan, m), m, pad, lw, lh)
    if top:
        pbuf, pmeta = packed_pyramid(img, top, pad, columns)
    else:
        pbuf, pmeta = np.zeros(0, img.dtype), np.zeros((1, 3), dtype=np.int64)
    kmeta = np.zeros((len(plan.kernels), 2), dtype=np.int64)
    start = 0
    for k, g in enumerate(plan.kernels):
        kmeta[k] = (start, g.size // 2)
        start += g.size
    kbuf = np.concatenate(plan.kernels)
    return _foveate_bands(
        img, sigma, plan.sigmas_px.astype(img.dtype), plan.pyramid_level, kbuf, kmeta, pbuf,
        pmeta, pad, BAND_ROWS, flat, shift, frame_empty(img.shape, img.dtype),
    )


@numba.njit(parallel=True, cache=True, fastmath=FASTMATH, nogil=True)
def _exact_at(img, sigma, ys, xs, truncate):  # pragma: no cover - compiled
    h, w, c = img.shape
    n = ys.shape[0]
    out = np.empty((n, c), dtype=np.float64)
    chunk = 256
    smax = 0.0
    for i in range(n):
        smax = max(smax, np.float64(sigma[ys[i], xs[i]]))
    rmax = int(truncate * smax + 0.5)
    for b in numba.prange((n + chunk - 1) // chunk):
        # per-thread buffers: the point's kernel, its clamped columns, sums per channel
        g = np.empty(2 * rmax + 1)
        cols = np.empty(2 * rmax + 1, dtype=np.int64)
        acc = np.empty(c)
        row = np.empty(c)
        for i in range(b * chunk, min(n, b * chunk + chunk)):
            y, x = ys[i], xs[i]
            s = np.float64(sigma[y, x])
            if s <= 0.0:
                for ch in range(c):
                    out[i, ch] = img[y, x, ch]
                continue
            r = int(truncate * s + 0.5)
            total = 0.0
            for d in range(-r, r + 1):
                g[d + r] = math.exp(-0.5 * d * d / (s * s))
                total += g[d + r]
                cols[d + r] = min(max(x + d, 0), w - 1)
            for d in range(2 * r + 1):
                g[d] /= total
            acc[:] = 0.0
            for dy in range(-r, r + 1):
                yy = min(max(y + dy, 0), h - 1)
                row[:] = 0.0
                for dx in range(2 * r + 1):
                    gx = g[dx]
                    xx = cols[dx]
                    for ch in range(c):
                        row[ch] += gx * img[yy, xx, ch]
                for ch in range(c):
                    acc[ch] += g[dy + r] * row[ch]
            for ch in range(c):
                out[i, ch] = acc[ch]
    return out


def foveate_exact(
    linear: np.ndarray, sigma_map_px: np.ndarray, ys: np.ndarray | None = None,
    xs: np.ndarray | None = None,
) -> np.ndarray:
    """Exact spatially varying convolution: each output pixel is the input convolved with the
    sampled, normalised Gaussian of *its own* sigma (truncated at 4 sigma, replicated borders).

    For a constant sigma this equals ``scipy.ndimage.gaussian_filter(mode="nearest")``. With
    ``ys, xs`` only those pixels are computed (returns (N,) or (N, C)); otherwise the whole
    image (slow: (8 sigma + 1)^2 multiply-adds per pixel and channel; the reference that
    ``EngineOptions(foveation="exact")`` runs). Sums in float64; the result is float32, or
    float64 for a float64 image.
    """
    grey = linear.ndim == 2
    img = _float_array(linear[..., None] if grey else linear)
    sigma = _float_array(sigma_map_px)
    whole = ys is None
    if whole:
        yy, xx = np.mgrid[0 : img.shape[0], 0 : img.shape[1]]
        ys, xs = yy.ravel(), xx.ravel()
    out = _exact_at(img, sigma, np.asarray(ys, np.int64), np.asarray(xs, np.int64),
                    TRUNCATE_SIGMAS)
    if whole:
        out = out.reshape(img.shape)
    out = out.astype(img.dtype)
    return out[..., 0] if grey else out
