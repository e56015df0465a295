"""The paired t-test of the validation (paper section 6.1) and the sampling-rate ratio of
section 6.3. The tests go through :mod:`scipy.stats`; the hand formulas are in the docstrings
and checked against scipy in the tests.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np
from scipy import stats

from fovexp import FovexpError


@dataclass(frozen=True)
class PairedTTest:
    """Paired (dependent-samples) t-test of ``a - b`` against 0, two-sided.

    ``d_z`` is Cohen's d for paired data, mean(diff) / sd(diff); ``ci_low``/``ci_high`` the 95 %
    confidence interval of the mean difference, mean +- t_{0.975, n-1} * sd / sqrt(n).
    """

    n: int
    mean_a: float
    mean_b: float
    mean_diff: float
    sd_diff: float
    t: float
    df: int
    p: float
    d_z: float
    ci_low: float
    ci_high: float

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


def paired_ttest(a: Sequence[float] | np.ndarray, b: Sequence[float] | np.ndarray,
                 confidence: float = 0.95) -> PairedTTest:
    """Paired t-test of ``a`` vs ``b`` (paper section 6.1: ours vs contrast, "t-test").

    Uses :func:`scipy.stats.ttest_rel`; needs at least two pairs, else the statistics are NaN.
    Pairs that all differ by the same amount (to rounding) give an infinite t and d_z (NaN
    when that amount is 0), no p, and a CI of that one value.
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    if a.shape != b.shape or a.ndim != 1:
        raise FovexpError(f"paired t-test needs two equally long 1-D samples, got {a.shape} "
                          f"and {b.shape}")
    n = int(a.size)
    d = a - b
    nan = math.nan
    if n < 2:
        m = float(d.mean()) if n else nan
        return PairedTTest(n, float(a.mean()) if n else nan, float(b.mean()) if n else nan,
                           m, nan, nan, max(n - 1, 0), nan, nan, nan, nan)
    sd = float(d.std(ddof=1))
    mean_d = float(d.mean())
    # Every pair differs by the same amount, to rounding (0.4 - 0.3 and 0.3 - 0.2 differ in
    # their last bits): t is infinite or undefined, and so is d_z; no p, a CI of one point.
    scale = float(np.max(np.abs(np.concatenate([a, b])))) if n else 0.0
    if sd <= 64 * np.finfo(float).eps * scale:
        inf = math.copysign(math.inf, mean_d) if mean_d else nan
        return PairedTTest(n, float(a.mean()), float(b.mean()), mean_d, 0.0, inf, n - 1, nan,
                           inf, mean_d, mean_d)
    res = stats.ttest_rel(a, b)
    ci = res.confidence_interval(confidence_level=confidence)
    d_z = mean_d / sd
    return PairedTTest(
        n=n, mean_a=float(a.mean()), mean_b=float(b.mean()), mean_diff=mean_d, sd_diff=sd,
        t=float(res.statistic), df=int(res.df), p=float(res.pvalue), d_z=float(d_z),
        ci_low=float(ci.low), ci_high=float(ci.high),
    )


def sampling_rate_ratio(blur_rate_new: float, blur_rate_base: float) -> float:
    """SR_new / SR_base = blur_rate_base / blur_rate_new (paper section 6.3, eqs. 10-11).

    With SR(x) = 1 / (4 sigma(x)) and sigma proportional to the blur-rate past the fovea, the
    net sampling rate scales with 1 / blur-rate. The reduction is ``1 - ratio``.
    """
    if not (blur_rate_new > 0 and blur_rate_base > 0):
        return math.nan
    return blur_rate_base / blur_rate_new
