"""12 against 64 impulses per kernel (paper section 6.3, Figure "kernels_density", right): the
validation repeated with 12 impulses (``protocols/validation-12.yaml``) keeps the advantage of
ours over contrast ("unchanged ... p < 0.001, t-test").

When the results hold validation experiments run with different impulse counts, this section
reports:

* ours against contrast at each impulse count (each experiment's paired t-test over all scenes,
  from its validation section);
* whether the advantage (ours - contrast blur-rate) differs between two impulse counts: a
  paired t-test of the per participant x scene advantages where the same participants saw the
  same scenes under both (pairs = participant x scene present in both); otherwise Welch's
  two-sample t-test on each participant's mean advantage (participants independent). A
  non-significant difference is not proof of equality; the 95 % CI of the difference says how
  large a change the data leave room for;
* the estimated sampling-rate reduction of ours over contrast per scene (eqs. 10-11:
  1 - blur_rate_contrast / blur_rate_ours) at each count, as the paper's bar plot.

An experiment's impulse count is its protocol's ``impulses`` (64 when the key is absent), read
from the protocol copy its ``session-*.json`` files record (docs/LOGS.md).
"""

from __future__ import annotations

import math
from itertools import combinations
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from fovexp.results.loading import impulse_count

from ..figures import _save
from ..stats import paired_ttest
from ..validation import ValidationResult
from .common import md_table, p_text, write_csv

if TYPE_CHECKING:
    from ..state import Analysis

DIFF_COLUMNS = ["a", "b", "test", "n", "mean_adv_a", "mean_adv_b", "mean_diff", "t", "df", "p",
                "ci_low", "ci_high"]


def advantages(trials: pd.DataFrame) -> pd.Series:
    """ours - contrast final blur-rate per (participant, image), repetitions averaged."""
    cell = trials.groupby(["participant", "image", "method"])["final_value"].mean()
    wide = cell.unstack("method")
    if not {"ours", "contrast"} <= set(wide.columns):
        return pd.Series(dtype=float)
    return (wide["ours"] - wide["contrast"]).dropna()


def difference_test(a_name: str, adv_a: pd.Series, b_name: str, adv_b: pd.Series) -> dict:
    """Whether the advantage differs between experiments a and b (module docstring)."""
    from scipy import stats

    common = adv_a.index.intersection(adv_b.index)
    parts_a = set(adv_a.index.get_level_values("participant"))
    parts_b = set(adv_b.index.get_level_values("participant"))
    row = {"a": a_name, "b": b_name, "mean_adv_a": float(adv_a.mean()),
           "mean_adv_b": float(adv_b.mean())}
    if parts_a == parts_b and len(common) >= 2:
        r = paired_ttest(adv_a.loc[common].to_numpy(), adv_b.loc[common].to_numpy())
        return {**row, "test": "paired (participant x scene)", "n": r.n,
                "mean_diff": r.mean_diff, "t": r.t, "df": r.df, "p": r.p, "ci_low": r.ci_low,
                "ci_high": r.ci_high}
    pa = adv_a.groupby(level="participant").mean().to_numpy()
    pb = adv_b.groupby(level="participant").mean().to_numpy()
    nan = math.nan
    out = {**row, "test": "Welch (participant means)", "n": f"{pa.size}+{pb.size}",
           "mean_diff": float(pa.mean() - pb.mean()) if pa.size and pb.size else nan,
           "t": nan, "df": nan, "p": nan, "ci_low": nan, "ci_high": nan}
    if pa.size >= 2 and pb.size >= 2:
        r = stats.ttest_ind(pa, pb, equal_var=False)
        ci = r.confidence_interval(0.95)
        out.update(t=float(r.statistic), df=float(r.df), p=float(r.pvalue),
                   ci_low=float(ci.low), ci_high=float(ci.high))
    return out


def sampling_figure(groups: list[tuple[int, ValidationResult]], stem: Path) -> list[Path]:
    """Grouped bars: the sampling-rate reduction per scene and over all scenes, one bar per
    impulse count (the paper's Figure "kernels_density", right)."""
    scopes = list(dict.fromkeys(s for _, r in groups for s in r.sampling["scope"]))
    fig = Figure(figsize=(max(5.5, 0.75 * len(scopes) + 2), 3.6))
    ax = fig.subplots()
    width = 0.8 / len(groups)
    x = np.arange(len(scopes))
    for k, (n, res) in enumerate(groups):
        vals = res.sampling.set_index("scope")["reduction_pct"].reindex(scopes)
        ax.bar(x + (k - (len(groups) - 1) / 2) * width, vals, width=width,
               label=f"{n} impulses ({res.experiment})", color=f"C{k}")
    ax.set_xticks(x)
    ax.set_xticklabels(scopes, rotation=45, ha="right")
    ax.axhline(0, color="black", linewidth=0.8)
    ax.set_ylabel("sampling-rate reduction (%)")
    ax.set_title("Ours vs contrast at each impulse count (section 6.3, eqs. 10-11)")
    ax.legend(fontsize="small")
    fig.tight_layout()
    fig.text(0.5, -0.02, "1 - blur-rate(contrast) / blur-rate(ours), from the means across "
             "participants; no error bars.", ha="center", va="top", fontsize="small")
    return _save(fig, stem)


def impulses_section(ana: Analysis) -> list[str]:
    """The comparison of impulse counts, when the validations ran with two or more."""
    counted: list[tuple[int, ValidationResult]] = []
    unknown = []
    for res in ana.validations:
        n = impulse_count(ana.data.root, res.experiment)  # a BIDS dataset's logs: read back
        if n is None:
            unknown.append(res.experiment)
        elif len(res.tests):
            counted.append((n, res))
    if len({n for n, _ in counted}) < 2:
        return []
    counted.sort(key=lambda g: (g[0], g[1].experiment))
    per_count = []
    for n, res in counted:
        main = res.tests.iloc[0]
        per_count.append({"impulses": n, "experiment": res.experiment, "n": int(main["n"]),
                          "mean_ours": main["mean_ours"], "mean_contrast": main["mean_contrast"],
                          "mean_diff": main["mean_diff"], "t": main["t"], "df": main["df"],
                          "p": main["p"], "d_z": main["d_z"]})
    per_count_df = pd.DataFrame(per_count)
    adv = {res.experiment: advantages(ana.data.experiment(res.experiment)) for _, res in counted}
    diffs = pd.DataFrame(
        [difference_test(ra.experiment, adv[ra.experiment], rb.experiment, adv[rb.experiment])
         for (na, ra), (nb, rb) in combinations(counted, 2) if na != nb],
        columns=DIFF_COLUMNS)
    sampling = pd.concat([r.sampling.assign(impulses=n, experiment=r.experiment)
                          for n, r in counted], ignore_index=True)
    wide = sampling.pivot_table(index="scope", columns="impulses", values="reduction_pct",
                                sort=False)
    wide.columns = [f"reduction_pct at {c}" for c in wide.columns]
    wide = wide.reset_index()
    for name, frame in (("per-count", per_count_df), ("difference", diffs),
                        ("sampling", sampling)):
        write_csv(frame, ana.tables / f"impulses-{name}.csv", ana.files)
    units = {"n": "pairs", "p": "probability", "mean_adv_a": "arcmin/deg",
             "mean_adv_b": "arcmin/deg", "impulses": "per kernel"}
    parts = ["## Impulses per kernel: 12 against 64 (section 6.3)\n",
             "Ours against contrast at each impulse count (paired t-test over all scenes, "
             "pairs = participant x scene):\n",
             md_table(per_count_df, units=units)]
    lines = []
    for r in diffs.itertuples():
        lines.append(f"- {r.a} vs {r.b}: advantage {r.mean_adv_a:.3f} vs {r.mean_adv_b:.3f} "
                     f"arcmin/deg; difference {r.mean_diff:.3f} [95% CI {r.ci_low:.3f}, "
                     f"{r.ci_high:.3f}], {r.test} t-test, {p_text(r.p)}.")
    parts += ["Does the advantage (ours - contrast) differ between the impulse counts? A paired "
              "t-test of the advantages per participant x scene where the same participants "
              "saw the same scenes in both experiments, else Welch's t-test on each "
              "participant's mean advantage. A non-significant result does not show the "
              "advantages equal; the CI bounds the change the data allow.\n",
              "\n".join(lines) + "\n",
              md_table(diffs, units=units),
              "Estimated sampling-rate reduction of ours over contrast (eqs. 10-11), per scene, "
              "at each impulse count:\n",
              md_table(wide, units={c: "%" for c in wide.columns if c != "scope"})]
    if ana.figures:
        ana.files += sampling_figure(counted, ana.fig_dir / "impulses-sampling")
        parts.append("![impulses](figures/impulses-sampling.png)\n")
    if unknown:
        parts.append(f"Note: no protocol copy recorded for {', '.join(unknown)}: its impulse "
                     "count is unknown, so it is not compared.\n")
    return ["\n".join(parts)]
