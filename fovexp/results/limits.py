"""The thresholds of the exclusion rules on a trial's frames (R11-R13 of
:mod:`fovexp.results.loading`), apart so that the command line states them without loading
pandas."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class TrialLimits:
    """What a participant's trial may show of its frames and still count (rules R11-R13).

    The thresholds are this project's (the paper states none), chosen to catch a faulty trial,
    not to trim a normal one: ``max_blanked_fraction`` 0.5 (blanked for more than half its
    frames: the participant judged the test half mostly without fixating the cross, paper
    section 6.1); ``max_dropped_fraction`` 0.05 (more than 1 frame in 20 dropped: the display
    stuttered, and the frames' timing no longer holds); ``max_latency_p95_ms`` 60 (Loschky and
    Wolverton 2007 found gaze-contingent updates up to 60 ms after an eye movement undetected;
    a 600 Hz tracker and a 120 Hz display give 10-25 ms, benchmarks/DISPLAY_LOOP.md).
    """

    max_blanked_fraction: float = 0.5
    max_dropped_fraction: float = 0.05
    max_latency_p95_ms: float = 60.0

    def rules(self) -> dict[str, str]:
        """R11-R13 as the report states them, with these thresholds."""
        return {
            "R11 blanking": f"a participant's trial blanked for more than "
            f"{self.max_blanked_fraction:.0%} of its frames: excluded",
            "R12 dropped frames": f"a participant's trial with more than "
            f"{self.max_dropped_fraction:.0%} of its frames dropped (frame log): excluded",
            "R13 latency": f"a participant's trial whose gaze-to-flip latency's 95th percentile "
            f"exceeds {self.max_latency_p95_ms:g} ms (frame log): excluded",
        }
