"""Shared inputs of the enhancer tests: generated textured images and the shared Sponza frame."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import ndimage

SPONZA = Path(__file__).resolve().parents[2] / "shared" / "stimuli" / "sponza-4k.jpg"


def textured_image(height: int = 270, width: int = 480, seed: int = 0, rgb: bool = True,
                   flat_squares: bool = True):
    """Display-encoded test image in [0.05, 0.95]: 1/f-like texture with a few flat patches and
    sharp edges, so every stage has something to work on. The flat squares are 60 px, one of
    them in the top-left corner: a crop smaller than that is one constant, on which no formula
    can be told from another (``flat_squares=False`` leaves them out)."""
    rng = np.random.default_rng(seed)
    tex = sum(
        ndimage.gaussian_filter(rng.standard_normal((height, width)), s) * s**0.5
        for s in (0.7, 1.5, 3.0, 6.0)
    )
    tex = (tex - tex.min()) / (tex.max() - tex.min())
    yy, xx = np.mgrid[0:height, 0:width]
    if flat_squares:
        tex[(xx // 60 + yy // 60) % 5 == 0] = 0.5
    tex = 0.05 + 0.9 * tex
    if not rgb:
        return tex.astype(np.float32)
    tint = np.array([1.0, 0.85, 0.7])
    return np.clip(tex[..., None] * tint, 0.0, 1.0).astype(np.float32)


@pytest.fixture(scope="session")
def sponza():
    if not SPONZA.is_file():
        pytest.skip(f"the shared 4K Sponza frame is absent ({SPONZA})")
    from fovexp import read_image

    return read_image(SPONZA)


def band_power_fraction(res, ecc_deg: float, row: int = 540, size: int = 96, slack: float = 0.05):
    """Local spectrum of ``res``'s noise in a ``size`` px window on ``row``, right of the centre,
    where the eccentricity is ``ecc_deg``: the fraction of its power within [F_L, F_H] widened
    by ``slack`` cycles/px (the Gabor kernel's and the window's spectral spread), and the share
    of the spectrum that band covers."""
    noise, ecc = res.map("noise"), res.map("eccentricity_deg")
    f_lo, f_hi = res.map("f_low_cpp"), res.map("f_high_cpp")
    mid = noise.shape[1] // 2
    x = int(np.argmin(np.abs(ecc[row, mid:] - ecc_deg))) + mid
    sl = np.s_[row - size // 2: row + size // 2, x - size // 2: x + size // 2]
    patch = noise[sl]
    assert patch.std() > 0
    win = np.outer(np.hanning(size), np.hanning(size))
    f = np.fft.fftfreq(size)
    fr = np.hypot(f[None, :], f[:, None])
    power = np.abs(np.fft.fft2((patch - patch.mean()) * win)) ** 2
    lo, hi = float(f_lo[sl].min()), float(f_hi[sl].max())
    assert lo < hi
    inside = (fr >= lo - slack) & (fr <= hi + slack)
    return power[inside].sum() / power.sum(), inside.mean()


def mixed_scene(height: int = 540, width: int = 960, seed: int = 3, rgb: bool = True):
    """A frame that mixes what skipping must get right: texture, black borders, a flat colour
    patch, flat grey and white regions, their edges off the 8 px blocks and 16 and 32 px tiles
    the skipping works on (so tiles cut through edges), and a constant-luminance patch that
    is not grey."""
    img = textured_image(height, width, seed=seed, rgb=True)
    h, w = height, width
    img[:, : max(1, w * 37 // 960)] = 0.0  # black borders
    img[:, w - max(1, w * 29 // 960):] = 0.0
    img[h * 100 // 540: h * 333 // 540, w * 203 // 960: w * 517 // 960] = (0.4, 0.35, 0.3)
    img[h * 301 // 540:, w * 601 // 960: w * 899 // 960] = 0.5
    img[h * 21 // 540: h * 91 // 540, w * 701 // 960: w * 949 // 960] = 1.0
    return img if rgb else img.mean(axis=2).astype(np.float32)
