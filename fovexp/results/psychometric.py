"""The psychometric function of the forced-choice task, one definition for the runner's adaptive
procedure, the simulated observers and the analysis' fits (issue 30).

The probability of a correct answer at blur-rate ``b`` (arcmin/deg) is a Weibull function of
``b``, which is a Gumbel (log-Weibull) function of ``x = log10(b)``; in QUEST+'s parametrisation
(Watson 2017, "QUEST+: a general multidimensional Bayesian adaptive psychometric method",
J. Vis. 17(3):10; the ``questplus`` package's ``weibull`` with ``scale='log10'``):

    p(x) = 1 - lapse - (1 - guess - lapse) * exp(-10 ** (slope * (x - t)))

with ``t`` the log10 of the Weibull's scale. ``slope`` is the Weibull's shape (``(b / 10**t)
** slope = 10 ** (slope * (x - t))``). In two-alternative forced choice ``guess`` is 0.5. At
``x = t`` the function is at ``1 - lapse - (1 - guess - lapse) / e`` (80.3 % correct with a
lapse of 0.02: not 75 %), so every threshold reported is converted to a stated level with
:func:`log10_threshold_at` (the inverse of the formula above, solved for ``x``).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

#: the guess rate of two-alternative forced choice (one of two halves, at random)
GUESS_RATE_2AFC = 0.5
#: the level at which thresholds are reported (proportion correct); halfway between the guess
#: rate and 1, the customary 2AFC threshold (e.g. Wichmann & Hill 2001, Percept. Psychophys.
#: 63(8):1293-1313)
THRESHOLD_PC = 0.75


def proportion_correct(log10_blur_rate: ArrayLike, log10_scale: ArrayLike, slope: ArrayLike,
                       lapse: ArrayLike, guess: float = GUESS_RATE_2AFC) -> NDArray[np.float64]:
    """p(correct) at ``log10_blur_rate`` (module docstring's formula; broadcasts)."""
    x = np.asarray(log10_blur_rate, dtype=float)
    lam = np.asarray(lapse, dtype=float)
    z = np.asarray(slope, dtype=float) * (x - np.asarray(log10_scale, dtype=float))
    # 10**z overflows above z ~ 308; exp(-huge) is 0 all the same
    return 1.0 - lam - (1.0 - guess - lam) * np.exp(-np.power(10.0, np.minimum(z, 300.0)))


def log10_threshold_at(pc: float, log10_scale: ArrayLike, slope: ArrayLike, lapse: ArrayLike,
                       guess: float = GUESS_RATE_2AFC) -> NDArray[np.float64]:
    """log10 of the blur-rate at which p(correct) is ``pc``: the formula of the module docstring
    solved for x, ``x = t + log10(-ln((1 - lapse - pc) / (1 - guess - lapse))) / slope``. NaN
    where ``pc`` is not between the guess rate and ``1 - lapse``."""
    lam = np.asarray(lapse, dtype=float)
    ratio = (1.0 - lam - pc) / (1.0 - guess - lam)
    with np.errstate(divide="ignore", invalid="ignore"):
        inner = -np.log(np.where((ratio > 0) & (ratio < 1), ratio, np.nan))
        return np.asarray(log10_scale, dtype=float) + np.log10(inner) / np.asarray(slope,
                                                                                   dtype=float)


def log10_scale_for(log10_threshold: float, pc: float, slope: float, lapse: float,
                    guess: float = GUESS_RATE_2AFC) -> float:
    """The inverse of :func:`log10_threshold_at`: the ``t`` that puts ``pc`` at
    ``log10_threshold`` (a simulated observer's truth is stated at the reported level)."""
    offset = float(log10_threshold_at(pc, 0.0, slope, lapse, guess))
    if not math.isfinite(offset):
        raise ValueError(f"{pc} correct is not between the guess rate {guess} and 1 - lapse "
                         f"{1 - lapse}")
    return log10_threshold - offset


__all__ = ["GUESS_RATE_2AFC", "THRESHOLD_PC", "log10_scale_for", "log10_threshold_at",
           "proportion_correct"]
