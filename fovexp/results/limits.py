"""The thresholds of the exclusion rules on a trial's frames (R11-R13 of
:mod:`fovexp.results.loading`), apart so that the command line states them without loading
pandas, and the latency budget R13's default comes from (docs/ANALYSIS.md, "R13's
threshold"). The analysis applies them to the logs of finished trials; ``fovexp monitor`` to the
trial on screen (the same predicates, :meth:`TrialLimits.exceeded`).

The blanking of paper section 5.1 has to put a black frame on the screen before the eye can
look at the stimulus it hides: before a saccade that leaves the 1.25 deg window lands, give or
take the few ms after the landing during which vision is still suppressed. How long that is
follows from the saccade's main sequence; what is left for the tracker, the computer and the
display is the budget, and the frame log measures the part the computer and tracker take
(gaze-to-flip, sample capture to flip).
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass
from typing import Any

#: the names of rules R11-R13, as the report and the monitor show them
R11, R12, R13 = "R11 blanking", "R12 dropped frames", "R13 latency"

#: The main sequence's duration (Carpenter 1988, "Movements of the Eyes", after Bahill, Clark
#: and Stark 1975): a saccade of A deg lasts about ``SACCADE_MS_PER_DEG * A +
#: SACCADE_BASE_MS`` ms (horizontal saccades of a few to about 50 deg).
SACCADE_MS_PER_DEG = 2.2
SACCADE_BASE_MS = 21.0
#: The smallest saccade the blanking must beat (deg): one landing 5 deg from the cross, where
#: the foveation and its enhancement differ visibly from the reference (smaller ones land where
#: both halves are nearly at full resolution), 4 times the window's radius.
DESIGN_SACCADE_DEG = 5.0
#: After a saccade lands, a change to the image goes unnoticed for about this long (ms):
#: McConkie and Loschky (2002) found display changes undetected under 6 ms after the saccade's
#: end (detection reached its asymptote 32 ms after it).
POST_SACCADIC_MS = 6.0
#: The tracker's sampling interval at the paper's 600 Hz (ms): the sample that first shows the
#: eye outside the window comes up to this long after it left.
SAMPLE_INTERVAL_MS = 1e3 / 600.0
#: The display's own latency (flip to light, ms) the default budget leaves room for: an
#: assumption, a TV in its low-latency (game/PC) mode at 120 Hz; the rig check measures a
#: lab's own with a photodiode, and :func:`latency_budget_ms` takes it.
DISPLAY_LATENCY_MS = 5.0


def _min_jerk_time(fraction: float) -> float:
    """The fraction of a minimum-jerk movement's duration (Flash and Hogan 1985: x(tau) =
    10 tau^3 - 15 tau^4 + 6 tau^5) at which it has covered ``fraction`` of its amplitude."""
    lo, hi = 0.0, 1.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if 10 * mid**3 - 15 * mid**4 + 6 * mid**5 < fraction:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def exit_to_landing_ms(amplitude_deg: float, radius_deg: float = 1.25) -> float:
    """How long after a saccade from the cross crosses ``radius_deg`` it lands
    ``amplitude_deg`` away (ms): the main sequence's duration (:data:`SACCADE_MS_PER_DEG`,
    :data:`SACCADE_BASE_MS`) and a minimum-jerk position profile. Real saccades reach their
    peak velocity early and decelerate longer (more so the larger they are), so they cross the
    radius earlier and leave more time than this: the estimate errs short, on the safe side.
    0 when the saccade lands inside the radius."""
    if amplitude_deg <= radius_deg:
        return 0.0
    duration = SACCADE_MS_PER_DEG * amplitude_deg + SACCADE_BASE_MS
    return duration * (1.0 - _min_jerk_time(radius_deg / amplitude_deg))


def latency_budget_ms(amplitude_deg: float = DESIGN_SACCADE_DEG, radius_deg: float = 1.25,
                      display_ms: float = DISPLAY_LATENCY_MS,
                      sample_interval_ms: float = SAMPLE_INTERVAL_MS,
                      post_saccadic_ms: float = POST_SACCADIC_MS) -> float:
    """The gaze-to-flip latency (sample capture to flip, what the frame log measures) that
    still blacks the screen out before a saccade of ``amplitude_deg`` leaving the window lands
    (plus the post-saccadic suppression): the exit-to-landing time, less the wait for the
    first sample outside and the display's own latency."""
    return (exit_to_landing_ms(amplitude_deg, radius_deg) + post_saccadic_ms
            - sample_interval_ms - display_ms)


@dataclass(frozen=True)
class TrialLimits:
    """What a participant's trial may show of its frames and still count (rules R11-R13).

    The thresholds are this project's (the paper states none), chosen to catch a faulty trial,
    not to trim a normal one: ``max_blanked_fraction`` 0.5 (blanked for more than half its
    frames: the participant judged the test half mostly without fixating the cross, paper
    section 6.1); ``max_dropped_fraction`` 0.05 (more than 1 frame in 20 dropped: the display
    stuttered, and the frames' timing no longer holds); ``max_latency_p95_ms`` 20, the
    :func:`latency_budget_ms` of a 5 deg saccade rounded to the ms (its exit-to-landing 20.5
    ms, 6 ms of post-saccadic suppression, less a 600 Hz sample interval and 5 ms of display
    latency: docs/ANALYSIS.md, "R13's threshold"). A late-latched 120 Hz rig with a 600 Hz
    tracker takes about a tracker's processing delay plus a few ms.
    """

    max_blanked_fraction: float = 0.5
    max_dropped_fraction: float = 0.05
    max_latency_p95_ms: float = float(round(latency_budget_ms()))

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
