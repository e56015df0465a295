"""Statistics of the analysis against hand computation and scipy (paper sections 5.3, 6.1, 6.3)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from fovexp import FovexpError
from fovexp.analysis.stats import paired_ttest, sampling_rate_ratio
from fovexp.results.stats import linear_fit, mean_sem

# d = a - b = [0.10, 0.15, 0.05, 0.20]: mean 0.125, sum of squared deviations 0.0125,
# sd = sqrt(0.0125 / 3), se = sd / 2, t = 0.125 / se = sqrt(15), d_z = sqrt(15) / 2.
A = [0.50, 0.60, 0.55, 0.70]
B = [0.40, 0.45, 0.50, 0.50]


def test_mean_sem_by_hand() -> None:
    mean, sem, n = mean_sem([1.0, 2.0, 3.0, 4.0])
    # sd = sqrt(5 / 3), sem = sd / 2
    assert (mean, n) == (2.5, 4)
    assert sem == pytest.approx(math.sqrt(5 / 3) / 2, rel=1e-12)
    assert sem == pytest.approx(stats.sem([1.0, 2.0, 3.0, 4.0]))


def test_mean_sem_degenerate() -> None:
    m, s, n = mean_sem([3.0])
    assert (m, n) == (3.0, 1) and math.isnan(s)
    m, s, n = mean_sem([])
    assert n == 0 and math.isnan(m) and math.isnan(s)
    assert mean_sem([1.0, np.nan, 3.0])[2] == 2  # NaN is no observation


def test_paired_ttest_by_hand() -> None:
    r = paired_ttest(A, B)
    assert r.n == 4 and r.df == 3
    assert r.mean_diff == pytest.approx(0.125)
    assert r.sd_diff == pytest.approx(math.sqrt(0.0125 / 3))
    assert r.t == pytest.approx(math.sqrt(15), rel=1e-10)
    assert r.d_z == pytest.approx(math.sqrt(15) / 2, rel=1e-10)
    # Student's t with 3 df has a closed-form CDF:
    # F(t) = 1/2 + (t / (sqrt(3) (1 + t^2/3)) + atan(t / sqrt(3))) / pi; here t/sqrt(3) = sqrt(5).
    cdf = 0.5 + (math.sqrt(5) / 6 + math.atan(math.sqrt(5))) / math.pi
    assert r.p == pytest.approx(2 * (1 - cdf), rel=1e-9)
    assert r.p == pytest.approx(0.0304663, abs=1e-6)
    # 95 % CI: 0.125 +- t_{0.975, 3} * se, t_{0.975, 3} = 3.182446 (tables)
    half = 3.182446305 * math.sqrt(0.0125 / 3) / 2
    assert r.ci_low == pytest.approx(0.125 - half, rel=1e-8)
    assert r.ci_high == pytest.approx(0.125 + half, rel=1e-8)


def test_paired_ttest_matches_scipy_random() -> None:
    rng = np.random.default_rng(3)
    a = rng.normal(0.5, 0.1, 25)
    b = a - rng.normal(0.05, 0.05, 25)
    r = paired_ttest(a, b)
    ref = stats.ttest_rel(a, b)
    assert r.t == pytest.approx(ref.statistic) and r.p == pytest.approx(ref.pvalue)
    # the one-sample t-test on the differences is the same test
    one = stats.ttest_1samp(a - b, 0.0)
    assert r.t == pytest.approx(one.statistic)
    d = a - b
    assert r.d_z == pytest.approx(d.mean() / d.std(ddof=1))


def test_paired_ttest_sign_and_small_n() -> None:
    assert paired_ttest(B, A).t == pytest.approx(-math.sqrt(15))
    r = paired_ttest([1.0], [0.5])
    assert r.n == 1 and math.isnan(r.t) and math.isnan(r.p)
    with pytest.raises(FovexpError, match="equally long"):
        paired_ttest([1.0, 2.0], [1.0])


def test_linear_fit_by_hand() -> None:
    # x = 1, 2, 3; y = 2, 4, 7: Sxy = 5, Sxx = 2 -> slope 2.5, intercept 13/3 - 5
    line = linear_fit([1, 2, 3], [2, 4, 7])
    assert line.slope == pytest.approx(2.5)
    assert line.intercept == pytest.approx(13 / 3 - 5)
    # residuals 1/6, -1/3, 1/6: SSres = 1/6; SStot = 38/3
    assert line.r2 == pytest.approx(1 - (1 / 6) / (38 / 3))
    assert line(2.0) == pytest.approx(2.5 * 2 + 13 / 3 - 5)
    with pytest.raises(FovexpError, match="two distinct"):
        linear_fit([1, 1], [2, 3])


def test_sampling_rate_ratio() -> None:
    # section 6.3: SR_2 / SR_1 = blur_rate_1 / blur_rate_2
    assert sampling_rate_ratio(0.5, 0.4) == pytest.approx(0.8)
    assert 1 - sampling_rate_ratio(0.5, 0.4) == pytest.approx(0.2)
    assert math.isnan(sampling_rate_ratio(0.0, 0.4))


def _quiet(fn, *args):
    """``fn(*args)`` with every warning an error: the degenerate cases are handled, not left
    to NumPy's 'mean of empty slice' or 'degrees of freedom <= 0'."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return fn(*args)


def test_degenerate_samples_give_nan_quietly() -> None:
    m, s, n = _quiet(mean_sem, [])
    assert n == 0 and math.isnan(m) and math.isnan(s)
    m, s, n = _quiet(mean_sem, [2.5])
    assert (m, n) == (2.5, 1) and math.isnan(s)
    none = _quiet(paired_ttest, [], [])
    assert none.n == 0 and none.df == 0
    assert all(math.isnan(getattr(none, k)) for k in ("mean_a", "mean_b", "mean_diff", "sd_diff",
                                                      "t", "p", "d_z", "ci_low", "ci_high"))
    one = _quiet(paired_ttest, [0.7], [0.4])
    assert (one.n, one.df, one.mean_a, one.mean_b) == (1, 0, 0.7, 0.4)
    assert one.mean_diff == pytest.approx(0.3)
    assert all(math.isnan(getattr(one, k)) for k in ("sd_diff", "t", "p", "d_z", "ci_low"))


def test_two_pairs_and_differences_of_sd_one_and_zero() -> None:
    """Two pairs are a t-test (df 1); d = 1, 2, 3 has sd 1 exactly (d_z = mean = 2); equal
    differences have sd 0: d_z is +-inf (or NaN for no difference at all)."""
    two = paired_ttest([1.0, 2.0], [0.0, 0.5])  # d = 1, 1.5: mean 1.25, se 0.25
    assert two.df == 1 and two.t == pytest.approx(5.0)
    r = paired_ttest([1.0, 2.0, 3.0], [0.0, 0.0, 0.0])
    assert r.sd_diff == 1.0 and r.d_z == pytest.approx(2.0)
    assert paired_ttest([1.0, 2.0, 3.0], [0.5, 1.5, 2.5]).d_z == math.inf
    assert paired_ttest([0.5, 1.5], [1.0, 2.0]).d_z == -math.inf
    assert math.isnan(paired_ttest([1.0, 2.0], [1.0, 2.0]).d_z)


def test_results_are_values() -> None:
    """The statistics' records cannot be changed after the fact (frozen dataclasses)."""
    import dataclasses

    with pytest.raises(dataclasses.FrozenInstanceError):
        paired_ttest(A, B).t = 0.0  # type: ignore[misc]
    with pytest.raises(dataclasses.FrozenInstanceError):
        linear_fit([0.0, 1.0], [1.0, 2.0]).slope = 0.0  # type: ignore[misc]


def test_sampling_rate_ratio_needs_positive_blur_rates() -> None:
    assert sampling_rate_ratio(0.5, 0.25) == pytest.approx(0.5)
    for new, base in ((0.5, 0.0), (0.0, 0.5), (-0.5, 0.5), (0.5, -0.5)):
        assert math.isnan(sampling_rate_ratio(new, base)), (new, base)
