"""fovexp analysis: trial logs -> the paper's results (sections 6.3 and 7.1).

``fovexp analyze results/ --out report/`` (or ``python -m analysis``) runs :func:`run_analysis`.
"""

from __future__ import annotations

from .calibration import Calibration, calibrate
from .loading import Dataset, Exclusion, load_results

__all__ = ["Calibration", "Dataset", "Exclusion", "calibrate", "load_results"]
