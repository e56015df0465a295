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


#: The paper's appendix A table (Thibos et al. 1996), transcribed from the paper, and the
#: release's extension past 30 deg (docs/METHOD.md, 5.6): eccentricity (deg), T_L, T_H (cpd)
THIBOS = [(0, 60, 60), (5, 27, 40), (10, 10.5, 26), (15, 8, 24), (20, 5.5, 23), (25, 4.8, 21),
          (30, 4, 20.5), (35, 3, 20.5), (70, 2, 20.5)]


def test_the_acuity_limits_are_the_papers_table_interpolated_linearly():
    """T_L and T_H at every entry of the table, halfway between entries (linear), and held
    constant before 0 and past 70 deg (paper section 4.1, appendix A)."""
    from fovexp.acuity import t_high_cpd, t_low_cpd

    ecc = np.array([e for e, _, _ in THIBOS], float)
    assert np.array_equal(t_low_cpd(ecc), [lo for _, lo, _ in THIBOS])
    assert np.array_equal(t_high_cpd(ecc), [hi for _, _, hi in THIBOS])
    for (e0, lo0, hi0), (e1, lo1, hi1) in zip(THIBOS[:-1], THIBOS[1:], strict=True):
        mid = 0.5 * (e0 + e1)
        assert t_low_cpd(mid) == pytest.approx(0.5 * (lo0 + lo1))
        assert t_high_cpd(mid) == pytest.approx(0.5 * (hi0 + hi1))
    assert t_low_cpd(90.0) == 2 and t_high_cpd(90.0) == 20.5
    assert t_low_cpd(-1.0) == 60 and t_high_cpd(-1.0) == 60


def test_the_band_takes_the_larger_lower_and_the_smaller_upper_limit():
    """F_L = max(T_L / ppd, 3 / (2 pi sigma)), F_H = min(T_H / ppd, 1/2) (eqs. 1-2), each
    side of each max and min: at 30 deg T_L = 4, T_H = 20.5 cpd."""
    ecc = np.full(4, 30.0)
    ppd = np.array([50.0, 50.0, 10.0, 100.0])
    sigma = np.array([0.5, 20.0, 20.0, 20.0])
    f_lo, f_hi = frequency.frequency_band_cpp(ecc, ppd, sigma)
    assert f_lo == pytest.approx([3 / (2 * math.pi * 0.5), 4 / 50, 4 / 10, 4 / 100])
    assert f_hi == pytest.approx([20.5 / 50, 20.5 / 50, 0.5, 20.5 / 100])
    assert frequency.blur_cutoff_cpp(np.array([0.0, 1.0]))[0] == np.inf
    assert frequency.blur_cutoff_cpp(np.array([2.0]))[0] == pytest.approx(3 / (4 * math.pi))


def test_lognormal_parameters_are_eqs_3_and_4():
    """mu_n = (ln F_L + ln F_H) / 2, sigma_n = s_f (mu_n - ln F_L) / 2 (eqs. 3-4)."""
    mu, sn = frequency.lognormal_params(np.array([0.04]), np.array([0.36]), 3.0)
    assert mu[0] == pytest.approx(0.5 * (math.log(0.04) + math.log(0.36)))
    assert sn[0] == pytest.approx(3.0 * 0.5 * math.log(3.0))  # (mu - ln 0.04) = ln 3


def test_the_truncated_draw_at_its_quantiles_and_its_limit():
    """The inverse CDF draw at known quantiles: u -> exp(mu + sigma Phi^-1(u Phi(z_H))), at
    most F_H; where sigma_n is 0 the draw is exp(mu_n)."""
    from scipy.stats import norm

    mu, sn, hi = np.full(3, -2.0), np.full(3, 0.5), np.full(3, math.exp(-1.5))
    u = np.array([0.1, 0.5, 0.999])
    z_h = (np.log(hi) - mu) / sn  # 1
    want = np.exp(mu + sn * norm.ppf(u * norm.cdf(z_h)))
    assert frequency.draw_truncated(u, mu, sn, hi) == pytest.approx(want, rel=1e-12)
    assert (want < hi).all()
    assert frequency.draw_truncated(np.array([0.7]), np.array([-2.0]), np.array([0.0]),
                                    np.array([1.0]))[0] == pytest.approx(math.exp(-2.0))
    # u close to 1 of a wide distribution: never above F_H
    f = frequency.draw_truncated(np.array([1.0 - 1e-16]), np.array([0.0]), np.array([50.0]),
                                 np.array([0.01]))
    assert 0 < f[0] <= 0.01


def test_release_draw_keeps_the_first_try_below_the_upper_limit():
    """The release's rejection (docs/METHOD.md, 5.6): tries in order, the first with
    ln f < ln F_H is kept; none: mu_n."""
    n = frequency.RELEASE_REJECTION_TRIES
    assert n == 10
    normals = np.zeros((3, n))
    normals[0, :3] = [3.0, 2.5, -1.0]  # tries 0 and 1 too high, 2 kept
    normals[1, :] = 5.0  # every try too high: mu
    normals[2, 0] = -0.5  # the first try kept
    mu, sn, hi = np.zeros(3), np.ones(3), np.full(3, math.exp(2.0))
    f = frequency.draw_release(normals, mu, sn, hi)
    assert f == pytest.approx([math.exp(-1.0), 1.0, math.exp(-0.5)])
    # exactly at the limit is not below it
    at = np.full((1, n), 2.0)
    at[0, 1] = 1.0
    assert frequency.draw_release(at, mu[:1], sn[:1], hi[:1])[0] == pytest.approx(math.e)


def test_the_draw_at_sigma_one_and_below_the_whole_distribution():
    """sigma_n of exactly 1 is an ordinary draw (only 0 is the point exp(mu_n)); where F_H
    lies far below the whole distribution (u Phi(z_H) underflows to 0), the draw is F_H, its
    limit, not 0."""
    from scipy.stats import norm

    f = frequency.draw_truncated(np.array([0.3]), np.array([-2.0]), np.array([1.0]),
                                 np.array([1.0]))
    assert f[0] == pytest.approx(math.exp(-2.0 + norm.ppf(0.3 * norm.cdf(2.0))), rel=1e-12)
    far = frequency.draw_truncated(np.array([0.5]), np.array([0.0]), np.array([0.01]),
                                   np.array([math.exp(-100.0)]))
    assert far[0] == math.exp(-100.0)


def test_a_negative_zero_sigma_is_no_blur_and_opens_no_band():
    """sigma = -0.0 is sigma = 0 (it compares equal): the blur removes nothing, so its cut-off
    3 / (2 pi sigma) is +inf, not the -inf the formula gives, and the band (eq. 1) stays empty,
    exactly as at +0.0, whatever the eccentricity (the noise must not open at the fovea)."""
    assert frequency.blur_cutoff_cpp(np.array([-0.0, 0.0, -0.0])).tolist() == [np.inf] * 3
    ecc = np.array([0.0, 5.0, 20.0, 40.0, 70.0])
    ppd = np.full(ecc.size, 40.0)
    neg = frequency.frequency_band_cpp(ecc, ppd, np.full(ecc.size, -0.0))
    pos = frequency.frequency_band_cpp(ecc, ppd, np.zeros(ecc.size))
    assert np.array_equal(neg[0], pos[0]) and np.array_equal(neg[1], pos[1])
    assert (neg[0] >= neg[1]).all()  # empty: no noise
    assert np.array_equal(frequency.blur_cutoff_cpp(np.float32(-0.0)), np.inf)


def test_a_band_open_by_one_ulp_draws_its_upper_limit():
    """F_L one float step below F_H: the band is open (F_L < F_H) but ln F_L == ln F_H, so
    mu_n = ln F_H and sigma_n = 0 (eqs. 3-4). The draw is then the point exp(mu_n) = F_H (its
    limit), not 0 / 0: no NaN frequency reaches the synthesis."""
    hi = np.array([0.3, 0.35])
    lo = np.nextafter(hi, 0.0)
    assert (lo < hi).all() and np.array_equal(np.log(lo), np.log(hi))  # the case asked for
    for s_f in (2.21, 1e-300):
        mu, sn = frequency.lognormal_params(lo, hi, s_f)
        assert not sn.any() and np.array_equal(mu, np.log(hi))
        f = frequency.draw_truncated(np.array([0.01, 0.99]), mu, sn, hi)
        assert np.array_equal(f, np.minimum(np.exp(mu), hi))


@pytest.mark.parametrize("n", [5, (1 << 14) + 1, 300_001])
def test_the_per_impulse_draw_on_threads_is_one_call_bit_for_bit(n):
    """The pipeline's per-impulse expressions go in parts on threads
    (fovexp._parallel.over_points): the frequency draw, a tuple-valued function and one of
    the point maps give the bits of one call, on every thread count."""
    import numba

    from fovexp._parallel import over_points

    rng = np.random.default_rng(n)
    f_lo = rng.uniform(0.01, 0.1, n)
    f_hi = f_lo * rng.uniform(0.5, 4.0, n)  # some bands closed
    u = rng.random(n)

    def draw(lo, hi, q):
        return frequency.draw_truncated(q, *frequency.lognormal_params(lo, hi, 1.3), hi)

    want = draw(f_lo, f_hi, u)
    want_pair = frequency.lognormal_params(f_lo, f_hi, 0.7)
    before = numba.get_num_threads()
    try:
        for threads in range(1, numba.config.NUMBA_NUM_THREADS + 1):
            numba.set_num_threads(threads)
            assert over_points(draw, f_lo, f_hi, u).tobytes() == want.tobytes()
            got = over_points(lambda lo, hi: frequency.lognormal_params(lo, hi, 0.7), f_lo, f_hi)
            assert isinstance(got, tuple) and len(got) == 2
            assert all(g.tobytes() == w.tobytes() for g, w in zip(got, want_pair, strict=True))
    finally:
        numba.set_num_threads(before)
