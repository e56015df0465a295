"""Calibration results for the experiment runner (paper section 6.2: each calibration step uses
the previous step's result).

The runner imports these three functions to set up the next calibration experiment and to write
a lab's Table 2. Each loads a results folder with the analysis' exclusion rules
(:func:`analysis.loading.load_results`) and raises :class:`~fovexp.FovexpError` on
missing or malformed data.
"""

from __future__ import annotations

from pathlib import Path

from fovexp import ParameterTable

from .calibration import calibrate, fe_summary, sk_lines, sk_summary
from .loading import load_results

__all__ = ["fe_by_blur_rate", "sk_line_by_blur_rate", "parameter_table"]


def fe_by_blur_rate(folder: Path) -> dict[float, float]:
    """Mean adjusted f_e per blur-rate from a calibration-fe results folder (section 6.2)."""
    fe = fe_summary(load_results(folder).trials)
    return {float(b): float(m) for b, m in zip(fe["blur_rate"], fe["mean"], strict=True)}


def sk_line_by_blur_rate(folder: Path) -> dict[float, tuple[float, float]]:
    """Per blur-rate the least-squares line s_k = slope * s_f + intercept, as (slope, intercept),
    from a calibration-sk results folder (section 6.2, "Bandwidth scaling" uses it)."""
    lines = sk_lines(sk_summary(load_results(folder).trials))
    return {br: (line.slope, line.intercept) for br, line in lines.items()}


def parameter_table(calibration_root: Path,
                    source: str = "fovexp analyze: lab calibration") -> ParameterTable:
    """Table 2 (section 6.3) from ``calibration-fe``, ``calibration-sk`` and ``calibration-sf``
    under ``calibration_root``: f_e is the mean adjusted f_e, s_f the mean adjusted s_f, and s_k
    the s_k line at that s_f."""
    root = Path(calibration_root)
    parts = [load_results(root / name).trials
             for name in ("calibration-fe", "calibration-sk", "calibration-sf")]
    return calibrate(*parts).parameter_table(source)
