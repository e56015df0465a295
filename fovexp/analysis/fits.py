"""Psychometric fits of forced-choice answers (issue 30, section 3): one participant's answers
for one method to a threshold at a stated level with its 95 % interval.

Two fits, reported side by side:

- :func:`fit_ml`: maximum likelihood of the Weibull of :mod:`fovexp.results.psychometric`
  (guess 0.5; the lapse fixed, or free in [0, 0.06] as Wichmann & Hill 2001, Percept.
  Psychophys. 63(8):1293-1313, advise), its interval from a parametric bootstrap (Wichmann &
  Hill 2001b, 63(8):1314-1329: answers drawn from the fitted function at the tested
  blur-rates, each refitted, the 2.5 and 97.5 percentiles of their thresholds). The likelihood
  is evaluated on a dense grid of (scale, slope[, lapse]) for the point estimate and every
  bootstrap sample at once (one matrix product), and the point estimate is then refined with
  :func:`scipy.optimize.minimize`.
- :func:`fit_psignifit`: psignifit 4's Bayesian fit (Schuett, Harmeling, Macke & Wichmann 2016,
  Vision Res. 122:105-123), the field's reference, where the ``[psignifit]`` extra is installed:
  its threshold is the posterior's, its interval the marginal credible interval. It uses its
  own priors (over the stimulus range) and integrates over the width and lapse, where the ML
  fit maximises; with many trials the two agree, with few psignifit's interval is the wider.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np
from scipy import optimize

from fovexp import FovexpError
from fovexp.results.psychometric import (
    GUESS_RATE_2AFC,
    THRESHOLD_PC,
    log10_threshold_at,
    proportion_correct,
)

#: a free lapse rate's range (Wichmann & Hill 2001: lapses above 6 % mean an observer who
#: was not doing the task)
LAPSE_RANGE = (0.0, 0.06)
#: the slopes (Weibull shapes) the fit considers: from a function spread over a decade of
#: blur-rate to one that rises within a few per cent of it
SLOPE_RANGE = (0.5, 20.0)


@dataclass(frozen=True)
class ThresholdFit:
    """A fitted psychometric function and its threshold at ``pc`` correct (arcmin/deg)."""

    fit: str  # "ml-bootstrap" or "psignifit"
    pc: float
    threshold_arcmin_per_deg: float
    ci_low_arcmin_per_deg: float
    ci_high_arcmin_per_deg: float
    log10_scale: float
    slope: float
    lapse: float
    n_trials: int

    def as_dict(self) -> dict[str, float | str | int]:
        return asdict(self)


def aggregate(blur_rate_arcmin_per_deg: Sequence[float] | np.ndarray,
              correct: Sequence[bool] | np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(blur-rates tested, correct answers, trials) per blur-rate; blur-rates of 0 (no
    foveation: nothing to detect) are left out."""
    b = np.asarray(blur_rate_arcmin_per_deg, dtype=float)
    c = np.asarray(correct, dtype=bool)
    if b.shape != c.shape:
        raise FovexpError(f"a fit needs one answer per blur-rate, got {b.size} and {c.size}")
    keep = b > 0
    levels, inv = np.unique(b[keep], return_inverse=True)
    k = np.bincount(inv, weights=c[keep].astype(float), minlength=levels.size)
    n = np.bincount(inv, minlength=levels.size).astype(float)
    return levels, k, n


class _Grid:
    """The parameter grid of the ML fit over a data set's blur-rates."""

    def __init__(self, x: np.ndarray, lapse: float | None, pc: float) -> None:
        lo, hi = float(x.min()), float(x.max())
        # scales from a decade below the lowest blur-rate tested to one above the highest: a
        # threshold outside that is not measured, and the interval says so by reaching the edge
        t = np.arange(lo - 1.0, hi + 1.0 + 1e-9, 0.005)
        s = np.geomspace(*SLOPE_RANGE, 40)
        lams = np.array([lapse]) if lapse is not None else np.linspace(*LAPSE_RANGE, 7)
        tt, ss, ll = np.meshgrid(t, s, lams, indexing="ij")
        self.t, self.s, self.lam = tt.ravel(), ss.ravel(), ll.ravel()
        p = proportion_correct(x[:, None], self.t[None, :], self.s[None, :], self.lam[None, :])
        p = np.clip(p, 1e-9, 1 - 1e-9)
        self.log_p, self.log_q = np.log(p), np.log1p(-p)  # (levels, grid)
        self.threshold = log10_threshold_at(pc, self.t, self.s, self.lam)

    def best(self, k: np.ndarray, n: np.ndarray) -> np.ndarray:
        """The grid index of the maximum likelihood for each row of ``k`` (samples x levels),
        in chunks of rows that keep the likelihood matrix to a few million values."""
        step = max(1, 4_000_000 // self.t.size)
        out = [np.argmax(k[i:i + step] @ self.log_p + (n - k[i:i + step]) @ self.log_q, axis=1)
               for i in range(0, k.shape[0], step)]
        return np.concatenate(out)


def _neg_log_lik(theta: np.ndarray, x: np.ndarray, k: np.ndarray, n: np.ndarray,
                 lapse: float | None) -> float:
    t, log_s = theta[0], theta[1]
    lam = lapse if lapse is not None else float(np.clip(theta[2], *LAPSE_RANGE))
    p = np.clip(proportion_correct(x, t, math.exp(log_s), lam), 1e-12, 1 - 1e-12)
    return float(-(k * np.log(p) + (n - k) * np.log1p(-p)).sum())


def fit_ml(blur_rate_arcmin_per_deg: Sequence[float] | np.ndarray,
           correct: Sequence[bool] | np.ndarray, *, pc: float = THRESHOLD_PC,
           lapse: float | None = 0.02, n_boot: int = 400, seed: int = 0) -> ThresholdFit:
    """The maximum-likelihood fit and its parametric-bootstrap 95 % interval (module
    docstring). ``lapse``: fixed at this value, or None (free in :data:`LAPSE_RANGE`)."""
    levels, k, n = aggregate(blur_rate_arcmin_per_deg, correct)
    if levels.size < 2:
        raise FovexpError(f"a psychometric fit needs answers at two blur-rates or more, got "
                          f"{levels.size}")
    x = np.log10(levels)
    grid = _Grid(x, lapse, pc)
    j = int(grid.best(k[None, :], n[None, :])[0])
    start = [grid.t[j], math.log(grid.s[j])] + ([] if lapse is not None else [grid.lam[j]])
    res = optimize.minimize(_neg_log_lik, np.array(start), args=(x, k, n, lapse),
                            method="Nelder-Mead", options={"xatol": 1e-5, "fatol": 1e-7})
    t_hat, s_hat = float(res.x[0]), float(math.exp(res.x[1]))
    s_hat = float(np.clip(s_hat, *SLOPE_RANGE))
    t_hat = float(np.clip(t_hat, grid.t[0], grid.t[-1]))
    lam_hat = lapse if lapse is not None else float(np.clip(res.x[2], *LAPSE_RANGE))
    if res.fun > _neg_log_lik(np.array(start), x, k, n, lapse):  # the grid's was better
        t_hat, s_hat, lam_hat = float(grid.t[j]), float(grid.s[j]), float(grid.lam[j])
    thr = float(log10_threshold_at(pc, t_hat, s_hat, lam_hat))
    # parametric bootstrap: answers drawn from the fitted function at the tested blur-rates
    rng = np.random.default_rng(seed)
    p_hat = proportion_correct(x, t_hat, s_hat, lam_hat)
    k_boot = rng.binomial(n.astype(int)[None, :], p_hat[None, :], size=(n_boot, x.size))
    boot = grid.threshold[grid.best(k_boot.astype(float), n[None, :])]
    lo, hi = np.nanpercentile(boot, [2.5, 97.5])
    return ThresholdFit("ml-bootstrap", pc, 10.0 ** thr, 10.0 ** float(lo), 10.0 ** float(hi),
                        t_hat, s_hat, lam_hat, int(n.sum()))


def psignifit_available() -> bool:
    """Whether the ``[psignifit]`` extra is installed."""
    try:
        import psignifit  # noqa: F401
    except ImportError:
        return False
    return True


def fit_psignifit(blur_rate_arcmin_per_deg: Sequence[float] | np.ndarray,
                  correct: Sequence[bool] | np.ndarray, *, pc: float = THRESHOLD_PC,
                  lapse: float | None = 0.02,
                  grid_arcmin_per_deg: tuple[float, float] | None = None) -> ThresholdFit:
    """psignifit 4's Bayesian fit (module docstring). Its 'weibull' is a Gumbel on its x, so x
    is ln(blur-rate) (../shared/CHECKED.md); ``grid_arcmin_per_deg``, the procedure's whole
    range, sets the prior's stimulus range (the default, the range tested, is narrow after
    QUEST+). The interval is psignifit's marginal one for the threshold at ``pc``."""
    try:
        import psignifit
    except ImportError:
        raise FovexpError("psignifit's fit needs the [psignifit] extra: pip install "
                          "'fovexp[psignifit]'") from None
    levels, k, n = aggregate(blur_rate_arcmin_per_deg, correct)
    if levels.size < 2:
        raise FovexpError(f"a psychometric fit needs answers at two blur-rates or more, got "
                          f"{levels.size}")
    data = np.column_stack([np.log(levels), k, n])
    lo, hi = grid_arcmin_per_deg or (float(levels.min()), float(levels.max()))
    kwargs: dict[str, object] = {"sigmoid": "weibull", "experiment_type": "2AFC",
                                 "stimulus_range": (math.log(lo), math.log(hi))}
    if lapse is not None:
        # psignifit's threshold is at thresh_PC of the sigmoid before guess and lapse scale it:
        # pc = guess + (1 - guess - lapse) * u, so u below puts it at pc correct, and its
        # marginal interval is the threshold's own
        kwargs["fixed_parameters"] = {"lambda": lapse}
        kwargs["thresh_PC"] = (pc - GUESS_RATE_2AFC) / (1.0 - GUESS_RATE_2AFC - lapse)
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = psignifit.psignifit(data, **kwargs)
    lam = float(res.parameter_estimate["lambda"])
    if lapse is not None:
        thr = float(res.parameter_estimate["threshold"])
        ci = res.confidence_intervals["threshold"]["0.95"]
    else:  # a free lapse: psignifit's conversion, whose interval is conservative (CHECKED.md)
        value, cis = res.threshold(pc)
        thr, ci = float(np.ravel(value)[0]), np.ravel(cis["0.95"])
    # psignifit's width (the Gumbel's rise from alpha to 1 - alpha, in ln units; alpha = its
    # width_alpha, 0.05) as the Weibull's shape: that span is (ln(-ln a) - ln(-ln(1 - a))) /
    # shape (its sigmoids.Gumbel)
    alpha = float(getattr(res.configuration, "width_alpha", 0.05))
    width = float(res.parameter_estimate["width"])
    slope = (math.log(-math.log(alpha)) - math.log(-math.log(1 - alpha))) / width
    t_log10 = float(log10_threshold_at(pc, 0.0, slope, lam))
    return ThresholdFit("psignifit", pc, math.exp(thr), math.exp(float(ci[0])),
                        math.exp(float(ci[1])), thr / math.log(10) - t_log10, slope, lam,
                        int(n.sum()))


@dataclass(frozen=True)
class PosteriorDifference:
    """The posterior of the mean difference of paired values (here log10 thresholds) under
    the normal model with the noninformative prior p(mu, sigma) ~ 1/sigma: a Student t with
    n - 1 degrees of freedom centred on the mean difference, scale sd / sqrt(n) (Gelman et al.,
    Bayesian Data Analysis, 3rd ed., section 3.2)."""

    n: int
    mean: float
    ci_low: float
    ci_high: float
    #: the posterior probability that the difference is above 0
    p_positive: float


def posterior_difference(diff: Sequence[float] | np.ndarray) -> PosteriorDifference:
    """:class:`PosteriorDifference` of ``diff`` (NaN with fewer than two values)."""
    from scipy import stats

    d = np.asarray(diff, dtype=float)
    d = d[np.isfinite(d)]
    n = int(d.size)
    if n < 2 or float(d.std(ddof=1)) == 0.0:
        m = float(d.mean()) if n else math.nan
        return PosteriorDifference(n, m, math.nan, math.nan, math.nan)
    post = stats.t(df=n - 1, loc=float(d.mean()), scale=float(d.std(ddof=1)) / math.sqrt(n))
    lo, hi = post.ppf([0.025, 0.975])
    return PosteriorDifference(n, float(d.mean()), float(lo), float(hi), float(post.sf(0.0)))


__all__ = ["LAPSE_RANGE", "PosteriorDifference", "ThresholdFit", "aggregate", "fit_ml",
           "fit_psignifit", "posterior_difference", "psignifit_available"]
