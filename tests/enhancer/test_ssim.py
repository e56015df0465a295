"""fovexp.ssim (paper section 6.2's measure) against scikit-image's structural_similarity,
the reference it reimplements faster: within 1e-4 (measured: within 1e-6) on images of
every kind the temporal analysis meets."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter
from skimage.metrics import structural_similarity

from fovexp import FovexpError, ssim
from fovexp.sequence import InterframeSSIM


def _pairs():
    rng = np.random.default_rng(7)
    noise = rng.random((90, 160)).astype(np.float32)
    yield "noise vs noisier", noise, np.clip(noise + 0.2 * rng.standard_normal(noise.shape),
                                             0, 1).astype(np.float32)
    from evaluation_helpers import scene

    img = scene(0).mean(axis=2)
    yield "scene vs shifted scene", img[:, :-6], img[:, 6:]
    yield "scene vs blurred", img, gaussian_filter(img, 1.5)
    yield "flat vs flat", np.full((40, 50), 0.3, np.float32), np.full((40, 50), 0.3,
                                                                        np.float32)
    yield "flat vs step", np.full((40, 50), 0.5), np.where(np.arange(50) < 25, 0.4, 0.6) * \
        np.ones((40, 1))
    yield "smallest (7 x 9), float64", rng.random((7, 9)), rng.random((7, 9))
    yield "odd sizes", rng.random((33, 71)), rng.random((33, 71))


@pytest.mark.parametrize("name,a,b", list(_pairs()), ids=[p[0] for p in _pairs()])
def test_ssim_matches_scikit_image(name, a, b):
    ref = structural_similarity(a, b, data_range=1.0)
    assert abs(ssim(a, b) - ref) < 1e-4, name
    assert abs(ssim(a, b) - ref) < 1e-6, name  # what it is in fact


def test_identical_images_and_range():
    x = np.linspace(0, 1, 64 * 48).reshape(48, 64)
    assert ssim(x, x) == pytest.approx(1.0, abs=1e-12)
    assert -1.0 <= ssim(x, 1 - x) <= 1.0


def test_interframe_ssim_is_the_mean_over_consecutive_pairs():
    rng = np.random.default_rng(3)
    frames = [rng.random((20, 30)).astype(np.float32) for _ in range(4)]
    run = InterframeSSIM()
    for f in frames:
        run.add(f)
    assert run.count == 3
    want = np.mean([structural_similarity(frames[i], frames[i + 1], data_range=1.0)
                    for i in range(3)])
    assert run.mean == pytest.approx(want, abs=1e-6)


@pytest.mark.parametrize("a,b", [(np.zeros((8, 8)), np.zeros((8, 9))),
                                 (np.zeros((6, 20)), np.zeros((6, 20))),
                                 (np.zeros((8, 8, 3)), np.zeros((8, 8, 3)))])
def test_bad_shapes_are_one_error(a, b):
    with pytest.raises(FovexpError, match="ssim"):
        ssim(a, b)
