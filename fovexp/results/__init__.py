"""The trial logs as data, below both the runner and the analysis.

``format``: the log formats (columns, types, the participant-ID rule, the ``trials.csv`` reader
that drops a torn last row; docs/LOGS.md). ``loading``: every results folder read with the
stated exclusion rules (docs/ANALYSIS.md). ``calibration``: the reductions of paper section 5.3
(mean f_e per blur-rate, the s_k-against-s_f lines, Table 2). ``derive``: what a calibration
experiment hands to the next one (section 5.2). ``bids``: where each log goes in a BIDS
dataset written by ``fovexp export bids``, and such a dataset read back (``load_results`` reads
one as it reads a results folder; docs/SHARING.md). The runner (``fovexp.experiment``) and the
analysis (``fovexp.analysis``) both import from here; neither imports the other.
"""

from .calibration import Calibration, calibrate
from .derive import fe_by_blur_rate, parameter_table, sk_line_by_blur_rate
from .loading import Dataset, Exclusion, load_results

__all__ = ["Calibration", "Dataset", "Exclusion", "calibrate", "fe_by_blur_rate",
           "load_results", "parameter_table", "sk_line_by_blur_rate"]
