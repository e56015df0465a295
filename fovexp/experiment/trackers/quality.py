"""Eye-tracker data quality of a validation or a drift check, as the field measures it.

The definitions follow Titta (Niehorster, Andersson & Nystrom 2020, "Titta: A toolbox for
creating PsychToolbox and Psychopy experiments with Tobii eye trackers", Behavior Research
Methods 52, 1970-1979; ``Titta.m``, ``getDataQuality`` and ``getOffsetFromPoint``), per eye and
per target:

- **accuracy**: each sample's angular offset at the eye (between the ray to the gaze point and
  the ray to the target, from the tracker's measured gaze origin) is split along its on-screen
  direction into a 2-D offset; the offsets are averaged and the length of the mean is the
  accuracy: the offset of the mean gaze from the target. Averaged over targets; the central
  target (where the fixation cross is) is reported on its own, since the 1.25 deg window of
  paper section 5.1 is what the experiment relies on.
- **precision**: RMS of the angles between successive gaze rays (RMS-S2S; pairs with an invalid
  sample left out), as Titta's Python version computes it (its MATLAB version differences the
  2-D offsets instead, the same to well under 0.001 deg at these angles); also the standard
  deviation of the 2-D offsets (Titta's STD). Averaged over targets.
- **data loss**: ``1 - valid / expected`` with ``expected`` the sampling rate times the
  collection window's duration, so samples the tracker never delivered count as lost, not only
  those it flagged invalid. Titta counts only the latter (``invalid / received``), reported
  here as ``invalid_fraction``.

Angles use each sample's measured gaze origin when the source gives one (a Tobii: its user
coordinate system, with the display area it reports), else the nominal eye: the display
profile's viewing distance on the screen normal through its centre.

The protocol's limits follow from the 1.25 deg window (:func:`central_accuracy_limit_deg`): a
session does not start when the worse eye's central accuracy, its accuracy over the targets or
its data loss exceeds them.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from ..protocol.defaults import (
    MAX_DATA_LOSS,
    QualityLimits,
)
from .gaze import DisplayArea, GazeSample, ray_angles_deg

#: Where the fixation cross is (normalised): the central validation target.
CENTRE = (0.5, 0.5)
#: A binocular tracker's eyes (a monocular one records one of them).
EYES: tuple[str, ...] = ("left", "right")


@dataclass
class TargetData:
    """The samples collected at one target and the window they were collected in."""

    target: tuple[float, float]
    samples: list[GazeSample]
    duration_s: float
    rate_hz: float

    @property
    def n_expected(self) -> int:
        """Samples the tracker should have delivered: rate x window duration."""
        return int(round(self.rate_hz * self.duration_s))


@dataclass
class TargetQuality:
    """One eye at one target (angles in degrees; offsets x right, y down on the screen)."""

    target: tuple[float, float]
    offset_x_deg: float
    offset_y_deg: float
    accuracy_deg: float
    precision_rms_s2s_deg: float
    precision_sd_deg: float
    data_loss: float
    invalid_fraction: float
    n_valid: int
    n_received: int
    n_expected: int
    #: samples whose angles used the measured gaze origin (the rest: the nominal eye)
    n_measured_origin: int


@dataclass
class EyeQuality:
    """One eye over all targets: accuracy, precision and data loss averaged over targets (as
    Titta), the central target's accuracy, and every target's figures."""

    accuracy_deg: float
    central_accuracy_deg: float
    precision_rms_s2s_deg: float
    precision_sd_deg: float
    data_loss: float
    invalid_fraction: float
    n_samples: int
    n_expected: int
    targets: list[TargetQuality] = field(default_factory=list)


def _eye(samples: Sequence[GazeSample], eye: str) -> tuple[np.ndarray, np.ndarray, list[Any]]:
    if eye == "left":
        xy = [(s.left_x, s.left_y) for s in samples]
        ok = [s.left_valid for s in samples]
        origins = [s.left_origin_mm for s in samples]
    else:
        xy = [(s.right_x, s.right_y) for s in samples]
        ok = [s.right_valid for s in samples]
        origins = [s.right_origin_mm for s in samples]
    pts = np.array(xy, dtype=np.float64).reshape(-1, 2)
    valid = np.array(ok, dtype=bool) & np.isfinite(pts).all(axis=1)
    return pts, valid, origins


def target_quality(area: DisplayArea, distance_mm: float, data: TargetData,
                   eye: str) -> TargetQuality:
    """Accuracy, precision and data loss of ``eye`` (``left``/``right``) at one target."""
    pts, valid, origins = _eye(data.samples, eye)
    n, n_valid = len(pts), int(valid.sum())
    nominal = area.eye_mm(distance_mm)
    org = np.tile(nominal, (n, 1))
    measured = 0
    for i, o in enumerate(origins):
        if o is not None and valid[i] and all(math.isfinite(v) for v in o):
            org[i] = o
            measured += 1
    target = np.asarray(data.target, dtype=np.float64)
    gaze_mm = area.points_mm(pts[:, 0], pts[:, 1])
    target_mm = area.points_mm(target[0], target[1])
    ang = ray_angles_deg(org, gaze_mm, target_mm)
    # the offset's direction on the screen (x right, y down), in mm along the area's axes
    d = (pts - target) * np.array([area.width_mm, area.height_mm])
    phi = np.arctan2(d[:, 1], d[:, 0])
    offs = np.stack([ang * np.cos(phi), ang * np.sin(phi)], axis=1)
    offs[~valid] = np.nan
    if n_valid:
        mean = np.nanmean(offs, axis=0)
        acc = float(np.hypot(*mean))
        sd = float(np.hypot(*np.nanstd(offs, axis=0, ddof=1))) if n_valid > 1 else math.nan
    else:
        mean, acc, sd = np.array([math.nan, math.nan]), math.nan, math.nan
    pair = valid[1:] & valid[:-1]
    if pair.any():
        s2s = ray_angles_deg(org[1:][pair], gaze_mm[1:][pair], gaze_mm[:-1][pair]
                             + (org[1:][pair] - org[:-1][pair]))
        rms = float(np.sqrt(np.mean(np.square(s2s))))
    else:
        rms = math.nan
    expected = data.n_expected
    loss = max(0.0, 1.0 - n_valid / expected) if expected > 0 else (
        1.0 - n_valid / n if n else 1.0)
    return TargetQuality(
        target=(float(target[0]), float(target[1])),
        offset_x_deg=float(mean[0]), offset_y_deg=float(mean[1]), accuracy_deg=acc,
        precision_rms_s2s_deg=rms, precision_sd_deg=sd, data_loss=loss,
        invalid_fraction=(n - n_valid) / n if n else 1.0,
        n_valid=n_valid, n_received=n, n_expected=expected, n_measured_origin=measured)


def _nanmean(values: list[float]) -> float:
    v = [x for x in values if not math.isnan(x)]
    return float(np.mean(v)) if v else math.nan


def eye_quality(area: DisplayArea, distance_mm: float, per_target: Sequence[TargetData],
                eye: str) -> EyeQuality:
    """One eye over the targets (:func:`target_quality` per target, then averaged)."""
    tq = [target_quality(area, distance_mm, d, eye) for d in per_target]
    central = [q.accuracy_deg for q in tq if q.target == CENTRE]
    return EyeQuality(
        accuracy_deg=_nanmean([q.accuracy_deg for q in tq]),
        central_accuracy_deg=central[0] if central else math.nan,
        precision_rms_s2s_deg=_nanmean([q.precision_rms_s2s_deg for q in tq]),
        precision_sd_deg=_nanmean([q.precision_sd_deg for q in tq]),
        data_loss=float(np.mean([q.data_loss for q in tq])) if tq else 1.0,
        invalid_fraction=float(np.mean([q.invalid_fraction for q in tq])) if tq else 1.0,
        n_samples=sum(q.n_received for q in tq),
        n_expected=sum(q.n_expected for q in tq),
        targets=tq,
    )


def _worst(values: Sequence[float]) -> float:
    """The worst of the tracked eyes' figures (NaN counts as worst)."""
    return math.inf if any(math.isnan(v) for v in values) else max(values)


@dataclass
class ValidationResult:
    left: EyeQuality
    right: EyeQuality
    targets: list[tuple[float, float]]
    limits: QualityLimits
    #: where the angles' eye positions came from: ``measured gaze origin`` or ``nominal eye``
    origins: str = "nominal eye"
    #: the eyes the tracker records (a monocular tracker's other eye is not judged)
    eyes: tuple[str, ...] = EYES

    def _tracked(self) -> list[EyeQuality]:
        return [q for name, q in (("left", self.left), ("right", self.right)) if name in self.eyes]

    @property
    def accuracy_deg(self) -> float:
        """The worse eye's accuracy averaged over the targets."""
        return _worst([q.accuracy_deg for q in self._tracked()])

    @property
    def central_accuracy_deg(self) -> float:
        """The worse eye's accuracy at the central target."""
        return _worst([q.central_accuracy_deg for q in self._tracked()])

    @property
    def data_loss(self) -> float:
        """The worse eye's data loss."""
        return max(q.data_loss for q in self._tracked())

    @property
    def passed(self) -> bool:
        return self.failure is None

    @property
    def failure(self) -> str | None:
        """Why the validation failed, or None when it passed."""
        lim = self.limits
        for name, q in (("left", self.left), ("right", self.right)):
            if name not in self.eyes:
                continue
            empty = [i + 1 for i, t in enumerate(q.targets) if t.n_valid == 0]
            if empty:
                return (f"no valid {name}-eye samples at target{'s' * (len(empty) > 1)} "
                        f"{', '.join(map(str, empty))}")
        if CENTRE not in self.targets:
            return "no validation target at the centre (the fixation cross)"
        if not self.central_accuracy_deg <= lim.max_central_accuracy_deg:
            return (f"central accuracy {self.central_accuracy_deg:.2f} deg is worse than the "
                    f"protocol's limit {lim.max_central_accuracy_deg:g} deg")
        if not self.accuracy_deg <= lim.max_accuracy_deg:
            return (f"accuracy {self.accuracy_deg:.2f} deg (mean over the targets) is worse than "
                    f"the protocol's limit {lim.max_accuracy_deg:g} deg")
        if self.data_loss > lim.max_data_loss:
            return (f"data loss {100 * self.data_loss:.1f}% is above the protocol's limit "
                    f"{100 * lim.max_data_loss:g}%")
        return None

    def to_dict(self) -> dict[str, Any]:
        return {"left": asdict(self.left), "right": asdict(self.right),
                "targets": [list(t) for t in self.targets], "limits": asdict(self.limits),
                "origins": self.origins, "eyes": list(self.eyes),
                "accuracy_deg": self.accuracy_deg,
                "central_accuracy_deg": self.central_accuracy_deg,
                "data_loss": self.data_loss, "passed": self.passed, "failure": self.failure}

    def summary(self) -> str:
        def eye(q: EyeQuality) -> str:
            return (f"centre {q.central_accuracy_deg:.2f} deg, mean {q.accuracy_deg:.2f} deg, "
                    f"RMS-S2S {q.precision_rms_s2s_deg:.3f} deg, "
                    f"loss {100 * q.data_loss:.1f}%")
        return "; ".join(f"{name} eye: {eye(q)}" for name, q in
                         (("left", self.left), ("right", self.right)) if name in self.eyes)


def _origins(per_eye: Sequence[EyeQuality]) -> str:
    measured = sum(t.n_measured_origin for q in per_eye for t in q.targets)
    valid = sum(t.n_valid for q in per_eye for t in q.targets)
    if measured == 0:
        return "nominal eye"
    return "measured gaze origin" if measured == valid else "measured gaze origin (partly)"


def validation_result(area: DisplayArea, distance_mm: float, per_target: Sequence[TargetData],
                      limits: QualityLimits, eyes: Sequence[str] = EYES) -> ValidationResult:
    """Quality per eye over the samples collected at each validation target; ``distance_mm`` is
    the display profile's viewing distance (the nominal eye, where no gaze origin is given);
    ``eyes``: those the tracker records (a monocular tracker's other eye is not judged)."""
    left = eye_quality(area, distance_mm, per_target, "left")
    right = eye_quality(area, distance_mm, per_target, "right")
    tracked = [q for n, q in (("left", left), ("right", right)) if n in eyes]
    return ValidationResult(left=left, right=right, targets=[d.target for d in per_target],
                            limits=limits, origins=_origins(tracked), eyes=tuple(eyes))


@dataclass
class DriftResult:
    """A drift check: the offset of the mean gaze from the central target, per eye."""

    left: TargetQuality
    right: TargetQuality
    limit_deg: float
    max_data_loss: float
    #: the eyes the tracker records
    eyes: tuple[str, ...] = EYES

    def _tracked(self) -> list[TargetQuality]:
        return [q for name, q in (("left", self.left), ("right", self.right)) if name in self.eyes]

    @property
    def offset_deg(self) -> float:
        """The worse eye's offset."""
        return _worst([q.accuracy_deg for q in self._tracked()])

    @property
    def data_loss(self) -> float:
        return max(q.data_loss for q in self._tracked())

    @property
    def failure(self) -> str | None:
        if self.data_loss > self.max_data_loss or math.isinf(self.offset_deg):
            return (f"data loss {100 * self.data_loss:.0f}% at the central target (limit "
                    f"{100 * self.max_data_loss:g}%)")
        if self.offset_deg > self.limit_deg:
            return (f"drift {self.offset_deg:.2f} deg at the centre exceeds "
                    f"{self.limit_deg:g} deg")
        return None

    @property
    def passed(self) -> bool:
        return self.failure is None

    def to_dict(self) -> dict[str, Any]:
        return {"left": asdict(self.left), "right": asdict(self.right),
                "offset_deg": self.offset_deg, "data_loss": self.data_loss,
                "limit_deg": self.limit_deg, "max_data_loss": self.max_data_loss,
                "passed": self.passed, "failure": self.failure}


def drift_result(area: DisplayArea, distance_mm: float, data: TargetData, limit_deg: float,
                 max_data_loss: float = MAX_DATA_LOSS, eyes: Sequence[str] = EYES) -> DriftResult:
    """The drift check's figures from the samples collected at the central target."""
    return DriftResult(target_quality(area, distance_mm, data, "left"),
                       target_quality(area, distance_mm, data, "right"), limit_deg,
                       max_data_loss, tuple(eyes))


def target_points(n: int) -> list[tuple[float, float]]:
    """Calibration/validation targets in normalised coordinates: the centre first (where the
    experiment's fixation cross is), then around it; 5 or 9 points, or the first ``n``."""
    ring = [CENTRE, (0.3, 0.3), (0.7, 0.3), (0.3, 0.7), (0.7, 0.7),
            (0.5, 0.3), (0.3, 0.5), (0.7, 0.5), (0.5, 0.7),
            (0.1, 0.1), (0.9, 0.1), (0.1, 0.9), (0.9, 0.9)]
    return ring[:n]
