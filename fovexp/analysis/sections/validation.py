"""The validation sections (paper sections 6.1 and 6.3): one per experiment whose trials
adjust the blur-rate."""

from __future__ import annotations

from typing import TYPE_CHECKING

from .. import figures as figs
from ..validation import ValidationResult, validate
from .common import BLUR_UNITS, md_table, p_text, write_csv

if TYPE_CHECKING:
    from ..state import Analysis


def validation_experiments(ana: Analysis) -> list[str]:
    """The experiments analysed as validations: their trials adjust the blur-rate."""
    t = ana.data.trials
    return sorted(set(t.loc[t["adjusted_parameter"] == "blur_rate", "experiment"]))


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


def _validation_md(res: ValidationResult, figures: bool) -> str:
    parts = [f"## Validation: {res.experiment} (section 6.1)\n",
             "Mean selected blur-rate ± SEM across participants, per scene and method:\n",
             md_table(res.summary, units=BLUR_UNITS),
             "Over all scenes (each participant's mean over scenes):\n",
             md_table(res.overall, units=BLUR_UNITS)]
    if len(res.tests):
        main = res.tests.iloc[0]
        parts += [
            "### Paired t-test, ours vs contrast\n",
            f"All scenes, paired by participant x scene: t({int(main['df'])}) = "
            f"{main['t']:.2f}, {p_text(main['p'])}, d_z = {main['d_z']:.2f}, mean difference "
            f"{main['mean_diff']:.3f} [95% CI {main['ci_low']:.3f}, {main['ci_high']:.3f}] "
            "arcmin/deg.\n",
            "Rows: all scenes (pairs = participant x scene), participant means (pairs = "
            "participants, scenes averaged; does not count a participant's scenes as "
            "independent), then each scene (pairs = participants).\n",
            md_table(res.tests, units={"n": "pairs", "p": "probability"}),
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
