"""fovexp analysis: trial logs -> the paper's results (sections 5.3, 6.1 and 6.3).

``fovexp analyze results/ --out report/`` (or ``python -m fovexp.analysis``) runs
:func:`fovexp.analysis.report.run_analysis`. Reading the logs and the calibration reductions
come from :mod:`fovexp.results`, which the runner shares; this package adds the validation
statistics, the tables, the figures and the report.
"""

from __future__ import annotations

from fovexp.results import Calibration, Dataset, Exclusion, calibrate, load_results

__all__ = ["Calibration", "Dataset", "Exclusion", "calibrate", "load_results"]
