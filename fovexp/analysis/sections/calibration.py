"""The calibration section (paper section 5.3): Table 2 from calibration-fe, -sk and -sf, or
what can be computed when one of them is missing."""

from __future__ import annotations

from collections.abc import Mapping
from datetime import datetime, timezone
from typing import TYPE_CHECKING

import pandas as pd

from fovexp import PAPER_TABLE2
from fovexp.results.calibration import Calibration, calibrate, fe_summary, sk_lines, sk_summary

from .. import figures as figs
from ..tables import table2_markdown, write_table2
from .common import FE_UNITS, SK_UNITS, md_table, write_csv

if TYPE_CHECKING:
    from ..state import Analysis

CALIBRATION_EXPERIMENTS = ("calibration-fe", "calibration-sk", "calibration-sf")


def calibration_section(ana: Analysis) -> list[str]:
    """Table 2, its three experiments' tables and the calibration figure (sets
    ``ana.calibration``); with one or two of the experiments, their own tables and what is
    missing; nothing without any."""
    data = ana.data
    present = [e for e in CALIBRATION_EXPERIMENTS if not data.experiment(e).empty]
    if not present:
        return []
    if len(present) < 3:
        return [_partial(ana, present)]
    calib = calibrate(*(data.experiment(e) for e in CALIBRATION_EXPERIMENTS))
    ana.calibration = calib
    source = ana.table_source or (f"fovexp analyze {ana.results} "
                                  f"({datetime.now(timezone.utc):%Y-%m-%d})")
    paths = write_table2(calib, ana.tables, source, yaml_path=ana.out / "table2.yaml")
    ana.files += list(paths.values())
    for name, frame in (("calibration-fe", calib.fe), ("calibration-sk", calib.sk),
                        ("calibration-sf", calib.sf),
                        ("calibration-sk-lines", lines_frame(calib.lines))):
        write_csv(frame, ana.tables / f"{name}.csv", ana.files)
    if ana.figures:
        ana.files += figs.calibration_figure(calib, ana.fig_dir / "calibration")
    return [_calibration_md(calib, ana.figures)]


def _partial(ana: Analysis, present: list[str]) -> str:
    """A calibration with an experiment missing: report what can be computed, say what is
    missing."""
    data = ana.data
    missing = [e for e in CALIBRATION_EXPERIMENTS if e not in present]
    ana.notes.append(f"calibration incomplete: no trials of {', '.join(missing)}; "
                     "Table 2 not computed")
    parts = ["## Calibration (section 5.3)\n",
             f"Table 2 needs all three calibration experiments; missing: "
             f"{', '.join(missing)}.\n"]
    if "calibration-fe" in present:
        fe = fe_summary(data.experiment("calibration-fe"))
        write_csv(fe, ana.tables / "calibration-fe.csv", ana.files)
        parts += ["### f_e per blur-rate\n", md_table(fe, units=FE_UNITS)]
    if "calibration-sk" in present:
        sk = sk_summary(data.experiment("calibration-sk"))
        write_csv(sk, ana.tables / "calibration-sk.csv", ana.files)
        parts += ["### s_k per (blur-rate, s_f)\n", md_table(sk, units=SK_UNITS),
                  "### s_k = slope * s_f + intercept\n", md_table(lines_frame(sk_lines(sk)))]
    return "\n".join(parts)


def lines_frame(lines: Mapping) -> pd.DataFrame:
    """calibration-sk's least-squares lines s_k = slope * s_f + intercept, a row per
    blur-rate."""
    return pd.DataFrame([{"blur_rate": br, "slope": ln.slope, "intercept": ln.intercept,
                          "r2": ln.r2, "n_levels": ln.n} for br, ln in sorted(lines.items())])


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
        md_table(paper, 2),
        "### f_e per blur-rate (calibration-fe)\n",
        md_table(calib.fe, units=FE_UNITS),
        "### s_k per (blur-rate, s_f) (calibration-sk)\n",
        md_table(calib.sk, units=SK_UNITS),
        "Least-squares line s_k = slope * s_f + intercept per blur-rate (fitted to the means "
        "above; calibration-sf sets s_k with it):\n",
        md_table(lines_frame(calib.lines)),
        "### Final s_f and its s_k (calibration-sf)\n",
        "s_k is the group line at the mean s_f; its SEM is sqrt((slope x SEM(s_f))^2 + "
        "SEM_line^2), SEM_line = SEM across participants of their own lines at that s_f.\n",
        md_table(calib.sf, units={"n": "participants"}),
    ]
    if figures:
        parts.append("![Calibration results](figures/calibration.png)\n")
    return "\n".join(parts)
