"""Mean with its standard error, and the least-squares line: what the calibration chain needs
(paper section 5.2). Both go through :mod:`scipy.stats`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import stats

from fovexp import FovexpError


def mean_sem(values: Sequence[float] | np.ndarray) -> tuple[float, float, int]:
    """(mean, standard error of the mean, n); SEM = sd(ddof=1) / sqrt(n), NaN for n < 2.

    The error bars of the paper's calibration and validation plots are SEMs (section 5.2).
    """
    x = np.asarray(values, dtype=float)
    x = x[np.isfinite(x)]
    n = int(x.size)
    if n == 0:
        return math.nan, math.nan, 0
    mean = float(x.mean())
    sem = float(stats.sem(x, ddof=1)) if n > 1 else math.nan
    return mean, sem, n


@dataclass(frozen=True)
class Line:
    """Least-squares line y = slope * x + intercept (paper section 5.2: s_k against s_f)."""

    slope: float
    intercept: float
    r2: float
    n: int

    def __call__(self, x: float | np.ndarray) -> float | np.ndarray:
        return self.slope * x + self.intercept


def linear_fit(x: Sequence[float] | np.ndarray, y: Sequence[float] | np.ndarray) -> Line:
    """Ordinary least squares via :func:`scipy.stats.linregress`; needs two distinct x."""
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    if len(np.unique(x)) < 2:
        raise FovexpError(f"a line needs at least two distinct x values, got {np.unique(x)}")
    res = stats.linregress(x, y)
    return Line(float(res.slope), float(res.intercept), float(res.rvalue**2), int(x.size))
