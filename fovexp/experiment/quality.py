"""Eye-tracker data quality from a validation: accuracy, precision and data loss per eye.

Accuracy is the median angular error between the gaze and the target; precision is the RMS of
the angles between successive samples (RMS-S2S); data loss is the fraction of invalid samples.
The experiment refuses to start when the worse eye's accuracy exceeds the protocol's limit, so
that the 1.25 deg fixation window of paper section 6.1 is meaningful, or when either eye lost
more than the protocol's fraction of samples (a median over a handful of valid samples says
nothing).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from .gaze import FixationGeometry, GazeSample

#: Default limit on a validation's data loss per eye (fraction of invalid samples).
MAX_DATA_LOSS = 0.2


@dataclass
class EyeQuality:
    accuracy_deg: float
    precision_rms_s2s_deg: float
    data_loss: float
    n_samples: int


@dataclass
class ValidationResult:
    left: EyeQuality
    right: EyeQuality
    targets: list[tuple[float, float]]
    limit_deg: float
    max_data_loss: float = MAX_DATA_LOSS

    @property
    def data_loss(self) -> float:
        """The worse eye's data loss."""
        return max(self.left.data_loss, self.right.data_loss)

    @property
    def accuracy_deg(self) -> float:
        """The worse eye's accuracy (NaN counts as worst)."""
        vals = [self.left.accuracy_deg, self.right.accuracy_deg]
        return math.inf if any(math.isnan(v) for v in vals) else max(vals)

    @property
    def passed(self) -> bool:
        return self.failure is None

    @property
    def failure(self) -> str | None:
        """Why the validation failed, or None when it passed."""
        if not self.accuracy_deg <= self.limit_deg:
            return (f"accuracy {self.accuracy_deg:.2f} deg is worse than the protocol's limit "
                    f"{self.limit_deg:g} deg")
        if self.data_loss > self.max_data_loss:
            return (f"data loss {100 * self.data_loss:.1f}% is above the protocol's limit "
                    f"{100 * self.max_data_loss:g}%")
        return None

    def to_dict(self) -> dict[str, Any]:
        return {"left": asdict(self.left), "right": asdict(self.right),
                "targets": [list(t) for t in self.targets], "limit_deg": self.limit_deg,
                "max_data_loss": self.max_data_loss, "accuracy_deg": self.accuracy_deg,
                "data_loss": self.data_loss, "passed": self.passed, "failure": self.failure}

    def summary(self) -> str:
        def eye(q: EyeQuality) -> str:
            return (f"accuracy {q.accuracy_deg:.2f} deg, precision {q.precision_rms_s2s_deg:.3f} "
                    f"deg RMS-S2S, data loss {100 * q.data_loss:.1f}%")
        return f"left eye: {eye(self.left)}; right eye: {eye(self.right)}"


def eye_quality(fix: FixationGeometry, per_target: Sequence[tuple[tuple[float, float],
                Sequence[GazeSample]]], eye: str) -> EyeQuality:
    errors: list[float] = []
    s2s: list[float] = []
    n = lost = 0
    for target, samples in per_target:
        prev = None
        for s in samples:
            n += 1
            valid = s.left_valid if eye == "left" else s.right_valid
            if not valid:
                lost += 1
                prev = None
                continue
            p = (s.left_x, s.left_y) if eye == "left" else (s.right_x, s.right_y)
            if not (0 <= p[0] <= 1 and 0 <= p[1] <= 1):
                lost += 1  # off the screen: unusable for a screen-based validation
                prev = None
                continue
            errors.append(fix.angle_between(p, target))
            if prev is not None:
                s2s.append(fix.angle_between(p, prev))
            prev = p
    return EyeQuality(
        accuracy_deg=float(np.median(errors)) if errors else math.nan,
        precision_rms_s2s_deg=float(np.sqrt(np.mean(np.square(s2s)))) if s2s else math.nan,
        data_loss=lost / n if n else 1.0,
        n_samples=n,
    )


def validation_result(fix: FixationGeometry,
                      per_target: Sequence[tuple[tuple[float, float], Sequence[GazeSample]]],
                      limit_deg: float,
                      max_data_loss: float = MAX_DATA_LOSS) -> ValidationResult:
    """Quality per eye over the samples collected at each validation target."""
    return ValidationResult(
        left=eye_quality(fix, per_target, "left"),
        right=eye_quality(fix, per_target, "right"),
        targets=[t for t, _ in per_target],
        limit_deg=limit_deg,
        max_data_loss=max_data_loss,
    )


def target_points(n: int) -> list[tuple[float, float]]:
    """Calibration/validation targets in normalised coordinates: the centre first (where the
    experiment's fixation cross is), then around it; 5 or 9 points, or the first ``n``."""
    ring = [(0.5, 0.5), (0.3, 0.3), (0.7, 0.3), (0.3, 0.7), (0.7, 0.7),
            (0.5, 0.3), (0.3, 0.5), (0.7, 0.5), (0.5, 0.7),
            (0.1, 0.1), (0.9, 0.1), (0.1, 0.9), (0.9, 0.9)]
    return ring[:n]
