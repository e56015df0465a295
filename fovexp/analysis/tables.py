"""Table 2 (paper section 5.3) written out: CSV, Markdown, LaTeX in the paper's layout, and the
ParameterTable YAML the enhancer reads."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from fovexp.results.calibration import Calibration


def _fmt(x: float, digits: int) -> str:
    return "" if not np.isfinite(x) else f"{x:.{digits}f}"


def table2_markdown(table: pd.DataFrame, digits: int = 2) -> str:
    """Table 2 as a Markdown table (value +- SEM)."""
    lines = ["| Foveation (blur-rate) | f_e | s_k | s_f |", "|---|---|---|---|"]
    for _, r in table.iterrows():
        cells = [f"{r['blur_rate']:g}"]
        for k in ("f_e", "s_k", "s_f"):
            sem = _fmt(r[f"{k}_sem"], digits)
            cells.append(_fmt(r[k], digits) + (f" ± {sem}" if sem else ""))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def table2_latex(table: pd.DataFrame, digits: int = 2) -> str:
    """Table 2 as LaTeX in the paper's layout (booktabs)."""
    out = [
        r"\begin{table}[h]",
        r"    \centering",
        r"    \caption{The optimal values of our parameters after calibration.}",
        r"    \label{tab:parameters}",
        r"    \begin{tabular}{cccc}",
        r"        \toprule",
        r"        Foveation ($\sigma_\text{BlurRate}$) & $f_e$ & $s_k$ & $s_f$ \\ \midrule",
    ]
    body = [f"        {r['blur_rate']:g} & {_fmt(r['f_e'], digits)} & {_fmt(r['s_k'], digits)}"
            f" & {_fmt(r['s_f'], digits)} \\\\" for _, r in table.iterrows()]
    out.append(" \\hline\n".join(body) + r" \bottomrule")
    out += [r"    \end{tabular}", r"\end{table}"]
    return "\n".join(out) + "\n"


def write_table2(calib: Calibration, out_dir: Path, source: str,
                 yaml_path: Path | None = None) -> dict[str, Path]:
    """Write Table 2 as CSV, Markdown and LaTeX into ``out_dir``, and once as ParameterTable YAML
    (``yaml_path``, default ``out_dir/table2.yaml``)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = {k: out_dir / f"table2.{k}" for k in ("csv", "md", "tex")}
    paths["yaml"] = Path(yaml_path) if yaml_path is not None else out_dir / "table2.yaml"
    calib.table.to_csv(paths["csv"], index=False, float_format="%.6g")
    paths["md"].write_text(table2_markdown(calib.table))
    paths["tex"].write_text(table2_latex(calib.table))
    calib.parameter_table(source).save(paths["yaml"])
    return paths
