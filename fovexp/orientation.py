"""Noise orientation from image gradients (paper section 4.3; docs/METHOD.md, 5.5).

Sobel gradients of the foveated grey image on Gaussian-pyramid level 3 (1/8 resolution, for
spatial and temporal smoothness), interpolated bicubically to the points where they are needed
(Keys cubic convolution, a = -0.5: MATLAB's imresize 'bicubic', which the release uses).
The orientation follows the release's convention (x right, y down)::

    omega = atan2(G_y, G_x) - pi / 2

and the Gabor carrier then runs at ``omega - pi / 2``, i.e. along the gradient: the noise's
stripes run along the edges (see :mod:`fovexp.gabor`).

References
----------
.. [tariq] Tariq, T., Tursun, C., Didyk, P. (2022). Noise-based Enhancement for Foveated
   Rendering. ACM Transactions on Graphics 41(4) (SIGGRAPH 2022). doi:10.1145/3528223.3530101
.. [keys] Keys, R. (1981). Cubic Convolution Interpolation for Digital Image Processing. IEEE
   Transactions on Acoustics, Speech, and Signal Processing 29(6), 1153-1160.
   doi:10.1109/TASSP.1981.1163711
"""

from __future__ import annotations

import numba
import numpy as np

from ._parallel import over_points
from .jit import FASTMATH
from .pyramids import sample_cubic

#: Gaussian-pyramid level the gradients are computed on (paper section 4.3).
ORIENTATION_LEVEL = 3

#: Gradient magnitude (linear luminance per level pixel) below which the direction is taken as
#: undefined: in a flat area G is float32 rounding (~1e-7) and its atan2 any angle, differently
#: on every backend; there omega = atan2(0, 0) - pi/2. Real edges are 1e-3 and more.
GRADIENT_EPS = 1e-5


def sobel_gradients(grey_level: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(G_x, G_y)``: Sobel derivatives along x (right) and y (down), replicated borders
    (float32, or float64 when the level is): ``scipy.ndimage.sobel(g, axis, mode="nearest")``
    for axis 1 and 0, bit for bit (:func:`_sobel_into`)."""
    g = np.asarray(grey_level)
    g = np.ascontiguousarray(g, dtype=np.float64 if g.dtype == np.float64 else np.float32)
    if g.ndim != 2:
        raise ValueError(f"Sobel gradients of a 2-D level, not shape {g.shape}")
    gx, gy = np.empty_like(g), np.empty_like(g)
    if g.size:
        _sobel_into(g, gx, gy)
    return gx, gy


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _difference(a, b, c):  # pragma: no cover - compiled
    """SciPy's correlate1d with ``[-1, 0, 1]`` at ``b`` (``a`` before, ``c`` after): in
    float64, ``b * 0 + (a - c) * -1`` (the products kept: ``b * 0`` is -0.0 for negative
    ``b``)."""
    return np.float64(b) * 0.0 + (np.float64(a) - np.float64(c)) * -1.0


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _smoothing(a, b, c):  # pragma: no cover - compiled
    """SciPy's correlate1d with ``[1, 2, 1]`` at ``b``: in float64, ``b * 2 + (a + c) * 1``."""
    return np.float64(b) * 2.0 + (np.float64(a) + np.float64(c)) * 1.0


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _taps(a, b, c, smooth):  # pragma: no cover - compiled
    """:func:`_smoothing` or :func:`_difference` at ``b``."""
    return _smoothing(a, b, c) if smooth else _difference(a, b, c)


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _sobel_pass(down, down_out, along, along_out, smooth):  # pragma: no cover - compiled
    """One of :func:`_sobel_into`'s passes: ``down`` filtered down its columns into
    ``down_out``, ``along`` along its rows into ``along_out`` (:func:`_taps`), the border
    replicated."""
    h, w = down.shape
    for y in range(h):
        # rows as slices indexed from 0, interior columns without clamping: they vectorise
        row, up, below, out = down[y], down[max(y - 1, 0)], down[min(y + 1, h - 1)], down_out[y]
        for x in range(w):
            out[x] = _taps(up[x], row[x], below[x], smooth)
        row, out = along[y], along_out[y]
        mid, left, right, inner = row[1:], row[0:], row[2:], out[1:]
        for x in range(w - 2):
            inner[x] = _taps(left[x], mid[x], right[x], smooth)
        out[0] = _taps(row[0], row[0], row[min(1, w - 1)], smooth)
        if w > 1:
            out[w - 1] = _taps(row[w - 2], row[w - 1], row[w - 1], smooth)


@numba.njit(cache=True, fastmath=FASTMATH, nogil=True)
def _sobel_into(g, gx, gy):  # pragma: no cover - compiled
    """``gx``, ``gy`` = the Sobel derivatives of ``g`` (H, W), the border replicated, as
    ``scipy.ndimage.sobel`` computes them: the central difference along the axis first
    (:func:`_difference`), stored in the output's dtype, then the smoothing across it
    (:func:`_smoothing`), stored. A compiled pass over a 4K frame's 480 x 270 level-3 grid:
    0.17 ms, where SciPy's line buffers took 1.0-1.5."""
    dx, dy = np.empty_like(gx), np.empty_like(gy)
    _sobel_pass(g, dy, g, dx, False)  # the differences: down for G_y, along for G_x
    _sobel_pass(dx, gx, dy, gy, True)  # the smoothing across each


def orientation_at(
    gx: np.ndarray, gy: np.ndarray, x_px: np.ndarray, y_px: np.ndarray,
    level: int = ORIENTATION_LEVEL, dtype: type = np.float32,
) -> np.ndarray:
    """``omega`` (rad) at full-resolution points: G_x, G_y interpolated bicubically (Keys,
    :func:`fovexp.pyramids.sample_cubic`) from their level grid, then
    ``atan2(G_y, G_x) - pi/2``; ``-pi/2`` where ``|G| < GRADIENT_EPS`` (a flat area).
    Float32 (or ``dtype``)."""
    gxs, gys = sample_cubic(np.stack((gx, gy)), x_px, y_px, level)  # one pass, shared taps

    def omega(gxs: np.ndarray, gys: np.ndarray) -> np.ndarray:
        flat = np.hypot(gxs, gys) < GRADIENT_EPS
        return (np.where(flat, 0.0, np.arctan2(gys, gxs)) - 0.5 * np.pi).astype(dtype)

    return over_points(omega, gxs, gys)
