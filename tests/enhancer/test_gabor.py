"""Sparse Gabor noise (paper section 4.4; Lagae et al. 2009): kernel radius, impulse density,
the K / 6 normalisation, and the synthesis against a direct sum."""

import math

import numpy as np
import pytest

from fovexp import gabor


def test_kernel_radius_and_density_as_computed_by_hand():
    """docs/METHOD.md, 4: r = sqrt(-ln 0.01 / pi) / a; N impulses per kernel of area pi r^2."""
    assert gabor.kernel_radius_px(0.06) == pytest.approx(20.2, abs=0.05)
    assert gabor.kernel_radius_px(0.08) == pytest.approx(15.1, abs=0.05)
    imp = gabor.generate_impulses(2000, 1000, 12, 0.06, 5)
    inside = (imp.x_px >= 0) & (imp.x_px < 2000) & (imp.y_px >= 0) & (imp.y_px < 1000)
    lam = gabor.impulse_density(12, 0.06)
    assert inside.sum() / (2000 * 1000) == pytest.approx(lam, rel=0.03)


@pytest.mark.parametrize("n", [12, 64])
def test_noise_std_over_k_is_one_sixth_whatever_the_impulse_count(n):
    """docs/METHOD.md, 5.9: the release's noise has std / K = 0.164 (measured) for 12 and 64."""
    h, w = 600, 800
    imp = gabor.generate_impulses(w, h, n, 0.06, 2)
    m = len(imp)
    rng = np.random.default_rng(0)
    noise = gabor.synthesize((h, w), imp, np.full(m, 0.3), rng.uniform(0.08, 0.4, m),
                             rng.uniform(0, np.pi, m), n, 0.06)
    ratio = noise[40:-40, 40:-40].std() / 0.3
    assert ratio == pytest.approx(1 / 6, rel=0.04)


def test_synthesis_matches_direct_sum_of_truncated_gabors():
    h, w = 64, 80
    imp = gabor.generate_impulses(w, h, 3, 0.06, 9)
    m = len(imp)
    rng = np.random.default_rng(1)
    k, f, t = rng.random(m), rng.uniform(0.05, 0.45, m), rng.uniform(-np.pi, np.pi, m)
    fast = gabor.synthesize((h, w), imp, k, f, t, 3, 0.06)
    r, a = gabor.kernel_radius_px(0.06), 0.06
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    ref = np.zeros((h, w))
    norm = gabor.normalisation(3, 0.06)
    for i in range(m):
        dx, dy = xx - imp.x_px[i], yy - imp.y_px[i]
        g = np.exp(-math.pi * a * a * (dx * dx + dy * dy)) * np.cos(
            2 * math.pi * f[i] * (dx * math.cos(t[i]) + dy * math.sin(t[i])))
        g[(np.abs(dx) > r) | (np.abs(dy) > r)] = 0
        ref += imp.weight[i] * k[i] * norm * g
    assert np.abs(fast - ref).max() < 1e-4 * max(1.0, np.abs(ref).max())


def test_impulses_are_deterministic_from_the_seed():
    a = gabor.generate_impulses(300, 200, 12, 0.06, 1)
    b = gabor.generate_impulses(300, 200, 12, 0.06, 1)
    c = gabor.generate_impulses(300, 200, 12, 0.06, 2)
    assert np.array_equal(a.x_px, b.x_px) and np.array_equal(a.weight, b.weight)
    assert len(a) != len(c) or not np.array_equal(a.x_px, c.x_px)
