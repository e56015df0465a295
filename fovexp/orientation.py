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

import numpy as np
from scipy import ndimage

from ._parallel import over_points
from .pyramids import sample_cubic

#: Gaussian-pyramid level the gradients are computed on (paper section 4.3).
ORIENTATION_LEVEL = 3

#: Gradient magnitude (linear luminance per level pixel) below which the direction is taken as
#: undefined: in a flat area G is float32 rounding (~1e-7) and its atan2 any angle, differently
#: on every backend; there omega = atan2(0, 0) - pi/2. Real edges are 1e-3 and more.
GRADIENT_EPS = 1e-5


def sobel_gradients(grey_level: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(G_x, G_y)``: Sobel derivatives along x (right) and y (down), replicated borders
    (float32, or float64 when the level is)."""
    g = np.asarray(grey_level)
    if g.dtype != np.float64:
        g = g.astype(np.float32)
    return ndimage.sobel(g, axis=1, mode="nearest"), ndimage.sobel(g, axis=0, mode="nearest")


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
