"""The validation sections (paper sections 6.1 and 6.3): one per experiment whose trials
adjust the blur-rate."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import pandas as pd

from fovexp.results.choices import forced_choice_experiments

from .. import figures as figs
from ..validation import TEST_STATISTICS, ValidationResult, validate
from .common import BLUR_UNITS, md_table, p_text, write_csv

if TYPE_CHECKING:
    from ..state import Analysis


def validation_experiments(ana: Analysis) -> list[str]:
    """The experiments analysed as validations: their trials adjust the blur-rate (a
    forced-choice experiment's rows name the blur-rate too, and have their own section)."""
    t = ana.data.trials
    forced = forced_choice_experiments(t)
    return sorted(set(t.loc[t["adjusted_parameter"] == "blur_rate", "experiment"]) - forced)


def validation_sections(ana: Analysis) -> list[str]:
    """Per validation experiment: its tables, t-tests, sampling-rate reduction and figures
    (appended to ``ana.validations``)."""
    out = []
    for exp in validation_experiments(ana):
        res = validate(ana.data.experiment(exp), exp)
        ana.validations.append(res)
        for name, frame in (("summary", res.summary), ("overall", res.overall),
                            ("tests", res.tests), ("sampling", res.sampling)):
            write_csv(frame, ana.tables / f"{exp}-{name}.csv", ana.files)
        if ana.figures:
            ana.files += figs.validation_figure(res, ana.fig_dir / exp)
            if len(res.sampling):
                ana.files += figs.sampling_figure(res, ana.fig_dir / f"{exp}-sampling")
        out.append(_validation_md(res, ana.figures))
    return out


#: what marks a statistic that was not computed, in the report's test tables
NOT_COMPUTED = "n/a"


def testable(row: pd.Series) -> bool:
    """Whether a test row has its statistics: at least two pairs that do not all differ by
    the same amount (else t is infinite or undefined), from at least two participants."""
    return bool(row["n"] >= 2 and math.isfinite(row["t"]))


def untestable_reason(row: pd.Series) -> str:
    """Why a row has no test, in a few words."""
    if row["n"] < 2:
        return "fewer than two pairs, and a paired test needs at least two"
    if row["sd_diff"] == 0:
        return "every pair differs by the same amount: no variance to test against"
    return "one participant: a paired test needs at least two"


def marked_tests(tests: pd.DataFrame, no_test: str | None = None,
                 ) -> tuple[pd.DataFrame, list[str]]:
    """The test table as the report shows it: in each row without a test (:func:`testable`)
    t, df, p and d_z, and any other statistic that is missing or infinite, read
    :data:`NOT_COMPUTED` (never ``nan``); and the reasons, once each (``no_test``: there is no
    test at all, for the reason the report gives above the table)."""
    out = tests.astype(object)
    why: list[str] = ["one participant: a paired test needs at least two"] if no_test else []
    for i, row in tests.iterrows():
        if testable(row):
            continue
        for col in TEST_STATISTICS:
            v = row[col]
            if col in ("t", "df", "p", "d_z") or not math.isfinite(float(v)):
                out.at[i, col] = NOT_COMPUTED
        reason = untestable_reason(row)
        if not no_test and reason not in why:
            why.append(reason)
    return out, why


def _validation_md(res: ValidationResult, figures: bool) -> str:
    parts = [f"## Validation: {res.experiment} (section 6.1)\n",
             "Task: adjustment (each participant set the blur-rate until the loss of detail "
             "was just invisible).\n",
             "Mean selected blur-rate ± SEM across participants, per scene and method:\n",
             md_table(res.summary, units=BLUR_UNITS),
             "Over all scenes (each participant's mean over scenes):\n",
             md_table(res.overall, units=BLUR_UNITS)]
    if len(res.tests):
        main = res.tests.iloc[0]
        marked, why = marked_tests(res.tests, res.no_test)
        parts += [
            "### Paired t-test, ours vs contrast\n",
            (res.no_test or "All scenes, paired by participant x scene: " + (
                f"t({int(main['df'])}) = {main['t']:.2f}, {p_text(main['p'])}, d_z = "
                f"{main['d_z']:.2f}, mean difference {main['mean_diff']:.3f} [95% CI "
                f"{main['ci_low']:.3f}, {main['ci_high']:.3f}] arcmin/deg."
                if testable(main) else f"no test ({untestable_reason(main)}).")) + "\n",
            "Rows: all scenes (pairs = participant x scene), participant means (pairs = "
            "participants, scenes averaged; does not count a participant's scenes as "
            "independent), then each scene (pairs = participants).\n",
            md_table(marked, units={"n": "pairs", "p": "probability"}),
            *([f"n/a: {'; '.join(why)}.\n"] if why else []),
            "### Estimated sampling-rate reduction (section 6.3)\n",
            "SR_ours / SR_contrast = blur_rate_contrast / blur_rate_ours; reduction = 1 - ratio.\n",
            md_table(res.sampling),
        ]
    for n in res.notes:
        parts.append(f"Note: {n}\n")
    if figures:
        parts.append(f"![{res.experiment}](figures/{res.experiment}.png)\n")
        if len(res.sampling):
            parts.append(f"![{res.experiment} sampling](figures/{res.experiment}-sampling.png)\n")
    return "\n".join(parts)
