"""The thresholds of the exclusion rules on a trial's frames (R11-R13 of
:mod:`fovexp.results.loading`), apart so that the command line states them without loading
pandas. The analysis applies them to the logs of finished trials; ``fovexp monitor`` to the
trial on screen (the same predicates, :meth:`TrialLimits.exceeded`)."""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass
from typing import Any

#: the names of rules R11-R13, as the report and the monitor show them
R11, R12, R13 = "R11 blanking", "R12 dropped frames", "R13 latency"


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
            R11: f"a participant's trial blanked for more than "
            f"{self.max_blanked_fraction:.0%} of its frames: excluded",
            R12: f"a participant's trial with more than "
            f"{self.max_dropped_fraction:.0%} of its frames dropped (frame log): excluded",
            R13: f"a participant's trial whose gaze-to-flip latency's 95th percentile "
            f"exceeds {self.max_latency_p95_ms:g} ms (frame log): excluded",
        }

    # The rules' predicates, for a number or element-wise for an array or a Series; a missing
    # figure (NaN) breaks none.
    def blanked_excluded(self, blanked_fraction: Any) -> Any:
        """R11: blanked for more than :attr:`max_blanked_fraction` of the trial's time."""
        return blanked_fraction > self.max_blanked_fraction

    def dropped_excluded(self, dropped_fraction: Any) -> Any:
        """R12: more than :attr:`max_dropped_fraction` of the trial's frames dropped."""
        return dropped_fraction > self.max_dropped_fraction

    def latency_excluded(self, latency_p95_ms: Any) -> Any:
        """R13: the gaze-to-flip latency's 95th percentile above :attr:`max_latency_p95_ms`."""
        return latency_p95_ms > self.max_latency_p95_ms

    def exceeded(self, *, blanked_fraction: float = math.nan,
                 dropped_fraction: float = math.nan,
                 latency_p95_ms: float = math.nan) -> dict[str, bool]:
        """Which of R11-R13 one trial's figures break (rule name -> bool)."""
        return {R11: bool(self.blanked_excluded(blanked_fraction)),
                R12: bool(self.dropped_excluded(dropped_fraction)),
                R13: bool(self.latency_excluded(latency_p95_ms))}

    def as_dict(self) -> dict[str, float]:
        return {"max_blanked_fraction": self.max_blanked_fraction,
                "max_dropped_fraction": self.max_dropped_fraction,
                "max_latency_p95_ms": self.max_latency_p95_ms}


def add_limit_options(p: argparse.ArgumentParser) -> None:
    """The ``--max-blanked``, ``--max-dropped`` and ``--max-latency-ms`` options (``fovexp
    analyze`` and ``fovexp monitor``: one definition, the same defaults)."""
    d = TrialLimits()
    p.add_argument("--max-blanked", type=float, default=d.max_blanked_fraction, metavar="F",
                   help="rule R11: the largest blanked fraction of a trial's frames "
                        f"(default {d.max_blanked_fraction:g})")
    p.add_argument("--max-dropped", type=float, default=d.max_dropped_fraction, metavar="F",
                   help="rule R12: the largest fraction of a trial's frames dropped "
                        f"(default {d.max_dropped_fraction:g})")
    p.add_argument("--max-latency-ms", type=float, default=d.max_latency_p95_ms, metavar="MS",
                   help="rule R13: the largest 95th percentile of a trial's gaze-to-flip "
                        f"latency (default {d.max_latency_p95_ms:g} ms)")


def limits_from_args(args: Any) -> TrialLimits:
    """The limits :func:`add_limit_options` parsed."""
    return TrialLimits(max_blanked_fraction=args.max_blanked,
                       max_dropped_fraction=args.max_dropped,
                       max_latency_p95_ms=args.max_latency_ms)
