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
