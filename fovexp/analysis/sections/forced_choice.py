"""The forced-choice section (issue 30, section 3): per participant and method a psychometric
function fitted to the answers and its threshold at 75 % correct with a 95 % interval (the ML
fit with a parametric bootstrap, and psignifit 4's Bayesian fit where the ``[psignifit]`` extra
is installed: :mod:`fovexp.analysis.fits`), the methods compared across participants on log
thresholds (paired t-tests, as the validation of paper section 6.1 compares its blur-rates,
and the Bayesian posterior of the difference), and, where a participant also ran an
adjustment validation, its adjusted blur-rates beside its thresholds.

The answers come from the ``trials.csv`` rows of forced-choice sessions
(:func:`fovexp.results.choices.with_choices`), after the loader's exclusion rules.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from fovexp import FovexpError
from fovexp.results.choices import with_choices
from fovexp.results.psychometric import THRESHOLD_PC, proportion_correct

from .. import figures as figs
from ..fits import fit_ml, fit_psignifit, posterior_difference, psignifit_available
from ..stats import paired_ttest
from .common import md_table, p_text, write_csv

if TYPE_CHECKING:
    from ..state import Analysis

#: the methods in the order the paper introduces them (section 6.1)
METHOD_ORDER = ("foveated", "contrast", "ours")
THRESHOLD_UNITS = {"threshold": "arcmin/deg", "ci_low": "arcmin/deg", "ci_high": "arcmin/deg",
                   "n_trials": "trials", "slope": "Weibull shape, dimensionless",
                   "lapse": "proportion"}


def _ordered(methods: object) -> list[str]:
    ms = sorted(set(map(str, methods)))  # type: ignore[call-overload]
    return sorted(ms, key=lambda m: (METHOD_ORDER.index(m) if m in METHOD_ORDER else 99, m))


def fit_thresholds(choices: pd.DataFrame, *, pc: float = THRESHOLD_PC,
                   lapse: float | None = 0.02, n_boot: int = 400,
                   psignifit: bool | None = None) -> pd.DataFrame:
    """One row per experiment, participant, method and fit: the threshold at ``pc`` correct
    and its 95 % interval (arcmin/deg), the fitted slope and lapse, the trials. ``psignifit``:
    add its fit (None: where installed). Practice trials are left out; a participant and
    method whose answers cannot be fitted (all at one blur-rate) have no row
    (:func:`unfitted` names them)."""
    use_ps = psignifit_available() if psignifit is None else psignifit
    rows = []
    main = choices[~choices["practice"].astype(bool)] if "practice" in choices else choices
    keys = ["experiment", "participant", "method"]
    for seed, ((exp, part, method), grp) in enumerate(main.groupby(keys, sort=True)):
        b, c = grp["blur_rate"].to_numpy(float), grp["correct"].to_numpy(bool)
        try:
            fits = [fit_ml(b, c, pc=pc, lapse=lapse, n_boot=n_boot, seed=seed)]
            if use_ps:
                fits.append(fit_psignifit(b, c, pc=pc, lapse=lapse))
        except FovexpError:
            continue
        for f in fits:
            rows.append({"experiment": exp, "participant": part, "method": method,
                         "fit": f.fit, "n_trials": f.n_trials,
                         "threshold": f.threshold_arcmin_per_deg,
                         "ci_low": f.ci_low_arcmin_per_deg, "ci_high": f.ci_high_arcmin_per_deg,
                         "slope": f.slope, "lapse": f.lapse, "log10_scale": f.log10_scale})
    return pd.DataFrame(rows)


def unfitted(choices: pd.DataFrame, thresholds: pd.DataFrame) -> list[str]:
    """``participant method`` of each main-trial group without a fit (:func:`fit_thresholds`)."""
    main = choices[~choices["practice"].astype(bool)]
    have = set() if not len(thresholds) else set(
        zip(thresholds["participant"], thresholds["method"], strict=True))
    return [f"{p} {m}" for p, m in sorted(set(zip(main["participant"], main["method"],
                                                   strict=True)) - have)]


def compare_methods(thresholds: pd.DataFrame, fit: str = "ml-bootstrap") -> pd.DataFrame:
    """Each pair of methods compared across participants on log10 thresholds (``fit``'s):
    the paired t-test (:func:`fovexp.analysis.stats.paired_ttest`) and the posterior of the
    mean difference (:func:`fovexp.analysis.fits.posterior_difference`); ``ratio`` is
    10 ** mean difference, the geometric-mean ratio of the thresholds."""
    t = thresholds[thresholds["fit"] == fit]
    rows = []
    for exp, grp in t.groupby("experiment", sort=True):
        wide = grp.pivot(index="participant", columns="method", values="threshold")
        for a, b in itertools.combinations(_ordered(wide.columns), 2):
            pair = wide[[a, b]].dropna()
            la, lb = np.log10(pair[b].to_numpy()), np.log10(pair[a].to_numpy())
            tt = paired_ttest(la, lb)
            post = posterior_difference(la - lb)
            rows.append({"experiment": exp, "comparison": f"{b} vs {a}", "n": tt.n,
                         "mean_log10_diff": tt.mean_diff, "ratio": 10.0 ** tt.mean_diff
                         if math.isfinite(tt.mean_diff) else math.nan,
                         "t": tt.t, "df": tt.df, "p": tt.p, "d_z": tt.d_z,
                         "posterior_low": post.ci_low, "posterior_high": post.ci_high,
                         "p_positive": post.p_positive})
    return pd.DataFrame(rows)


def compare_with_adjustment(thresholds: pd.DataFrame, trials: pd.DataFrame,
                            fc_experiments: set[str], fit: str = "ml-bootstrap"
                            ) -> tuple[pd.DataFrame, float]:
    """Per participant and method who ran both tasks: the mean adjusted blur-rate of the
    adjustment validations (main trials) beside the forced-choice threshold, and the Pearson
    correlation of their logs (NaN below three pairs)."""
    adj = trials[(trials["adjusted_parameter"] == "blur_rate")
                 & ~trials["experiment"].isin(fc_experiments) & ~trials["practice"]]
    if not len(adj) or not len(thresholds):
        return pd.DataFrame(), math.nan
    mean_adj = adj.groupby(["participant", "method"])["final_value"].mean().rename("adjusted")
    thr = thresholds[thresholds["fit"] == fit].groupby(["participant", "method"])[
        "threshold"].mean().rename("forced_choice")
    both = pd.concat([mean_adj, thr], axis=1, join="inner").reset_index()
    both = both[(both["adjusted"] > 0) & (both["forced_choice"] > 0)]
    r = math.nan
    if len(both) >= 3:
        r = float(np.corrcoef(np.log10(both["adjusted"]), np.log10(both["forced_choice"]))[0, 1])
    return both, r


# -- figures -----------------------------------------------------------------------------------

def psychometric_figure(choices: pd.DataFrame, thresholds: pd.DataFrame, exp: str,
                        stem: Path) -> list[Path]:
    """:func:`psychometric_plot`, written as PNG and PDF."""
    return figs._save(psychometric_plot(choices, thresholds, exp), stem)


def psychometric_plot(choices: pd.DataFrame, thresholds: pd.DataFrame, exp: str) -> Figure:
    """Each participant's answers (proportion correct per blur-rate, the marker's area by its
    trials) and fitted functions, one panel per participant."""
    parts = sorted(choices["participant"].unique())
    cols = min(4, len(parts))
    rows_n = -(-len(parts) // cols)
    fig = figs._figure(3.0 * cols + 0.5, 2.6 * rows_n + 1.0)
    axes = np.atleast_1d(fig.subplots(rows_n, cols, sharex=True, sharey=True)).ravel()
    lo, hi = float(choices["blur_rate"].min()), float(choices["blur_rate"].max())
    xs = np.geomspace(max(lo, 1e-3), hi, 100)
    fits = thresholds[thresholds["fit"] == "ml-bootstrap"].set_index(["participant", "method"])
    for ax, part in zip(axes, parts, strict=False):
        mine = choices[choices["participant"] == part]
        for method, grp in mine.groupby("method", sort=True):
            agg = grp.groupby("blur_rate")["correct"].agg(["mean", "size"])
            colour = figs.METHOD_COLOURS.get(str(method))
            ax.scatter(agg.index, agg["mean"], s=8 * agg["size"], alpha=0.5, color=colour)
            if (part, method) in fits.index:
                f = fits.loc[(part, method)]
                ax.plot(xs, proportion_correct(np.log10(xs), f["log10_scale"], f["slope"],
                                               f["lapse"]), color=colour, label=str(method))
        ax.set_xscale("log")
        ax.set_ylim(0.3, 1.05)
        ax.set_title(str(part), fontsize="medium")
    for ax in axes[len(parts):]:
        ax.set_visible(False)
    for ax in axes[::cols]:
        ax.set_ylabel("proportion correct")
    for j in range(min(cols, len(parts))):  # the lowest panel of each column: its axis named
        ax = axes[j + cols * ((len(parts) - 1 - j) // cols)]
        ax.xaxis.set_tick_params(labelbottom=True)
        ax.set_xlabel("blur-rate (arcmin/deg)")
    axes[0].legend(title="method", fontsize="x-small")
    fig.suptitle(f"{exp}: answers and ML fits per participant")
    figs._caption(fig, f"Marker area proportional to the trials at that blur-rate; "
                       f"n = {len(parts)} participants, {len(choices)} trials.")
    return fig


def threshold_figure(thresholds: pd.DataFrame, exp: str, stem: Path) -> list[Path]:
    """:func:`threshold_plot`, written as PNG and PDF."""
    return figs._save(threshold_plot(thresholds, exp), stem)


def threshold_plot(thresholds: pd.DataFrame, exp: str) -> Figure:
    """Each participant's threshold per method with its 95 % interval (ML fit)."""
    t = thresholds[thresholds["fit"] == "ml-bootstrap"]
    methods = _ordered(t["method"])
    parts = sorted(t["participant"].unique())
    fig = figs._figure(max(4.5, 1.6 * len(methods) + 2), 4.4)
    ax = fig.subplots()
    offsets = np.linspace(-0.3, 0.3, len(parts)) if len(parts) > 1 else np.zeros(1)
    for i, method in enumerate(methods):
        grp = t[t["method"] == method].set_index("participant").reindex(parts)
        x = i + offsets
        ax.errorbar(x, grp["threshold"], yerr=[grp["threshold"] - grp["ci_low"],
                                              grp["ci_high"] - grp["threshold"]],
                    fmt="o", ms=3, capsize=2, color=figs.METHOD_COLOURS.get(method))
    ax.set_yscale("log")
    ax.set_xticks(range(len(methods)))
    ax.set_xticklabels(methods)
    ax.set_xlabel("method")
    ax.set_ylabel(f"{THRESHOLD_PC:.0%} correct blur-rate (arcmin/deg)")
    figs._title(ax, fig, f"{exp}: forced-choice thresholds")
    figs._caption(fig, f"One point per participant (n = {len(parts)}), error bars 95 % "
                       "intervals (ML fit, parametric bootstrap).")
    return fig


def adjustment_plot(both: pd.DataFrame, r: float, exp: str) -> Figure:
    """Each participant and method who ran both tasks: the adjusted blur-rate against the
    forced-choice threshold (log axes, the identity line dashed)."""
    fig = figs._figure(4.8, 4.6)
    ax = fig.subplots()
    for method, grp in both.groupby("method", sort=True):
        ax.scatter(grp["adjusted"], grp["forced_choice"], label=str(method),
                   color=figs.METHOD_COLOURS.get(str(method)))
    lo = float(min(both["adjusted"].min(), both["forced_choice"].min())) / 1.2
    hi = float(max(both["adjusted"].max(), both["forced_choice"].max())) * 1.2
    ax.plot([lo, hi], [lo, hi], "k--", lw=0.8)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("adjusted blur-rate (arcmin/deg)")
    ax.set_ylabel(f"{THRESHOLD_PC:.0%}-correct threshold (arcmin/deg)")
    ax.legend(title="method", fontsize="small")
    figs._title(ax, fig, f"{exp} against the adjustment task")
    r_text = "n/a" if math.isnan(r) else f"{r:.2f}"
    figs._caption(fig, f"One point per participant and method (n = {len(both)}); Pearson r of "
                       f"the logs {r_text}; dashed: equal.")
    return fig


# -- the section -------------------------------------------------------------------------------

def forced_choice_section(ana: Analysis) -> list[str]:
    """Per forced-choice experiment: thresholds, comparisons, figures (module docstring)."""
    choices = with_choices(ana.data.trials)
    if not len(choices):
        return []
    thresholds = fit_thresholds(choices)
    fc = set(choices["experiment"])
    out = []
    for exp in sorted(fc):
        mine = choices[(choices["experiment"] == exp) & ~choices["practice"].astype(bool)]
        thr = thresholds[thresholds["experiment"] == exp] if len(thresholds) else thresholds
        missing = unfitted(mine, thr)
        if missing:
            ana.notes.append(f"{exp}: no psychometric fit for {', '.join(missing)} (answers "
                             "at fewer than two blur-rates)")
        if not len(thr):
            continue
        comp = compare_methods(thr)
        both, r = compare_with_adjustment(thr, ana.data.trials, fc)
        for name, frame in (("thresholds", thr), ("methods", comp), ("adjustment", both)):
            if len(frame):
                write_csv(frame, ana.tables / f"{exp}-{name}.csv", ana.files)
        if ana.figures:
            ana.files += psychometric_figure(mine, thr, exp, ana.fig_dir / f"{exp}-psychometric")
            ana.files += threshold_figure(thr, exp, ana.fig_dir / f"{exp}-thresholds")
            if len(both):
                ana.files += figs._save(adjustment_plot(both, r, exp),
                                        ana.fig_dir / f"{exp}-adjustment")
        out.append(_markdown(exp, thr, comp, both, r, ana.figures))
    return out


def _markdown(exp: str, thr: pd.DataFrame, comp: pd.DataFrame, both: pd.DataFrame, r: float,
              figures: bool) -> str:
    n = thr["participant"].nunique()
    fits = ", ".join(sorted(thr["fit"].unique()))
    parts = [f"## Forced choice: {exp}\n",
             "Task: two-alternative forced choice (which half is degraded), blur-rate from an "
             "adaptive procedure per method; the thresholds below were measured by this task, "
             "not by adjustment. Threshold: the blur-rate at "
             f"{THRESHOLD_PC:.0%} correct of a Weibull fitted per participant and method "
             f"({fits}; {n} participants).\n",
             md_table(thr.drop(columns=["log10_scale"]), units=THRESHOLD_UNITS)]
    if len(comp):
        parts += ["### Methods compared (log10 thresholds, paired by participant)\n",
                  "ratio: geometric-mean threshold ratio; posterior: 95 % credible interval "
                  "of the mean log10 difference (noninformative prior), p_positive its "
                  "probability above 0.\n",
                  md_table(comp, units={"n": "participants", "mean_log10_diff": "log10 units",
                                        "ratio": "dimensionless", "p": "probability",
                                        "posterior_low": "log10 units",
                                        "posterior_high": "log10 units",
                                        "p_positive": "probability"})]
        for _, row in comp.iterrows():
            parts.append(f"- {row['comparison']}: ratio {row['ratio']:.2f}, "
                         f"{p_text(float(row['p']))}.\n")
    if len(both):
        parts += ["### Beside the adjustment task\n",
                  "Adjusted: the participant's mean blur-rate in the adjustment validation; "
                  f"forced choice: this experiment's threshold. Pearson r of their logs: "
                  f"{'n/a (fewer than 3 pairs)' if math.isnan(r) else f'{r:.2f}'} "
                  f"({len(both)} pairs).\n",
                  md_table(both, units={"adjusted": "arcmin/deg",
                                        "forced_choice": "arcmin/deg"})]
        if figures:
            parts.append(f"![{exp} against adjustment](figures/{exp}-adjustment.png)\n")
    if figures:
        parts += [f"![{exp} psychometric](figures/{exp}-psychometric.png)\n",
                  f"![{exp} thresholds](figures/{exp}-thresholds.png)\n"]
    return "\n".join(parts)


__all__ = ["adjustment_plot", "compare_methods", "compare_with_adjustment", "fit_thresholds",
           "forced_choice_section", "psychometric_figure", "psychometric_plot", "threshold_figure",
           "threshold_plot"]
