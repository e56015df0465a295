"""The blanking rule of paper section 5.1, defined once: the runner decides every frame with it
(:class:`fovexp.experiment.trackers.gaze.BlankingMonitor`), and the analysis and the tests check the
frame logs against it (:func:`fovexp.results.frames.unblanked_violations`).

Section 5.1: "stimuli are hidden by rendering a black frame whenever participants' gaze
position moved outside a small circular region with radius 1.25 deg at the center of the
screen". A frame may show the stimulus only when, at the moment it is decided, the newest gaze
sample is

- fresh: no older than the gaze timeout (``decision - sample <= timeout``, both on the
  tracker's clock, in whole microseconds: exact, no slack);
- valid: at least one eye found;
- inside: no farther than ``radius_deg`` from the cross.

Otherwise the frame is black (the cross stays), for a reason: ``lost`` (no sample, or none
fresh), ``invalid``, ``outside``, checked in that order. The predicates work on numbers and on
NumPy/pandas arrays alike, so the runner's scalar decision and the analysis's column-wise check
are the same expressions. This module imports nothing but the standard library.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

#: Paper section 5.1: gaze farther than this from the cross blanks the frame (deg).
BLANKING_RADIUS_DEG = 1.25
#: No sample newer than this at the frame's decision: gaze "lost", the frame is black (s).
#: The protocol's ``fixation.gaze_timeout_s`` overrides it.
GAZE_TIMEOUT_S = 0.05

#: Why a frame is black (the blanking log's ``reason``); "" when it shows the stimulus.
REASONS = ("lost", "invalid", "outside")


@dataclass(frozen=True)
class BlankingRule:
    """The rule with a protocol's radius and gaze timeout (module docstring)."""

    radius_deg: float = BLANKING_RADIUS_DEG
    timeout_s: float = GAZE_TIMEOUT_S

    @property
    def timeout_us(self) -> int:
        """The timeout in whole microseconds, the unit of the tracker's clock."""
        return round(self.timeout_s * 1e6)

    def fresh(self, age_us: Any) -> Any:
        """The newest sample is no older than the timeout at the decision (``age_us``: the
        decision's time minus the sample's; NaN where there is no sample: not fresh)."""
        return age_us <= self.timeout_us

    def inside(self, ecc_deg: Any) -> Any:
        """The sample lies within the radius (``ecc_deg`` NaN for an invalid one: not
        inside)."""
        return ecc_deg <= self.radius_deg

    def allows(self, age_us: Any, ecc_deg: Any) -> Any:
        """Whether a frame may show the stimulus: a fresh, valid sample inside the radius."""
        return self.fresh(age_us) & self.inside(ecc_deg)

    def reason(self, age_us: int | None, valid: bool, ecc_deg: float) -> str:
        """The decision for one frame: ``""`` (show the stimulus) or why it is black
        (:data:`REASONS`). ``age_us`` None: no sample yet."""
        if age_us is None or not self.fresh(age_us):
            return "lost"
        if not valid:
            return "invalid"
        if not self.inside(ecc_deg):
            return "outside"
        return ""


__all__ = ["BLANKING_RADIUS_DEG", "GAZE_TIMEOUT_S", "REASONS", "BlankingRule"]
