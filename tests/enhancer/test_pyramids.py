"""Image pyramids (paper sections 4.2, 4.3): the min/max pyramid of the clipping control
against brute force and against the paper's 2 x 2 construction."""

import numpy as np

from fovexp import pyramids


def test_block_extremes_match_brute_force():
    rng = np.random.default_rng(3)
    img = rng.random((37, 45, 3))
    lo, hi = pyramids.block_extremes(img, 3)
    assert lo.shape == (5, 6)
    assert lo[1, 2] == img[8:16, 16:24].min() and hi[4, 5] == img[32:37, 40:45].max()
    # the paper's construction, 2 x 2 neighbourhoods level by level, gives the same numbers
    a = img.min(axis=2)[:32, :40]
    for _ in range(3):
        a = np.minimum(np.minimum(a[0::2, 0::2], a[1::2, 0::2]),
                       np.minimum(a[0::2, 1::2], a[1::2, 1::2]))
    assert np.array_equal(a, lo[:4, :5])


def _constant_by_filters(lo: np.ndarray, hi: np.ndarray, radius: int) -> np.ndarray:
    """The definition of pyramids.constant_blocks: min of lo == max of hi over the clamped
    (2 r + 1)^2 window, in every channel (SciPy's filters)."""
    from scipy import ndimage

    size = 2 * radius + 1
    out = np.ones(lo.shape[:2], dtype=bool)
    for ch in range(lo.shape[2]):
        out &= ndimage.minimum_filter(lo[..., ch], size, mode="nearest") == (
            ndimage.maximum_filter(hi[..., ch], size, mode="nearest"))
    return out


def test_constant_radius_answers_every_radius_as_the_window_filters_do():
    """One pass (a chessboard distance to the nearest block whose 3 x 3 window is not
    constant) gives, at every radius, the blocks whose whole window is one constant: random
    grids of one, two or three channels, mostly one value with specks, regions of another
    value and non-constant blocks; the whole grid constant answers every radius."""
    rng = np.random.default_rng(7)
    for _ in range(300):
        bh, bw, c = (int(v) for v in (rng.integers(1, 25), rng.integers(1, 25),
                                     rng.integers(1, 4)))
        other = rng.integers(0, 2, (bh, bw, c)).astype(np.float32)
        lo = np.where(rng.random((bh, bw, c)) < 0.3 * rng.random(), other, np.float32(0.5))
        hi = lo + np.float32(0.1) * (rng.random((bh, bw, c)) < 0.05)
        radius = pyramids.constant_radius_blocks(lo, hi)
        for r in [*range(0, 27), 60]:
            np.testing.assert_array_equal(radius >= r, _constant_by_filters(lo, hi, r))
    flat = np.full((5, 7, 1), 0.25, np.float32)
    assert pyramids.constant_blocks(flat, flat, 10**6).all()
    speck = flat.copy()
    speck[2, 3] = np.nan  # NaN is never one constant (SciPy's filters would skip it)
    assert (pyramids.constant_radius_blocks(speck, speck)[2, 3]) == -1
