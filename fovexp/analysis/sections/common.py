"""What every section of the report shares: Markdown tables with units, p-value wording."""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path

import pandas as pd

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
    "max_ms": "ms", "draw_median_ms": "ms", "draw_p95_ms": "ms", "dropped_pct": "%",
    "with_gaze": "frames", "rule_violations": "frames", "delivery_p50_ms": "ms",
    "delivery_p95_ms": "ms", "delivery_max_ms": "ms", "tracker_cost_frames": "frames",
    "stamped_violations": "frames", "outside_ms": "ms", "outside_fraction": "dimensionless",
    "excursion_max_ms": "ms",
    "n_trials": "trials", "n_levels": "s_f levels", "t": "dimensionless",
    "d_z": "dimensionless", "df": "degrees of freedom",
}

#: per-table units of the ``mean`` / ``sem`` / ``n`` columns
FE_UNITS = {"mean": "f_e, dimensionless", "sem": "f_e, dimensionless", "n": "participants"}
SK_UNITS = {"mean": "s_k, dimensionless", "sem": "s_k, dimensionless", "n": "participants"}
BLUR_UNITS = {"mean": "arcmin/deg", "sem": "arcmin/deg", "n": "participants"}


def md_table(frame: pd.DataFrame, digits: int = 3, units: Mapping[str, str] | None = None,
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


def p_text(p: float) -> str:
    """A p-value as the report words it."""
    return "n/a" if math.isnan(p) else ("p < 0.001" if p < 0.001 else f"p = {p:.3f}")


def write_csv(frame: pd.DataFrame, path: Path, files: list[Path]) -> None:
    """One of the report's tables as CSV (6 significant digits), listed in ``files``."""
    frame.to_csv(path, index=False, float_format="%.6g")
    files.append(path)
