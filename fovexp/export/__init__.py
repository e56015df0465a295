"""Sharing a study: ``fovexp export bids`` writes a results folder as a BIDS dataset
(docs/SHARING.md).

May import: the public API (``fovexp``), the logs layer (``fovexp.results``, where the
dataset's layout is defined once, for the writer here and the reader the analysis uses) and,
for the dataset's ``derivatives/fovexp/``, the analysis (``fovexp.analysis``). Never the
runner (``fovexp.experiment``): an analyst's machine exports without PsychoPy.
"""

from .bids import ExportReport, export_bids, validate

__all__ = ["ExportReport", "export_bids", "validate"]
