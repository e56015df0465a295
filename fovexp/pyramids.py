"""Image pyramids (paper sections 4.2, 4.3; notes sections 3.5, 3.7, 3.8).

Gaussian and Laplacian pyramids use the 5-tap binomial kernel [1, 4, 6, 4, 1] / 16 with
replicated borders, keeping every second sample (Burt and Adelson 1983), as the release does.
Sample ``j`` of level ``m`` sits on full-resolution pixel ``j * 2**m``.

Laplacian levels are counted from 1 (notes section 1, erratum): ``L_1 = G_0 - expand(G_1)`` is
the finest band, 0.25..0.5 cycles/px, with centre ``2**-1.5``; level ``k`` has centre
``2**-(k + 0.5)`` cycles/px and lives on the grid of ``G_{k-1}``.

Min/max pyramids (paper section 4.2): level ``l`` holds the minimum (maximum) of each
``2**l x 2**l`` block of the full-resolution image.
"""

from __future__ import annotations

import numba
import numpy as np
from scipy import ndimage

from .jit import FASTMATH

#: Burt-Adelson 5-tap binomial kernel; its variance is 1 px^2 at the level it filters.
BINOMIAL_5 = np.array([1.0, 4.0, 6.0, 4.0, 1.0], dtype=np.float32) / 16.0
#: :func:`expand`'s polyphase taps (zero insertion, then BINOMIAL_5 x 2): an even output takes
#: the kernel's even taps, at a[i-1], a[i], a[i+1] ([1, 6, 1] / 8), an odd output its odd
#: taps, at a[i], a[i+1] ([1, 1] / 2).
EXPAND_EVEN_TAPS = 2 * BINOMIAL_5[0::2]
EXPAND_ODD_TAPS = 2 * BINOMIAL_5[1::2]
# float32 scalars for the compiled loops (the kernels are symmetric)
_REDUCE_OUTER, _REDUCE_INNER, _REDUCE_CENTRE = BINOMIAL_5[0], BINOMIAL_5[1], BINOMIAL_5[2]
_EXPAND_SIDE, _EXPAND_CENTRE = EXPAND_EVEN_TAPS[0], EXPAND_EVEN_TAPS[1]
_EXPAND_HALF = EXPAND_ODD_TAPS[0]


def level_scale(level: int) -> int:
    """Full-resolution pixels per sample of Gaussian level ``level``."""
    return 1 << level


def gaussian_sigma_px(level: int) -> float:
    """Effective Gaussian std (full-res px) of Gaussian level ``level``: sum of 4**j, j < level.

    Each reduce filters with variance 1 in its input's pixels, i.e. 4**j full-res px^2.
    """
    return float(np.sqrt((4.0**level - 1.0) / 3.0))


@numba.njit(parallel=True, cache=True, fastmath=FASTMATH, nogil=True)
def _reduce_2d(img: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    h, w = img.shape
    ho, wo = (h + 1) // 2, (w + 1) // 2
    out = np.empty((ho, wo), dtype=np.float32)
    k0, k1, k2 = _REDUCE_OUTER, _REDUCE_INNER, _REDUCE_CENTRE
    for i in numba.prange(ho):
        r = 2 * i
        rm2, rm1 = max(r - 2, 0), max(r - 1, 0)
        rp1, rp2 = min(r + 1, h - 1), min(r + 2, h - 1)
        row = np.empty(w, dtype=np.float32)
        for x in range(w):
            row[x] = (
                k0 * (img[rm2, x] + img[rp2, x]) + k1 * (img[rm1, x] + img[rp1, x])
                + k2 * img[r, x]
            )
        for j in range(wo):
            c = 2 * j
            out[i, j] = (
                k0 * (row[max(c - 2, 0)] + row[min(c + 2, w - 1)])
                + k1 * (row[max(c - 1, 0)] + row[min(c + 1, w - 1)])
                + k2 * row[c]
            )
    return out


@numba.njit(parallel=True, cache=True, fastmath=FASTMATH, nogil=True)
def _expand_2d(a: np.ndarray, ho: int, wo: int) -> np.ndarray:  # pragma: no cover - compiled
    h, w = a.shape
    out = np.empty((ho, wo), dtype=np.float32)
    for y in numba.prange(ho):
        i = y // 2
        row = np.empty(w, dtype=np.float32)
        if y % 2 == 0:
            im1, ip1 = max(i - 1, 0), min(i + 1, h - 1)
            for x in range(w):
                row[x] = _EXPAND_SIDE * (a[im1, x] + a[ip1, x]) + _EXPAND_CENTRE * a[i, x]
        else:
            ip1 = min(i + 1, h - 1)
            for x in range(w):
                row[x] = _EXPAND_HALF * (a[i, x] + a[ip1, x])
        for x in range(wo):
            j = x // 2
            if x % 2 == 0:
                out[y, x] = _EXPAND_SIDE * (row[max(j - 1, 0)] + row[min(j + 1, w - 1)]) + (
                    _EXPAND_CENTRE * row[j]
                )
            else:
                out[y, x] = _EXPAND_HALF * (row[j] + row[min(j + 1, w - 1)])
    return out


def _per_channel(fn, image: np.ndarray, *args: int) -> np.ndarray:
    image = np.ascontiguousarray(image, dtype=np.float32)
    if image.ndim == 2:
        return fn(image, *args)
    return np.stack(
        [fn(np.ascontiguousarray(image[..., c]), *args) for c in range(image.shape[2])], axis=-1
    )


def reduce(image: np.ndarray) -> np.ndarray:
    """One Gaussian-pyramid step: binomial filter (replicated borders), keep every second sample.

    Works on (H, W) or (H, W, C) float32 images.
    """
    return _per_channel(_reduce_2d, image)


def expand(image: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Inverse step of :func:`reduce`: upsample to ``shape`` (the finer level's size).

    Zero insertion and filtering with the binomial kernel x 2, in polyphase form
    (:data:`EXPAND_EVEN_TAPS`, :data:`EXPAND_ODD_TAPS`): even outputs
    ``(a[i-1] + 6 a[i] + a[i+1]) / 8``, odd outputs ``(a[i] + a[i+1]) / 2``, borders replicated.
    """
    return _per_channel(_expand_2d, image, int(shape[0]), int(shape[1]))


def gaussian_pyramid(image: np.ndarray, levels: int) -> list[np.ndarray]:
    """``[G_0, ..., G_levels]`` with ``G_0`` the image itself (not copied)."""
    pyr = [image]
    for _ in range(levels):
        if min(pyr[-1].shape[:2]) < 2:
            break
        pyr.append(reduce(pyr[-1]))
    return pyr


@numba.njit(parallel=True, cache=True, fastmath=FASTMATH, nogil=True)
def _abs_diff_box3(fine, up):  # pragma: no cover - compiled
    h, w = fine.shape
    out = np.empty((h, w), dtype=np.float32)
    for y in numba.prange(h):
        for x in range(w):
            acc = np.float32(0.0)
            for dy in range(-1, 2):
                yy = min(max(y + dy, 0), h - 1)
                for dx in range(-1, 2):
                    xx = min(max(x + dx, 0), w - 1)
                    acc += abs(fine[yy, xx] - up[yy, xx])
            out[y, x] = acc / np.float32(9.0)
    return out


def smoothed_abs_laplacian(gaussian: list[np.ndarray], levels: int) -> dict[int, np.ndarray]:
    """``|L_k|`` smoothed by a 3 x 3 mean on its own grid (notes 3.7), ``k = 1..levels``,
    in one fused pass per level."""
    out = {}
    for k in range(1, min(levels, len(gaussian) - 1) + 1):
        fine = np.ascontiguousarray(gaussian[k - 1], dtype=np.float32)
        out[k] = _abs_diff_box3(fine, expand(gaussian[k], fine.shape[:2]))
    return out


def laplacian_levels(gaussian: list[np.ndarray], levels: int) -> dict[int, np.ndarray]:
    """Laplacian bands ``{k: G_{k-1} - expand(G_k)}`` for ``k = 1..levels`` (notes section 1)."""
    out = {}
    for k in range(1, min(levels, len(gaussian) - 1) + 1):
        fine = gaussian[k - 1]
        out[k] = fine - expand(gaussian[k], fine.shape[:2])
    return out


@numba.njit(parallel=True, cache=True, nogil=True, fastmath=FASTMATH)
def _block_extremes(img, add, block):  # pragma: no cover - compiled
    h, w, c = img.shape
    bh, bw = (h + block - 1) // block, (w + block - 1) // block
    lo = np.empty((bh, bw), dtype=img.dtype)
    hi = np.empty((bh, bw), dtype=img.dtype)
    for by in numba.prange(bh):
        for bx in range(bw):
            mn = img[by * block, bx * block, 0] + add[by * block, bx * block]
            mx = mn
            for y in range(by * block, min(by * block + block, h)):
                for x in range(bx * block, min(bx * block + block, w)):
                    for ch in range(c):
                        v = img[y, x, ch] + add[y, x]
                        mn = min(mn, v)
                        mx = max(mx, v)
            lo[by, bx] = mn
            hi[by, bx] = mx
    return lo, hi


def block_extremes(
    image: np.ndarray, level: int, add: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Level ``level`` of the min and max pyramids (paper section 4.2): the minimum and maximum
    of each ``2**level x 2**level`` block (over all channels of an (H, W, C) image), of
    ``image + add`` when a grey (H, W) ``add`` is given (added to every channel).

    The paper builds the level from 2 x 2 neighbourhoods level by level; the extreme of the
    block is the same number, computed here in one pass (edge blocks are the partial ones).
    """
    img = np.ascontiguousarray(image if image.ndim == 3 else image[..., None])
    grey = np.zeros(img.shape[:2], img.dtype) if add is None else np.ascontiguousarray(
        add, dtype=img.dtype)
    return _block_extremes(img, grey, level_scale(level))


def sample_bilinear(grid: np.ndarray, x_px: np.ndarray, y_px: np.ndarray, level: int) -> np.ndarray:
    """Bilinear sample of a level-``level`` grid at full-resolution coordinates (borders held)."""
    s = float(level_scale(level))
    return ndimage.map_coordinates(
        grid, [np.asarray(y_px) / s, np.asarray(x_px) / s], order=1, mode="nearest"
    ).astype(np.float32, copy=False)


def sample_nearest(grid: np.ndarray, x_px: np.ndarray, y_px: np.ndarray, block: int) -> np.ndarray:
    """The value of the ``block`` x ``block`` cell that contains each full-resolution pixel."""
    iy = np.clip((np.asarray(y_px) + 0.5).astype(np.int64) // block, 0, grid.shape[0] - 1)
    ix = np.clip((np.asarray(x_px) + 0.5).astype(np.int64) // block, 0, grid.shape[1] - 1)
    return grid[iy, ix]


#: Keys (1981) cubic-convolution parameter: a = -0.5 is MATLAB's imresize 'bicubic', with which
#: the release brings the level-3 gradients to full size (notes section 3.5).
KEYS_A = -0.5


@numba.njit(cache=True, inline="always", nogil=True, fastmath=FASTMATH)
def _keys_weight(t):  # pragma: no cover - compiled
    """Keys' cubic-convolution kernel W(t), a = KEYS_A (interpolating: W(0) = 1, W(+-1) = 0)."""
    t = abs(t)
    a = KEYS_A
    if t <= 1.0:
        return ((a + 2.0) * t - (a + 3.0)) * t * t + 1.0
    if t < 2.0:
        return ((a * t - 5.0 * a) * t + 8.0 * a) * t - 4.0 * a
    return 0.0


@numba.njit(parallel=True, cache=True, nogil=True, fastmath=FASTMATH)
def _sample_cubic(grid, u, v):  # pragma: no cover - compiled
    h, w = grid.shape
    out = np.empty(u.shape[0])
    for i in numba.prange(u.shape[0]):
        iu = int(np.floor(u[i]))
        iv = int(np.floor(v[i]))
        fu = u[i] - iu
        fv = v[i] - iv
        acc = 0.0
        for j in range(4):
            wy = _keys_weight(fv + 1.0 - j)
            yy = min(max(iv - 1 + j, 0), h - 1)
            for k in range(4):
                xx = min(max(iu - 1 + k, 0), w - 1)
                acc += wy * _keys_weight(fu + 1.0 - k) * grid[yy, xx]
        out[i] = acc
    return out


def sample_cubic(grid: np.ndarray, x_px: np.ndarray, y_px: np.ndarray, level: int) -> np.ndarray:
    """Bicubic sample (Keys cubic convolution, a = -0.5, borders held) of a level-``level``
    grid at full-resolution coordinates: MATLAB's imresize 'bicubic' kernel (notes 3.5),
    evaluated only at the points asked for. Returns float64 of the points' shape."""
    s = float(level_scale(level))
    x = np.asarray(x_px, dtype=np.float64)
    y = np.asarray(y_px, dtype=np.float64)
    x, y = np.broadcast_arrays(x, y)
    out = _sample_cubic(np.ascontiguousarray(grid, dtype=np.float32), x.ravel() / s,
                        y.ravel() / s)
    return out.reshape(x.shape)
