"""``fovexp analyze``: trial logs -> tables, figures, statistics and a Markdown report, also as
an HTML page (paper sections 5.3, 6.1 and 6.3).

The report says at its top when its data come from dry runs (simulated participants) or
include mouse-gaze pilots. Every table column with a unit names it in its header; f_e, s_k and
s_f are dimensionless; every mean comes with its SEM across participants and n.

Output folder layout::

    report.md                      everything below, gathered, with the exclusions
    report.html                    the same as a page (readable offline; the figures' PNGs)
    table2.yaml                    the lab's Table 2 as a ParameterTable (the enhancer reads it)
    tables/table2.{csv,md,tex}
    tables/calibration-fe.csv, calibration-sk.csv, calibration-sk-lines.csv, calibration-sf.csv
    tables/<experiment>-summary.csv, -overall.csv, -tests.csv, -sampling.csv
    tables/exclusions.csv
    tables/latency.csv             gaze-to-flip latency and the blanking rule per session
    figures/calibration.{png,pdf}, <experiment>.{png,pdf}, <experiment>-sampling.{png,pdf}
    figures/latency.{png,pdf}
"""

from __future__ import annotations

from collections.abc import Mapping
from datetime import datetime, timezone
from pathlib import Path

import pandas as pd

from fovexp import FovexpError
from fovexp.results.choices import forced_choice_experiments
from fovexp.results.format import PILOT_TRACKER, SIMULATED_TRACKER
from fovexp.results.loading import TrialLimits, load_results, rules

from .html import write_report_html
from .sections import SECTIONS
from .sections.calibration import CALIBRATION_EXPERIMENTS
from .sections.common import md_table
from .sections.validation import validation_experiments
from .state import Analysis


def run_analysis(
    results: str | Path,
    out: str | Path,
    *,
    include_incomplete: bool = False,
    include_pilots: bool = False,
    protocol: Mapping[str, str] | None = None,
    limits: TrialLimits | None = None,
    figures: bool = True,
    table_source: str | None = None,
) -> Analysis:
    """Analyse every experiment under ``results`` and write the report into ``out``.

    Calibration (section 5.3) needs calibration-fe, -sk and -sf; every experiment whose trials
    adjust the blur-rate is analysed as a validation experiment (section 6.1). The exclusion
    rules and their options: :func:`fovexp.results.loading.load_results`. The report's
    sections, in order: :data:`fovexp.analysis.sections.SECTIONS`.
    """
    results = Path(results)
    out = Path(out)
    limits = limits or TrialLimits()
    data = load_results(results, include_incomplete=include_incomplete,
                        include_pilots=include_pilots, protocol=protocol, limits=limits)
    ana = Analysis(data=data, out=out, results=results, limits=limits, figures=figures,
                   table_source=table_source)
    ana.tables.mkdir(parents=True, exist_ok=True)

    sections: list[str] = []
    for section in SECTIONS:
        sections += section(ana)

    analysed = (set(CALIBRATION_EXPERIMENTS) | set(validation_experiments(ana))
                | forced_choice_experiments(data.trials))
    other = [e for e in data.experiments if e not in analysed]
    if other:
        ana.notes.append(f"experiments not analysed (no analysis defined): {', '.join(other)}")

    excl = pd.DataFrame([e.__dict__ for e in data.exclusions],
                        columns=["rule", "experiment", "participant", "session", "n_trials",
                                 "file", "detail"])
    excl.to_csv(ana.tables / "exclusions.csv", index=False)
    ana.files.append(ana.tables / "exclusions.csv")

    text = _report_md(ana, sections, results)
    ana.report.write_text(text)
    ana.files.append(ana.report)
    ana.files.append(write_report_html(text, ana.out / "report.html"))  # the same, as a page
    return ana


def _report_md(ana: Analysis, sections: list[str], results: Path) -> str:
    t = ana.data.trials
    overview = (t.groupby("experiment")
                .agg(participants=("participant", "nunique"), sessions=("session", "nunique"),
                     trials=("trial_index", "size"),
                     protocol=("protocol_sha256", lambda s: ", ".join(sorted({v[:12] for v in s}))))
                .reset_index())
    parts = [
        "# fovexp analysis report\n",
        *_data_warnings(t),
        f"Results folder: `{results}` ({len(ana.data.files)} trials.csv files). "
        f"Generated {datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC.\n",
        "## Data included\n",
        md_table(overview),
        *sections,
        "## Exclusions\n",
        "Rules, applied in this order (docs/ANALYSIS.md):\n",
        *[f"- **{rule}**: {text}" for rule, text in rules(ana.limits).items()],
        "",
    ]
    excl = [e for e in ana.data.exclusions if e.rule != "note"]
    if excl:
        frame = pd.DataFrame([{"rule": e.rule, "experiment": e.experiment,
                               "participant": e.participant, "session": e.session,
                               "trials": e.n_trials, "file": _rel(e.file, ana.data.root),
                               "detail": e.detail} for e in excl])
        counts = frame.groupby("rule")["trials"].sum().reset_index()
        parts += ["Trials removed per rule:\n", md_table(counts)]
        # Practice exclusions are expected in every session: counted above, listed in the CSV.
        details = frame[frame["rule"] != "R4 practice"]
        if len(details):
            parts += ["Details (practice trials per session: `tables/exclusions.csv`):\n",
                      md_table(details)]
    else:
        parts.append("Nothing was excluded.\n")
    notes = [f"{e.file}: {e.detail}" for e in ana.data.exclusions if e.rule == "note"]
    notes += ana.data.notes + ana.notes
    if notes:
        parts += ["### Notes\n", *[f"- {n}" for n in notes], ""]
    return "\n".join(parts)




def _data_warnings(trials: pd.DataFrame) -> list[str]:
    """What the report must say before any result: data from dry runs (simulated
    participants), and mouse-gaze pilots kept with ``--include-pilots``."""
    out = []
    n = len(trials)
    sim = int((trials["tracker"] == SIMULATED_TRACKER).sum())
    pilots = int((trials["tracker"] == PILOT_TRACKER).sum())
    if sim:
        out.append(f"> **{'All' if sim == n else f'{sim} of {n}'} trials come from dry runs: "
                   "simulated participants, not people.** Nothing below is a measurement of "
                   "vision; it shows that the pipeline runs.\n")
    if pilots:
        out.append(f"> **{pilots} of {n} trials come from mouse-gaze pilot sessions** (no eye "
                   "tracker; kept with --include-pilots).\n")
    return out


def _rel(path: str, root: Path) -> str:
    """``path`` relative to the results folder where it lies inside it (shorter tables)."""
    try:
        return str(Path(path).relative_to(root))
    except ValueError:
        return path


def analyze(results: str | Path, out: str | Path, **kwargs: object) -> Analysis:
    """Alias of :func:`run_analysis` (the ``fovexp analyze`` command)."""
    try:
        return run_analysis(results, out, **kwargs)  # type: ignore[arg-type]
    except OSError as exc:
        raise FovexpError(f"{exc.filename or out}: {exc.strerror}") from None
