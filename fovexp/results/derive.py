"""Calibration results for the experiment runner (paper section 5.2: each calibration step uses
the previous step's result).

The runner imports these three functions to set up the next calibration experiment and to write
a lab's Table 2. Each loads a results folder with the exclusion rules
(:func:`fovexp.results.loading.load_results`; rule R7 already drops dry runs beside real
sessions) and raises :class:`~fovexp.FovexpError` on missing or malformed data. With
``real_only`` (a session with a participant) a folder holding nothing but simulated sessions
(dry runs) is an error: a participant's parameters never come from a simulated participant.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from fovexp import FovexpError, ParameterTable

from .calibration import calibrate, fe_summary, sk_lines, sk_summary
from .format import SIMULATED_TRACKER
from .loading import load_results

__all__ = ["fe_by_blur_rate", "sk_line_by_blur_rate", "parameter_table"]


def _trials(folder: Path, real_only: bool) -> pd.DataFrame:
    trials = load_results(folder).trials
    if real_only and (trials["tracker"] == SIMULATED_TRACKER).all():
        raise FovexpError(f"{folder} holds only simulated sessions (dry runs); a session with "
                          "a participant cannot take its parameters from them (resuming a dry "
                          "run? add --dry-run)")
    return trials


def fe_by_blur_rate(folder: Path, real_only: bool = False) -> dict[float, float]:
    """Mean adjusted f_e per blur-rate from a calibration-fe results folder (section 5.2)."""
    fe = fe_summary(_trials(folder, real_only))
    return {float(b): float(m) for b, m in zip(fe["blur_rate"], fe["mean"], strict=True)}


def sk_line_by_blur_rate(folder: Path,
                         real_only: bool = False) -> dict[float, tuple[float, float]]:
    """Per blur-rate the least-squares line s_k = slope * s_f + intercept, as (slope, intercept),
    from a calibration-sk results folder (section 5.2, "Bandwidth scaling" uses it)."""
    lines = sk_lines(sk_summary(_trials(folder, real_only)))
    return {br: (line.slope, line.intercept) for br, line in lines.items()}


def parameter_table(calibration_root: Path, source: str = "fovexp analyze: lab calibration",
                    real_only: bool = False) -> ParameterTable:
    """Table 2 (section 5.3) from ``calibration-fe``, ``calibration-sk`` and ``calibration-sf``
    under ``calibration_root``: f_e is the mean adjusted f_e, s_f the mean adjusted s_f, and s_k
    the s_k line at that s_f."""
    root = Path(calibration_root)
    parts = [_trials(root / name, real_only)
             for name in ("calibration-fe", "calibration-sk", "calibration-sf")]
    return calibrate(*parts).parameter_table(source)
