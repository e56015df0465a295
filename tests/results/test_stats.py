"""The calibration chain's statistics (fovexp.results.stats): mean and SEM, the least-squares
line, by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fovexp import FovexpError
from fovexp.results.limits import TrialLimits
from fovexp.results.stats import Line, linear_fit, mean_sem


def test_mean_sem_by_hand_and_without_the_missing_values():
    # 1, 2, 6: mean 3, sd (ddof 1) sqrt(((-2)^2 + 1 + 9) / 2) = sqrt(7), SEM sqrt(7 / 3)
    assert mean_sem([1.0, 2.0, 6.0]) == pytest.approx((3.0, math.sqrt(7 / 3), 3))
    assert mean_sem([1.0, np.nan, 2.0, np.inf, 6.0]) == pytest.approx((3.0, math.sqrt(7 / 3), 3))
    mean, sem, n = mean_sem([4.5])
    assert (mean, n) == (4.5, 1) and math.isnan(sem)
    mean, sem, n = mean_sem([np.nan])
    assert n == 0 and math.isnan(mean) and math.isnan(sem)
    assert mean_sem(np.array([2, 4])) == pytest.approx((3.0, 1.0, 2))


def test_linear_fit_by_hand():
    # (0, 1), (1, 3), (2, 4): Sxx = 2, Sxy = 3 -> slope 1.5, intercept 8/3 - 1.5 = 7/6;
    # residuals -1/6, 1/3, -1/6: SSres = 1/6, SStot = 14/3 -> r2 = 1 - 1/28
    line = linear_fit([0.0, 1.0, 2.0], [1.0, 3.0, 4.0])
    assert (line.slope, line.intercept, line.r2, line.n) == pytest.approx(
        (1.5, 7 / 6, 1 - 1 / 28, 3))
    assert isinstance(line.n, int) and isinstance(line.slope, float)
    assert line(4.0) == pytest.approx(1.5 * 4 + 7 / 6)
    assert np.allclose(line(np.array([0.0, 2.0])), [7 / 6, 3 + 7 / 6])
    assert Line(2.0, -1.0, 1.0, 2)(3.0) == 5.0
    assert linear_fit([1, 1, 2], [0, 2, 4]).slope == pytest.approx(3.0)  # two distinct x
    with pytest.raises(FovexpError, match="at least two distinct x values"):
        linear_fit([2.0, 2.0], [1.0, 3.0])


def test_the_trial_limits_and_their_rules():
    import dataclasses

    lim = TrialLimits()
    with pytest.raises(dataclasses.FrozenInstanceError):
        lim.max_latency_p95_ms = 100.0  # type: ignore[misc]
    assert (lim.max_blanked_fraction, lim.max_dropped_fraction, lim.max_latency_p95_ms) == (
        0.5, 0.05, 20.0)  # R13: 20 ms since issue 18 (docs/ANALYSIS.md)
    rules = TrialLimits(0.25, 0.1, 45.5).rules()
    assert list(rules) == ["R11 blanking", "R12 dropped frames", "R13 latency"]
    assert "more than 25% of its frames: excluded" in rules["R11 blanking"]
    assert "more than 10% of its frames dropped" in rules["R12 dropped frames"]
    assert "exceeds 45.5 ms" in rules["R13 latency"]
