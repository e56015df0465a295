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

import numba
import numpy as np

from ._parallel import power
from .jit import FASTMATH

#: BT.601 luma weights. The release's Y of YCbCr, normalised as (Y - 16/255) / (219/255), equals
#: 0.299 R + 0.587 G + 0.114 B (docs/METHOD.md, 5.4); its grey for orientation uses the same
#: weights rounded as MATLAB's rgb2gray (0.2989, 0.5870, 0.1140).
LUMA_BT601_F64 = np.array([0.299, 0.587, 0.114])
LUMA_BT601 = LUMA_BT601_F64.astype(np.float32)

#: The release's hybrid transfer (docs/METHOD.md, 5.1): ((v + 0.055) / 1.055) ** 2.2.
_RELEASE_OFFSET = 0.055


def linearize(
    encoded: np.ndarray, gamma: float, transfer: str = "power", dtype: type = np.float32
) -> np.ndarray:
    """Display-encoded values in [0, 1] to linear light in [0, 1] (float32, or ``dtype``).

    ``power``: ``v ** gamma`` (the display profile's gamma). ``release``: the release's
    ``((v + 0.055) / 1.055) ** 2.2`` (docs/METHOD.md, 5.1).
    """
    scalar = np.dtype(dtype).type
    if transfer != "release":  # straight from the input: no copy
        return power(np.ascontiguousarray(encoded, dtype=dtype), scalar(gamma))
    out = np.array(encoded, dtype=dtype)  # a copy: worked on in place below
    out += scalar(_RELEASE_OFFSET)
    out *= scalar(1.0 / (1.0 + _RELEASE_OFFSET))
    return power(out, scalar(gamma), out)


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
    linear: np.ndarray, gamma: float, transfer: str = "power", *grey: np.ndarray
) -> np.ndarray:
    """Inverse of :func:`linearize`, after adding up to two grey (H, W) images (the contrast
    change, the noise) to every channel; values outside [0, 1] are clipped first (a display
    shows nothing else). One pass adds and clips, then NumPy's vectorised power (on
    threads). Float32, or float64 when ``linear`` is."""
    lin = np.asarray(linear)
    if lin.dtype != np.float64:
        lin = lin.astype(np.float32, copy=False)
    dtype = lin.dtype
    scalar = dtype.type
    out = np.empty(lin.shape, dtype=dtype)
    if grey:
        if len(grey) > 2:
            raise ValueError("encode adds at most two grey images")
        # contiguous: on strided views the compiled loop measured 7x slower than a copy
        a = np.ascontiguousarray(grey[0], dtype=dtype)
        b = (np.ascontiguousarray(grey[1], dtype=dtype) if len(grey) == 2
             else np.zeros(a.shape, dtype))
        three = lin.ndim == 3
        _add_grey_clip(np.ascontiguousarray(lin if three else lin[..., None]), a, b,
                       out if three else out[..., None])
    else:
        np.clip(lin, 0.0, 1.0, out=out)
    power(out, scalar(1.0 / gamma), out)
    if transfer == "release":
        out *= scalar(1.0 + _RELEASE_OFFSET)
        out -= scalar(_RELEASE_OFFSET)
        np.clip(out, 0.0, 1.0, out=out)
    return out


def luminance(linear: np.ndarray) -> np.ndarray:
    """Linear luma ``0.299 R + 0.587 G + 0.114 B`` of an (H, W, 3) image; grey passes through.
    Float32, or float64 (with the weights in float64) when ``linear`` is."""
    dtype = np.float64 if np.asarray(linear).dtype == np.float64 else np.float32
    if linear.ndim == 2:
        return np.asarray(linear, dtype=dtype)
    weights = LUMA_BT601_F64 if dtype == np.float64 else LUMA_BT601
    return np.tensordot(linear, weights, axes=([-1], [0])).astype(dtype, copy=False)
