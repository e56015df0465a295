"""What a protocol means where it is silent: the tracker's rate and the limits a validation must
meet (the protocol's ``tracker`` keys, resolved). The trackers' room reads them from here
(:mod:`fovexp.experiment.trackers.quality`, the sources' default rate), so that the protocol
depends on no part of the runner but the stimuli.

The fixation window's radius and the gaze timeout are the blanking rule's
(:mod:`fovexp.results.blanking`), which the analysis checks the logs against.
"""

from __future__ import annotations

from dataclasses import dataclass

#: Tobii Pro Spectrum's rate in the paper (section 5.1), and the simulated sources' (Hz).
TRACKER_RATE_HZ = 600.0
#: Default limit on a validation's data loss per eye (fraction of the expected samples).
MAX_DATA_LOSS = 0.2
#: Default limit on the accuracy averaged over the validation targets (deg, worse eye).
MAX_ACCURACY_DEG = 1.0
#: The central accuracy limit as a fraction of the fixation window's radius: 0.4 x 1.25 = 0.5 deg.
#: A gaze error e at the cross moves the window on the retina: the stimulus then stays visible
#: up to r + e from the cross and blanks from r - e on, 0.75 ... 1.75 deg for e = 0.5 deg, and
#: the edge of the paper's 8 deg foveal region falls within 0.5 deg (6 %) of where it should.
CENTRAL_ACCURACY_FRACTION = 0.4


def central_accuracy_limit_deg(radius_deg: float) -> float:
    """The default limit on the central target's accuracy for a fixation window of
    ``radius_deg`` (:data:`CENTRAL_ACCURACY_FRACTION` of it)."""
    return CENTRAL_ACCURACY_FRACTION * float(radius_deg)


@dataclass(frozen=True)
class QualityLimits:
    """What a validation must meet (the protocol's ``tracker`` keys, resolved)."""

    max_accuracy_deg: float = MAX_ACCURACY_DEG
    max_central_accuracy_deg: float = CENTRAL_ACCURACY_FRACTION * 1.25
    max_data_loss: float = MAX_DATA_LOSS
