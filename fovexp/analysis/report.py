"""``fovexp analyze``: trial logs -> tables, figures, statistics and a Markdown report
(paper sections 5.3, 6.1 and 6.3).

The report says at its top when its data come from dry runs (simulated participants) or
include mouse-gaze pilots. Every table column with a unit names it in its header; f_e, s_k and
s_f are dimensionless; every mean comes with its SEM across participants and n.

Output folder layout::

    report.md                      everything below, gathered, with the exclusions
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

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

import pandas as pd

from fovexp import PAPER_TABLE2, FovexpError
from fovexp.results.calibration import Calibration, calibrate, fe_summary, sk_lines, sk_summary
from fovexp.results.format import PILOT_TRACKER, SIMULATED_TRACKER
from fovexp.results.loading import Dataset, TrialLimits, load_results, rules

from . import figures as figs
from .latency import session_latency
from .tables import table2_markdown, write_table2
from .validation import ValidationResult, validate

CALIBRATION_EXPERIMENTS = ("calibration-fe", "calibration-sk", "calibration-sf")

#: The unit of each column the report's tables show, by column name ("dimensionless": a pure
#: number; counts named for what they count, such as ``participants``, need none); a table
#: passes its own for the columns whose unit depends on it (``mean``, ``sem``, ``n``).
UNITS: dict[str, str] = {
    "blur_rate": "arcmin/deg", "blur_rate_contrast": "arcmin/deg",
    "blur_rate_ours": "arcmin/deg", "mean_ours": "arcmin/deg", "mean_contrast": "arcmin/deg",
    "mean_diff": "arcmin/deg", "sd_diff": "arcmin/deg", "ci_low": "arcmin/deg",
    "ci_high": "arcmin/deg", "f_e": "dimensionless", "s_k": "dimensionless",
    "s_f": "dimensionless", "s_f_sem": "dimensionless", "s_k_sem": "dimensionless",
    "slope": "s_k per unit s_f", "intercept": "dimensionless", "r2": "dimensionless",
    "sr_ratio": "dimensionless", "reduction_pct": "%", "median_ms": "ms", "p95_ms": "ms",
    "max_ms": "ms", "dropped_pct": "%", "with_gaze": "frames", "rule_violations": "frames",
    "n_trials": "trials", "n_levels": "s_f levels", "t": "dimensionless",
    "d_z": "dimensionless", "df": "degrees of freedom",
}


@dataclass
class Analysis:
    """Everything ``fovexp analyze`` computed, and the files it wrote."""

    data: Dataset
    out: Path
    calibration: Calibration | None = None
    validations: list[ValidationResult] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    files: list[Path] = field(default_factory=list)
    limits: TrialLimits = field(default_factory=TrialLimits)

    @property
    def report(self) -> Path:
        return self.out / "report.md"


def _md_table(frame: pd.DataFrame, digits: int = 3, units: Mapping[str, str] | None = None,
              ) -> str:
    """A DataFrame as a Markdown table (floats to ``digits`` significant decimals), each column
    header with its unit (:data:`UNITS`, then ``units``)."""
    known = {**UNITS, **(units or {})}
    def cell(v: object) -> str:
        if isinstance(v, float):
            if math.isnan(v):
                return ""
            if abs(v) < 1e-3 and v != 0:
                return f"{v:.2e}"
            return f"{v:.{digits}f}"
        return str(v)
    head = "| " + " | ".join(f"{c} ({known[c]})" if c in known else str(c)
                             for c in frame.columns) + " |"
    rule = "|" + "---|" * len(frame.columns)
    body = ["| " + " | ".join(cell(v) for v in row) + " |" for row in frame.itertuples(False)]
    return "\n".join([head, rule, *body]) + "\n"


def _p(p: float) -> str:
    return "n/a" if math.isnan(p) else ("p < 0.001" if p < 0.001 else f"p = {p:.3f}")


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
    rules and their options: :func:`fovexp.results.loading.load_results`.
    """
    results = Path(results)
    out = Path(out)
    limits = limits or TrialLimits()
    data = load_results(results, include_incomplete=include_incomplete,
                        include_pilots=include_pilots, protocol=protocol, limits=limits)
    ana = Analysis(data=data, out=out, limits=limits)
    tables = out / "tables"
    fig_dir = out / "figures"
    tables.mkdir(parents=True, exist_ok=True)

    present = [e for e in CALIBRATION_EXPERIMENTS if not data.experiment(e).empty]
    sections: list[str] = []
    if len(present) == 3:
        calib = calibrate(*(data.experiment(e) for e in CALIBRATION_EXPERIMENTS))
        ana.calibration = calib
        source = table_source or f"fovexp analyze {results} ({datetime.now(timezone.utc):%Y-%m-%d})"
        paths = write_table2(calib, tables, source, yaml_path=out / "table2.yaml")
        ana.files += list(paths.values())
        for name, frame in (("calibration-fe", calib.fe), ("calibration-sk", calib.sk),
                            ("calibration-sf", calib.sf), ("calibration-sk-lines",
                                                           _lines_frame(calib))):
            frame.to_csv(tables / f"{name}.csv", index=False, float_format="%.6g")
            ana.files.append(tables / f"{name}.csv")
        if figures:
            ana.files += figs.calibration_figure(calib, fig_dir / "calibration")
        sections.append(_calibration_md(calib, figures))
    elif present:
        # Partial calibration: report what can be computed, say what is missing.
        missing = [e for e in CALIBRATION_EXPERIMENTS if e not in present]
        ana.notes.append(f"calibration incomplete: no trials of {', '.join(missing)}; "
                         "Table 2 not computed")
        parts = ["## Calibration (section 5.3)\n",
                 f"Table 2 needs all three calibration experiments; missing: "
                 f"{', '.join(missing)}.\n"]
        if "calibration-fe" in present:
            fe = fe_summary(data.experiment("calibration-fe"))
            fe.to_csv(tables / "calibration-fe.csv", index=False, float_format="%.6g")
            parts += ["### f_e per blur-rate\n", _md_table(fe, units=_FE_UNITS)]
        if "calibration-sk" in present:
            sk = sk_summary(data.experiment("calibration-sk"))
            sk.to_csv(tables / "calibration-sk.csv", index=False, float_format="%.6g")
            lines = _lines_frame_from(sk_lines(sk))
            parts += ["### s_k per (blur-rate, s_f)\n", _md_table(sk, units=_SK_UNITS),
                      "### s_k = slope * s_f + intercept\n", _md_table(lines)]
        sections.append("\n".join(parts))

    validation_exps = sorted(set(data.trials.loc[data.trials["adjusted_parameter"] == "blur_rate",
                                                 "experiment"]))
    for exp in validation_exps:
        res = validate(data.experiment(exp), exp)
        ana.validations.append(res)
        for name, frame in (("summary", res.summary), ("overall", res.overall),
                            ("tests", res.tests), ("sampling", res.sampling)):
            frame.to_csv(tables / f"{exp}-{name}.csv", index=False, float_format="%.6g")
            ana.files.append(tables / f"{exp}-{name}.csv")
        if figures:
            ana.files += figs.validation_figure(res, fig_dir / exp)
            if len(res.sampling):
                ana.files += figs.sampling_figure(res, fig_dir / f"{exp}-sampling")
        sections.append(_validation_md(res, figures))

    sections.append(_latency_section(ana, tables, fig_dir, figures))

    other = [e for e in data.experiments
             if e not in CALIBRATION_EXPERIMENTS and e not in validation_exps]
    if other:
        ana.notes.append(f"experiments not analysed (no analysis defined): {', '.join(other)}")

    excl = pd.DataFrame([e.__dict__ for e in data.exclusions],
                        columns=["rule", "experiment", "participant", "session", "n_trials",
                                 "file", "detail"])
    excl.to_csv(tables / "exclusions.csv", index=False)
    ana.files.append(tables / "exclusions.csv")

    text = _report_md(ana, sections, results)
    ana.report.write_text(text)
    ana.files.append(ana.report)
    return ana


def _latency_section(ana: Analysis, tables: Path, fig_dir: Path, figures: bool) -> str:
    """The gaze-to-flip latency per session (frame logs; :mod:`fovexp.analysis.latency`)."""
    table, lat, notes = session_latency(ana.data)
    table.to_csv(tables / "latency.csv", index=False, float_format="%.6g")
    ana.files.append(tables / "latency.csv")
    parts = ["## Gaze-to-flip latency and blanking (section 5.1)\n",
             "Per session, from its frame log: the time from the newest gaze sample a frame's "
             "blanking decision used to the frame's flip, on the tracker's clock (median, 95th "
             "percentile, maximum), the dropped frames, and the frames drawn with the stimulus "
             "although the newest sample was invalid, outside the blanking radius, or older "
             "than the gaze timeout when the frame was decided (after the previous flip; "
             "`rule_violations`: 0 in a valid session).\n"]
    if len(table):
        parts.append(_md_table(table, 2, units={"n": "participants"}))
        if figures and lat:
            ana.files += figs.latency_figure(lat, fig_dir / "latency")
            parts.append("![Gaze-to-flip latency](figures/latency.png)\n")
    else:
        parts.append("No frame log with gaze samples.\n")
    parts += [f"Note: {n}\n" for n in notes]
    return "\n".join(parts)


def _lines_frame_from(lines: Mapping) -> pd.DataFrame:
    return pd.DataFrame([{"blur_rate": br, "slope": ln.slope, "intercept": ln.intercept,
                          "r2": ln.r2, "n_levels": ln.n} for br, ln in sorted(lines.items())])


def _lines_frame(calib: Calibration) -> pd.DataFrame:
    return _lines_frame_from(calib.lines)


def _calibration_md(calib: Calibration, figures: bool) -> str:
    paper = pd.DataFrame([r.model_dump() for r in PAPER_TABLE2.rows])
    parts = [
        "## Calibration (section 5.3)\n",
        "Means ± SEM across participants (each participant's images and repetitions averaged "
        "first).\n",
        "### Table 2: parameters per foveation level\n",
        table2_markdown(calib.table),
        "Files: `tables/table2.csv`, `tables/table2.md`, `tables/table2.tex`; the enhancer reads "
        "`table2.yaml` (ParameterTable).\n",
        "The paper's Table 2 for comparison:\n",
        _md_table(paper, 2),
        "### f_e per blur-rate (calibration-fe)\n",
        _md_table(calib.fe, units=_FE_UNITS),
        "### s_k per (blur-rate, s_f) (calibration-sk)\n",
        _md_table(calib.sk, units=_SK_UNITS),
        "Least-squares line s_k = slope * s_f + intercept per blur-rate (fitted to the means "
        "above; calibration-sf sets s_k with it):\n",
        _md_table(_lines_frame(calib)),
        "### Final s_f and its s_k (calibration-sf)\n",
        "s_k is the group line at the mean s_f; its SEM is sqrt((slope x SEM(s_f))^2 + "
        "SEM_line^2), SEM_line = SEM across participants of their own lines at that s_f.\n",
        _md_table(calib.sf, units={"n": "participants"}),
    ]
    if figures:
        parts.append("![Calibration results](figures/calibration.png)\n")
    return "\n".join(parts)


def _validation_md(res: ValidationResult, figures: bool) -> str:
    parts = [f"## Validation: {res.experiment} (section 6.1)\n",
             "Mean selected blur-rate ± SEM across participants, per scene and method:\n",
             _md_table(res.summary, units=_BLUR_UNITS),
             "Over all scenes (each participant's mean over scenes):\n",
             _md_table(res.overall, units=_BLUR_UNITS)]
    if len(res.tests):
        main = res.tests.iloc[0]
        parts += [
            "### Paired t-test, ours vs contrast\n",
            f"All scenes, paired by participant x scene: t({int(main['df'])}) = "
            f"{main['t']:.2f}, {_p(main['p'])}, d_z = {main['d_z']:.2f}, mean difference "
            f"{main['mean_diff']:.3f} [95% CI {main['ci_low']:.3f}, {main['ci_high']:.3f}] "
            "arcmin/deg.\n",
            "Rows: all scenes (pairs = participant x scene), participant means (pairs = "
            "participants, scenes averaged; does not count a participant's scenes as "
            "independent), then each scene (pairs = participants).\n",
            _md_table(res.tests, units={"n": "pairs", "p": "probability"}),
            "### Estimated sampling-rate reduction (section 6.3)\n",
            "SR_ours / SR_contrast = blur_rate_contrast / blur_rate_ours; reduction = 1 - ratio.\n",
            _md_table(res.sampling),
        ]
    for n in res.notes:
        parts.append(f"Note: {n}\n")
    if figures:
        parts.append(f"![{res.experiment}](figures/{res.experiment}.png)\n")
        if len(res.sampling):
            parts.append(f"![{res.experiment} sampling](figures/{res.experiment}-sampling.png)\n")
    return "\n".join(parts)


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
        _md_table(overview),
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
                               "trials": e.n_trials, "file": _rel(e.file, results),
                               "detail": e.detail} for e in excl])
        counts = frame.groupby("rule")["trials"].sum().reset_index()
        parts += ["Trials removed per rule:\n", _md_table(counts)]
        # Practice exclusions are expected in every session: counted above, listed in the CSV.
        details = frame[frame["rule"] != "R4 practice"]
        if len(details):
            parts += ["Details (practice trials per session: `tables/exclusions.csv`):\n",
                      _md_table(details)]
    else:
        parts.append("Nothing was excluded.\n")
    notes = [f"{e.file}: {e.detail}" for e in ana.data.exclusions if e.rule == "note"]
    notes += ana.data.notes + ana.notes
    if notes:
        parts += ["### Notes\n", *[f"- {n}" for n in notes], ""]
    return "\n".join(parts)


_FE_UNITS = {"mean": "f_e, dimensionless", "sem": "f_e, dimensionless", "n": "participants"}
_SK_UNITS = {"mean": "s_k, dimensionless", "sem": "s_k, dimensionless", "n": "participants"}
_BLUR_UNITS = {"mean": "arcmin/deg", "sem": "arcmin/deg", "n": "participants"}


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
