"""The state of one ``fovexp analyze`` run that its sections share
(:mod:`fovexp.analysis.sections`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from fovexp.results.calibration import Calibration
from fovexp.results.loading import Dataset, TrialLimits

from .validation import ValidationResult


@dataclass
class Analysis:
    """Everything ``fovexp analyze`` computed, and the files it wrote; each section
    (:mod:`fovexp.analysis.sections`) reads its settings here and adds its results."""

    data: Dataset
    out: Path
    #: the results folder analysed
    results: Path = Path(".")
    calibration: Calibration | None = None
    validations: list[ValidationResult] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    files: list[Path] = field(default_factory=list)
    limits: TrialLimits = field(default_factory=TrialLimits)
    #: write the figures (PNG and PDF)
    figures: bool = True
    #: the source Table 2's YAML names (default: the command and the date)
    table_source: str | None = None

    @property
    def report(self) -> Path:
        return self.out / "report.md"

    @property
    def tables(self) -> Path:
        return self.out / "tables"

    @property
    def fig_dir(self) -> Path:
        return self.out / "figures"
