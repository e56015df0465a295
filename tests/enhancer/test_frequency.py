"""Frequency band and draw (paper section 4.1, eqs. 1-5) against their formulas and the exact
truncated log-normal."""

import math

import numpy as np
import pytest
from scipy import stats

from fovexp import frequency


def test_band_is_empty_where_sigma_is_zero_and_capped_at_nyquist():
    f_lo, f_hi = frequency.frequency_band_cpp(np.array([5.0, 30.0]), np.array([40.0, 40.0]),
                                              np.array([0.0, 5.0]))
    assert f_lo[0] >= f_hi[0]  # sigma 0: no noise
    assert f_lo[1] == pytest.approx(max(4.0 / 40, 3 / (2 * math.pi * 5)))
    assert f_hi[1] == pytest.approx(min(20.5 / 40, 0.5))


def test_truncated_draw_is_exactly_the_truncated_lognormal():
    rng = np.random.default_rng(0)
    n = 20000
    f_lo, f_hi = np.full(n, 0.05), np.full(n, 0.3)
    mu, sn = frequency.lognormal_params(f_lo, f_hi, 2.21)
    f = frequency.draw_truncated(rng.random(n), mu, sn, f_hi)
    assert f.max() < 0.3 and f.min() > 0
    b = (np.log(0.3) - mu[0]) / sn[0]
    ks = stats.kstest(np.log(f), stats.truncnorm(-np.inf, b, loc=mu[0], scale=sn[0]).cdf)
    assert ks.pvalue > 0.01
    # the paper's sigma_n: mu +- 2 sigma_n spans the band when s_f = 1
    mu1, sn1 = frequency.lognormal_params(f_lo[:1], f_hi[:1], 1.0)
    assert mu1[0] - 2 * sn1[0] == pytest.approx(np.log(0.05))


def test_release_draw_falls_back_to_the_mean_when_all_tries_fail():
    mu, sn, hi = np.array([0.0]), np.array([1.0]), np.array([1e-9])
    f = frequency.draw_release(np.zeros((1, frequency.RELEASE_REJECTION_TRIES)), mu, sn, hi)
    assert f[0] == pytest.approx(1.0)
