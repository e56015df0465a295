"""What gaze sources share, and the gaze-contingent blanking decision.

Paper section 5.1 ("Task"): participants fixate a cross at the screen centre; "stimuli are hidden
by rendering a black frame whenever participants' gaze position moved outside a small circular
region with radius 1.25 deg at the center of the screen". Gaze arrives in normalised display-area
coordinates (origin top-left, x right, y down, as Tobii's ``gaze_point_on_display_area``);
degrees from the cross come from :meth:`fovexp.geometry.ViewingGeometry.eccentricity_deg`.

What every source shares lives here (:class:`GazeSample`, :class:`SourceEvent`, the clock
:func:`monotonic_us`, :class:`SampleBuffer`, the fixation and display-area geometry, the gaze
log's rows); the sources themselves are :mod:`fovexp.experiment.trackers`, one module each.
"""

from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

from fovexp import FovexpError, ViewingGeometry
from fovexp.results.blanking import BLANKING_RADIUS_DEG, GAZE_TIMEOUT_S, BlankingRule

from ..protocol.defaults import TRACKER_RATE_HZ

#: Seconds of samples a tracker's buffer holds before the oldest are dropped.
GAZE_BUFFER_S = 120.0


Vec3 = tuple[float, float, float]


class GazeSample(NamedTuple):
    """One tracker sample; positions in normalised display-area coordinates.

    ``*_origin_mm`` is the eye's position (the tracker's gaze origin) in the coordinate system of
    the source's :class:`DisplayArea` (a Tobii's user coordinate system: mm, x right, y up, z
    towards the user), or None where the source does not measure it or the eye was not found.
    """

    device_time_us: int
    system_time_us: int
    left_x: float
    left_y: float
    left_valid: bool
    right_x: float
    right_y: float
    right_valid: bool
    left_origin_mm: Vec3 | None = None
    right_origin_mm: Vec3 | None = None
    #: when the runner received the sample, on the ``system_time_us`` clock (None: as measured)
    received_system_time_us: int | None = None
    #: the simulated eye's true eccentricity from the cross (deg; None for a real eye)
    true_ecc_deg: float | None = None

    @property
    def received_us(self) -> int:
        """When the runner had the sample (its measurement time where the source does not say)."""
        r = self.received_system_time_us
        return self.system_time_us if r is None else r

    @property
    def valid(self) -> bool:
        return self.left_valid or self.right_valid

    @property
    def point(self) -> tuple[float, float] | None:
        """Binocular gaze: the mean of the valid eyes, or None when neither is valid."""
        if self.left_valid and self.right_valid:
            return 0.5 * (self.left_x + self.right_x), 0.5 * (self.left_y + self.right_y)
        if self.left_valid:
            return self.left_x, self.left_y
        if self.right_valid:
            return self.right_x, self.right_y
        return None


@dataclass
class SourceEvent:
    """A tracker status change noticed by a source (connection, sampling rate)."""

    kind: str  # connection_lost / connection_restored / frequency_changed / rate_deviation
    system_time_us: int
    detail: dict[str, Any] = field(default_factory=dict)


def monotonic_us() -> int:
    return time.monotonic_ns() // 1000


class FixationGeometry:
    """Degrees between a gaze point and the fixation cross (screen centre), on the display's full
    pixel grid.

    Always the exact geometry of the display profile, whatever model the protocol gives the
    enhancer: the 1.25 deg window is a physical angle at the participant's eye (a "release" model
    would measure it on the released prototype's screen, a "linear" one with a constant px/deg).
    """

    def __init__(self, display: Any) -> None:
        self.display = display
        self.geometry = ViewingGeometry.for_image(display, display.width_px, display.height_px,
                                                  "exact")
        self.cross_px = self.geometry.gaze_px((0.5, 0.5))
        cx = np.array(self.cross_px[0])
        cy = np.array(self.cross_px[1])
        #: pixels per degree at the cross, to place simulated gaze at an angle
        self.ppd_centre = float(self.geometry.ppd(cx, cy))

    def to_px(self, x: float, y: float) -> tuple[float, float]:
        return self.geometry.gaze_px((x, y))

    def eccentricity(self, point: tuple[float, float] | None) -> float:
        """Angle (deg) from the cross; ``inf`` when there is no point or it is off the screen."""
        if point is None:
            return math.inf
        x, y = point
        if not (0.0 <= x <= 1.0 and 0.0 <= y <= 1.0):
            return math.inf
        px, py = self.to_px(x, y)
        return float(self.geometry.eccentricity_deg(np.array(px), np.array(py), self.cross_px))

    def angle_between(self, a: tuple[float, float], b: tuple[float, float]) -> float:
        """Angle (deg) between two on-screen points (validation accuracy and precision)."""
        ax, ay = self.to_px(*a)
        bx, by = self.to_px(*b)
        return float(self.geometry.eccentricity_deg(np.array(ax), np.array(ay), (bx, by)))

    def offset_to_norm(self, dx_deg: float, dy_deg: float,
                       origin: tuple[float, float] = (0.5, 0.5)) -> tuple[float, float]:
        """A point ``(dx, dy)`` degrees from ``origin`` (normalised; default the cross), via the
        pixels per degree at the cross (simulation only; the blanking decision measures the
        angle exactly)."""
        g = self.geometry
        return (origin[0] + dx_deg * self.ppd_centre / g.width_px,
                origin[1] + dy_deg * self.ppd_centre / g.height_px)


@dataclass(frozen=True)
class DisplayArea:
    """The screen's active area in a tracker's coordinate system: three corners (mm).

    Normalised display coordinates ``(u, v)`` (origin top-left, x right, y down: Tobii's active
    display coordinate system, the runner's convention) lie at ``top_left + u (top_right -
    top_left) + v (bottom_left - top_left)``. A Tobii reports its area with
    ``get_display_area()`` in its user coordinate system (x right, y up, z towards the user,
    origin on the tracker), where its gaze origins are too; :meth:`nominal` is the display
    profile's screen centred on the origin, the frame the simulated eyes are placed in.
    """

    top_left: Vec3
    top_right: Vec3
    bottom_left: Vec3
    #: ``tracker`` (the tracker's own) or ``profile`` (nominal, from the display profile)
    source: str = "profile"

    @classmethod
    def nominal(cls, display: Any) -> DisplayArea:
        """The profile's screen (``width_cm`` x ``height_cm``) centred on the origin, facing +z."""
        w, h = 5.0 * float(display.width_cm), 5.0 * float(display.height_cm)  # half, in mm
        return cls((-w, h, 0.0), (w, h, 0.0), (-w, -h, 0.0), "profile")

    @classmethod
    def from_sdk(cls, area: Any) -> DisplayArea:
        """From a ``tobii_research.DisplayArea``."""
        def vec(c: Any) -> Vec3:
            x, y, z = (float(v) for v in c)
            return (x, y, z)
        return cls(vec(area.top_left), vec(area.top_right), vec(area.bottom_left), "tracker")

    def _axes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        tl = np.asarray(self.top_left, dtype=np.float64)
        return (tl, np.asarray(self.top_right, dtype=np.float64) - tl,
                np.asarray(self.bottom_left, dtype=np.float64) - tl)

    @property
    def width_mm(self) -> float:
        return float(np.linalg.norm(self._axes()[1]))

    @property
    def height_mm(self) -> float:
        return float(np.linalg.norm(self._axes()[2]))

    @property
    def centre_mm(self) -> np.ndarray:
        tl, ux, vy = self._axes()
        return tl + 0.5 * ux + 0.5 * vy

    @property
    def normal(self) -> np.ndarray:
        """Unit normal of the screen, towards the viewer."""
        _, ux, vy = self._axes()
        n = np.cross(vy, ux)  # (down) x (right) = towards the viewer
        return n / np.linalg.norm(n)

    def points_mm(self, u: Any, v: Any) -> np.ndarray:
        """Normalised display coordinates (arrays of N) -> points on the screen, (N, 3) mm."""
        tl, ux, vy = self._axes()
        u = np.asarray(u, dtype=np.float64)[..., None]
        v = np.asarray(v, dtype=np.float64)[..., None]
        return tl + u * ux + v * vy

    def eye_mm(self, distance_mm: float) -> np.ndarray:
        """The nominal eye: ``distance_mm`` in front of the screen centre, on its normal (the
        position the display profile's viewing distance assumes)."""
        return self.centre_mm + float(distance_mm) * self.normal

    def distance_mm(self, origin_mm: Any) -> float:
        """The eye's distance from the screen plane (mm)."""
        return float(np.dot(np.asarray(origin_mm, dtype=np.float64) - self.centre_mm,
                            self.normal))

    def to_dict(self) -> dict[str, Any]:
        return {"top_left": list(self.top_left), "top_right": list(self.top_right),
                "bottom_left": list(self.bottom_left), "width_mm": round(self.width_mm, 2),
                "height_mm": round(self.height_mm, 2), "source": self.source}


#: Half the typical adult interpupillary distance (63 mm): the simulated eyes' offsets (mm).
HALF_IPD_MM = 31.5
#: A tracker's display area may differ from the display profile's physical size by this much
#: (mm, width and height each). A width off by e mm misplaces normalised gaze by up to e/2 mm
#: (at the cross when the area's top-left corner is right): 1.5 mm, 0.12 deg at 71.5 cm, a tenth
#: of the 1.25 deg window; 3 mm still allows for the millimetre to which a tape measure reads
#: each of the two sizes.
DISPLAY_AREA_TOLERANCE_MM = 3.0


def check_display_area(area: DisplayArea, display: Any,
                       tolerance_mm: float = DISPLAY_AREA_TOLERANCE_MM) -> dict[str, Any]:
    """The tracker's display area against the display profile's physical size.

    Normalised gaze coordinates are fractions of the area the tracker was told the screen is:
    when that is not the screen the profile describes, every angle computed from them is wrong.
    Returns both sizes (for the session file); raises FovexpError naming both when they differ
    by more than ``tolerance_mm`` in width or height.
    """
    tracker = (area.width_mm, area.height_mm)
    profile = (10.0 * float(display.width_cm), 10.0 * float(display.height_cm))
    diff = (tracker[0] - profile[0], tracker[1] - profile[1])
    info = {"tracker_mm": [round(v, 2) for v in tracker],
            "profile_mm": [round(v, 2) for v in profile],
            "difference_mm": [round(v, 2) for v in diff], "tolerance_mm": tolerance_mm,
            "display_area": area.to_dict()}
    if max(abs(diff[0]), abs(diff[1])) > tolerance_mm:
        raise FovexpError(
            f"the eye tracker's display area is {tracker[0]:.1f} x {tracker[1]:.1f} mm, but "
            f"display profile {display.name!r} says {profile[0]:.1f} x {profile[1]:.1f} mm "
            f"(more than {tolerance_mm:g} mm apart): set the display area in Tobii Pro Eye "
            "Tracker Manager (Display setup) to this screen's active area, or correct "
            "width_cm/height_cm in the display profile")
    return info


def ray_angles_deg(origins_mm: np.ndarray, a_mm: np.ndarray, b_mm: np.ndarray) -> np.ndarray:
    """Angle (deg) at each origin between the rays to points ``a`` and ``b`` (arrays of shape
    (N, 3) or broadcastable): ``atan2(|r_a x r_b|, r_a . r_b)``, accurate at small angles too."""
    ra = np.asarray(a_mm, dtype=np.float64) - origins_mm
    rb = np.asarray(b_mm, dtype=np.float64) - origins_mm
    ra, rb = np.broadcast_arrays(ra, rb)
    cross = np.linalg.norm(np.cross(ra, rb), axis=-1)
    return np.degrees(np.arctan2(cross, np.einsum("...i,...i->...", ra, rb)))


@dataclass
class BlankDecision:
    blank: bool
    reason: str  # "" when shown; "outside" / "invalid" / "lost"
    #: the newest sample's angle from the cross (inf: no sample, or an invalid one)
    eccentricity_deg: float
    #: when the decision was made, on the gaze source's clock (us): the newest sample's age is
    #: measured against it (the frame log's ``decide_system_time_us``)
    decided_us: int = 0


class BlankingMonitor:
    """Decides per frame whether the next frame is black (paper section 5.1), by the one
    definition of the rule (:class:`fovexp.results.blanking.BlankingRule`).

    The most recent sample decides: none, or none newer than ``timeout_s`` at the decision
    (lost), invalid (no eye valid), or farther than ``radius_deg`` from the cross -> black;
    otherwise the stimulus is shown.
    """

    def __init__(self, fixation: FixationGeometry, radius_deg: float = BLANKING_RADIUS_DEG,
                 timeout_s: float = GAZE_TIMEOUT_S) -> None:
        self.fixation = fixation
        self.rule = BlankingRule(radius_deg, timeout_s)
        self.radius_deg = radius_deg
        self.timeout_us = self.rule.timeout_us
        self.last: GazeSample | None = None
        self._pending: deque[GazeSample] = deque()

    def update(self, samples: list[GazeSample], now_us: int) -> BlankDecision:
        """Take the samples since the last call; decide a frame at ``now_us`` (the source's
        clock, read at the poll, before the samples were taken): the newest sample received by
        then decides, and one received later (a poll is not instant) waits for the next
        decision, so that the rule holds against every sample received before it."""
        if samples:
            self._pending.extend(samples)
        while self._pending and self._pending[0].received_us <= now_us:
            self.last = self._pending.popleft()
        s = self.last
        age = None if s is None else now_us - s.system_time_us
        valid = s is not None and s.valid
        ecc = self.fixation.eccentricity(s.point) if valid and s is not None else math.inf
        reason = self.rule.reason(age, valid, ecc)
        return BlankDecision(reason != "", reason, ecc, now_us)


#: How the blanking decision measures a sample's angle (the session file's ``blanking_rule``).
ANGLE_RULE = (
    "binocular gaze point (the mean of the valid eyes) on the screen; its angle from the cross "
    "seen from the nominal eye (the display profile's distance on the screen normal through the "
    "cross), not from the eyes' measured origins; off the screen or no valid eye: black")


def rule_record(radius_deg: float, timeout_s: float) -> dict[str, Any]:
    """The blanking rule a session ran with, for its session file (docs/EXPERIMENT.md, "Gaze
    truth"): the radius, the sample timeout, how the angle is computed and when the decision is
    taken."""
    return {"radius_deg": radius_deg, "gaze_timeout_s": timeout_s, "angle": ANGLE_RULE,
            "decision": "at the poll: the newest sample received by then decides"}


class SampleBuffer:
    """A thread-safe FIFO filled by a tracker thread and drained by the frame loop.

    ``deque.append`` and ``popleft`` are atomic in CPython, so the producer never takes a lock.
    """

    def __init__(self, maxlen: int = int(TRACKER_RATE_HZ * GAZE_BUFFER_S)) -> None:
        self._q: deque[Any] = deque(maxlen=maxlen)

    def append(self, item: Any) -> None:
        self._q.append(item)

    def drain(self) -> list[Any]:
        out = []
        q = self._q
        while True:
            try:
                out.append(q.popleft())
            except IndexError:
                return out


def sample_row(trial_index: int | None, attempt: int | None, s: GazeSample,
               ecc: float) -> tuple[Any, ...]:
    """A ``gaze-<session>.csv`` row (:data:`fovexp.results.format.GAZE_COLUMNS`)."""
    pt = s.point
    return (trial_index, attempt, s.device_time_us, s.system_time_us,
            s.left_x, s.left_y, s.left_valid, s.right_x, s.right_y, s.right_valid,
            pt[0] if pt else None, pt[1] if pt else None, s.valid,
            None if math.isinf(ecc) else round(ecc, 4)) + origin_fields(s) + (
            s.received_us, None if s.true_ecc_deg is None else round(s.true_ecc_deg, 4))


def origin_fields(s: GazeSample) -> tuple[float | None, ...]:
    """The gaze log's origin columns (:data:`fovexp.results.format.GAZE_ORIGIN_COLUMNS`)."""
    out: list[float | None] = []
    for o in (s.left_origin_mm, s.right_origin_mm):
        out += [None] * 3 if o is None else [round(float(v), 2) for v in o]
    return tuple(out)

