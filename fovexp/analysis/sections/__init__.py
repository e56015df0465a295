"""The report's sections, in the order ``report.md`` shows them.

A section is a function ``(ana: Analysis) -> list[str]``: it computes its own tables and figures
(written under ``ana.out``, listed in ``ana.files``), records what later sections or callers
read on ``ana`` (``ana.calibration``, ``ana.validations``), and returns its Markdown, one string
per sub-report (none when the data have nothing for it). :mod:`fovexp.analysis.report` only
loads the data, runs the sections in this order and frames them (data, exclusions, notes).

A new analysis goes in as a module here and one entry in :data:`SECTIONS`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

from .calibration import calibration_section
from .forced_choice import forced_choice_section
from .impulses import impulses_section
from .latency import latency_section
from .validation import validation_sections

if TYPE_CHECKING:
    from ..state import Analysis

Section = Callable[["Analysis"], list[str]]

#: the report's sections, in order
SECTIONS: tuple[Section, ...] = (calibration_section, validation_sections,
                                 forced_choice_section, impulses_section, latency_section)

__all__ = ["SECTIONS", "Section"]
