"""Validation experiment results (paper section 6.1, Figure "validation"; section 6.3, eq. 10).

Participants chose, per scene and method, the highest blur-rate at which foveation was not
visible. Reported here:

* per scene and method the mean blur-rate +- SEM across participants (each participant's
  repetitions averaged first);
* the paired t-test ``ours`` vs ``contrast``, paired by participant x scene, overall and per scene
  (pairs = participants), with t, df, p, Cohen's d_z and the 95 % CI of the mean difference; and,
  as a check that does not treat a participant's scenes as independent, the same test on each
  participant's mean over scenes. With one participant there is no test (its statistics are
  left out, and :attr:`ValidationResult.no_test` says why);
* the estimated sampling-rate reduction of ours over contrast, 1 - SR_ours / SR_contrast with
  SR_ours / SR_contrast = blur_rate_contrast / blur_rate_ours (section 6.3), from the mean
  blur-rates per scene and overall.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import pandas as pd

from fovexp import FovexpError
from fovexp.results.calibration import summarize

from .stats import paired_ttest, sampling_rate_ratio

TEST_COLUMNS = ["scope", "n", "mean_ours", "mean_contrast", "mean_diff", "sd_diff", "t", "df",
                "p", "d_z", "ci_low", "ci_high"]
#: the columns of a test's statistics (the others describe its pairs)
TEST_STATISTICS = ["sd_diff", "t", "df", "p", "d_z", "ci_low", "ci_high"]


@dataclass
class ValidationResult:
    """Section 6.1 results of one validation experiment."""

    experiment: str
    summary: pd.DataFrame  # image, method, mean, sem, n, n_trials
    overall: pd.DataFrame  # method, mean, sem, n, n_trials
    tests: pd.DataFrame  # TEST_COLUMNS; scope = "all scenes", "participant means", or a scene
    sampling: pd.DataFrame  # scope, blur_rate_contrast, blur_rate_ours, sr_ratio, reduction_pct
    notes: list[str] = field(default_factory=list)
    #: why no paired test was computed at all (fewer than two participants), else None
    no_test: str | None = None


def _test_row(scope: str, ours: pd.Series, contrast: pd.Series) -> dict:
    r = paired_ttest(ours.to_numpy(), contrast.to_numpy())
    return {"scope": scope, "n": r.n, "mean_ours": r.mean_a, "mean_contrast": r.mean_b,
            "mean_diff": r.mean_diff, "sd_diff": r.sd_diff, "t": r.t, "df": r.df, "p": r.p,
            "d_z": r.d_z, "ci_low": r.ci_low, "ci_high": r.ci_high}


def _sampling_row(scope: str, contrast: float, ours: float) -> dict:
    ratio = sampling_rate_ratio(ours, contrast)
    return {"scope": scope, "blur_rate_contrast": contrast, "blur_rate_ours": ours,
            "sr_ratio": ratio, "reduction_pct": 100.0 * (1.0 - ratio)}


#: the two methods the paired test (section 6.1) and the sampling-rate estimate (6.3) compare
COMPARED = ("ours", "contrast")


def missing_cells(trials: pd.DataFrame) -> pd.DataFrame:
    """Per scene, the compared methods (:data:`COMPARED`) it has no trials of, and per
    participant x scene, those the participant has none of where the scene has them from
    others: ``image``, ``participant`` (empty for the whole scene), ``missing``."""
    out = []
    have = trials.groupby("image")["method"].agg(lambda m: set(map(str, m)))
    for scene, methods in have.items():
        gone = [m for m in COMPARED if m not in methods]
        if gone:
            out.append({"image": str(scene), "participant": "", "missing": ", ".join(gone)})
    per = trials.groupby(["image", "participant"])["method"].agg(lambda m: set(map(str, m)))
    for (scene, pid), methods in per.items():
        gone = [m for m in COMPARED if m in have[scene] and m not in methods]
        if gone:
            out.append({"image": str(scene), "participant": str(pid),
                        "missing": ", ".join(gone)})
    return pd.DataFrame(out, columns=["image", "participant", "missing"])


def validate(trials: pd.DataFrame, experiment: str = "validation") -> ValidationResult:
    """Section 6.1 statistics from the trials of one validation experiment, as far as the
    data go: the means of every scene and method there are; the paired tests and the
    sampling-rate estimate from the participant x scene cells with both compared methods, and
    notes naming the scenes and cells without them (partial data never stop the report)."""
    sel = trials[trials["adjusted_parameter"] == "blur_rate"]
    if sel.empty:
        raise FovexpError(f"{experiment}: no trials adjusting blur_rate")
    notes: list[str] = []
    summary = summarize(sel, ["image", "method"])
    overall = summarize(sel, ["method"])
    cell = sel.groupby(["participant", "image", "method"])["final_value"].mean().unstack("method")
    tests: list[dict] = []
    sampling: list[dict] = []
    no_test: str | None = None
    if set(COMPARED) <= set(cell.columns):
        gaps = missing_cells(sel)
        for _, g in gaps[gaps["participant"] == ""].iterrows():
            notes.append(f"scene {g['image']} has no trials of {g['missing']}: no paired test "
                         "or sampling-rate estimate for it")
        lone = gaps[gaps["participant"] != ""]
        if len(lone):
            listed = "; ".join(f"{g['participant']} x {g['image']} lacks {g['missing']}"
                               for _, g in lone.iterrows())
            notes.append(f"{len(lone)} participant x scene cell(s) lack one of the compared "
                         f"methods and are left out of the paired tests ({listed})")
        pairs = cell[list(COMPARED)]
        pairs = pairs[~pairs.isna().any(axis=1)]
        if pairs.empty:
            notes.append("no participant x scene has both ours and contrast: no paired t-test "
                         "or sampling-rate estimate")
        else:
            tests.append(_test_row("all scenes", pairs["ours"], pairs["contrast"]))
            per_part = pairs.groupby(level="participant").mean()
            tests.append(_test_row("participant means", per_part["ours"],
                                   per_part["contrast"]))
            for scene, grp in pairs.groupby(level="image", sort=True):
                tests.append(_test_row(str(scene), grp["ours"], grp["contrast"]))
            if len(per_part) < 2:
                no_test = one_participant_reason(str(per_part.index[0]))
                for row in tests:  # the means stay; no statistic of a single participant
                    row.update(dict.fromkeys(TEST_STATISTICS, float("nan")))
            sampling.append(_sampling_row("all scenes", float(pairs["contrast"].mean()),
                                          float(pairs["ours"].mean())))
            means = summary.pivot(index="image", columns="method", values="mean")
            for scene, row in means.iterrows():
                if pd.notna(row["contrast"]) and pd.notna(row["ours"]):
                    sampling.append(_sampling_row(str(scene), float(row["contrast"]),
                                                  float(row["ours"])))
    else:
        notes.append("ours and contrast are not both present: no t-test or sampling-rate "
                     f"estimate (methods: {', '.join(map(str, cell.columns))})")
    return ValidationResult(
        experiment=experiment, summary=summary, overall=overall,
        tests=pd.DataFrame(tests, columns=TEST_COLUMNS),
        sampling=pd.DataFrame(sampling, columns=["scope", "blur_rate_contrast", "blur_rate_ours",
                                                 "sr_ratio", "reduction_pct"]),
        notes=notes, no_test=no_test,
    )


def one_participant_reason(participant: str) -> str:
    """Why there is no paired test with one participant, in words for the report."""
    return (f"No paired t-test: ours and contrast are compared within each participant, and the "
            f"test asks whether that difference holds across participants, which needs at least "
            f"two; these trials are from one participant ({participant}). The means above "
            f"describe that participant only.")
