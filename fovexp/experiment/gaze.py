"""Gaze sources behind one interface, and the gaze-contingent blanking decision.

Paper section 6.1 ("Task"): participants fixate a cross at the screen centre; "stimuli are hidden
by rendering a black frame whenever participants' gaze position moved outside a small circular
region with radius 1.25 deg at the center of the screen". Gaze arrives in normalised display-area
coordinates (origin top-left, x right, y down, as Tobii's ``gaze_point_on_display_area``);
degrees from the cross come from :meth:`fovexp.geometry.ViewingGeometry.eccentricity_deg`.

Sources: :class:`SimulatedGaze` (fixation with jitter, drift, microsaccades, saccades, blinks and
dropouts from a seed), :class:`MouseGaze` (pilot sessions), and
``fovexp.experiment.tobii.TobiiGaze`` (Tobii Pro through tobii-research). :class:`ClockedGaze` is
the shared base of sources sampled on a fixed-rate grid (the tests script gaze paths with it).
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, NamedTuple, Protocol

import numpy as np

from fovexp import ViewingGeometry

#: Paper section 6.1: gaze farther than this from the cross blanks the next frame (deg).
BLANKING_RADIUS_DEG = 1.25
#: No sample newer than this: gaze "lost", the next frame is black (s).
GAZE_TIMEOUT_S = 0.05
#: Tobii Pro Spectrum's rate in the paper (section 6.1), and the simulated sources' (Hz).
TRACKER_RATE_HZ = 600.0
#: Seconds of samples a tracker's buffer holds before the oldest are dropped.
GAZE_BUFFER_S = 120.0


class GazeSample(NamedTuple):
    """One tracker sample; positions in normalised display-area coordinates."""

    device_time_us: int
    system_time_us: int
    left_x: float
    left_y: float
    left_valid: bool
    right_x: float
    right_y: float
    right_valid: bool

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


class GazeSource(Protocol):
    """What the runner needs from a gaze source."""

    name: str

    def start(self) -> None: ...
    def stop(self) -> None: ...
    def now_us(self) -> int: ...
    def poll(self) -> list[GazeSample]: ...
    def poll_events(self) -> list[SourceEvent]: ...
    @property
    def connected(self) -> bool: ...
    def info(self) -> dict[str, Any]: ...


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


@dataclass
class BlankDecision:
    blank: bool
    reason: str  # "" when shown; "outside" / "invalid" / "lost"
    eccentricity_deg: float


class BlankingMonitor:
    """Decides per frame whether the next frame is black (paper section 6.1).

    The most recent sample decides: farther than ``radius_deg`` from the cross, invalid (no eye
    valid), or none newer than ``timeout_s`` (lost) -> black; otherwise the stimulus is shown.
    """

    def __init__(self, fixation: FixationGeometry, radius_deg: float = BLANKING_RADIUS_DEG,
                 timeout_s: float = GAZE_TIMEOUT_S) -> None:
        self.fixation = fixation
        self.radius_deg = radius_deg
        self.timeout_us = int(timeout_s * 1e6)
        self.last: GazeSample | None = None

    def update(self, samples: list[GazeSample], now_us: int) -> BlankDecision:
        if samples:
            self.last = samples[-1]
        s = self.last
        if s is None or now_us - s.system_time_us > self.timeout_us:
            return BlankDecision(True, "lost", math.inf)
        if not s.valid:
            return BlankDecision(True, "invalid", math.inf)
        ecc = self.fixation.eccentricity(s.point)
        if ecc > self.radius_deg:
            return BlankDecision(True, "outside", ecc)
        return BlankDecision(False, "", ecc)


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


@dataclass
class SimGazeParams:
    """Behaviour of :class:`SimulatedGaze` (degrees, seconds, events per second)."""

    rate_hz: float = TRACKER_RATE_HZ
    jitter_deg: float = 0.03
    drift_sd_deg: float = 0.25  # stationary sd of the slow drift (Ornstein-Uhlenbeck)
    drift_tau_s: float = 2.0
    microsaccade_rate: float = 1.0
    microsaccade_deg: float = 0.3
    saccade_rate: float = 0.05  # looks away from the cross
    saccade_deg: tuple[float, float] = (2.0, 8.0)
    saccade_dwell_s: tuple[float, float] = (0.15, 0.5)
    blink_rate: float = 0.15
    blink_s: tuple[float, float] = (0.08, 0.25)
    dropout_prob: float = 0.002
    eye_offset_deg: float = 0.05


class ClockedGaze:
    """The lifecycle shared by sources whose samples lie on a fixed ``rate_hz`` grid from
    :meth:`start` (their values depend only on the sample index, not on when the frame loop
    polls), with a connection that can be cut (:meth:`set_connected`): samples due while
    disconnected are lost, as with a tracker (they are still generated, then dropped, so that
    sample ``i`` is the same whether or not the connection was cut before it). Subclasses give
    :meth:`_sample`."""

    name = "clocked"
    #: calibrated and validated at the session's start (the mouse and scripted paths are not)
    validated = True

    def __init__(self, rate_hz: float = TRACKER_RATE_HZ,
                 clock_us: Callable[[], int] = monotonic_us) -> None:
        self.rate_hz = float(rate_hz)
        self._clock = clock_us
        self._t0: int | None = None
        self._n = 0
        self._connected = True

    def start(self) -> None:
        self._t0 = self._clock()
        self._n = 0

    def stop(self) -> None:
        pass

    def now_us(self) -> int:
        return self._clock()

    @property
    def connected(self) -> bool:
        return self._connected

    def set_connected(self, value: bool) -> None:
        """Simulate a lost (False) or restored (True) tracker connection."""
        self._connected = value

    def poll_events(self) -> list[SourceEvent]:
        return []

    def info(self) -> dict[str, Any]:
        return {"name": self.name, "rate_hz": self.rate_hz}

    def _sample(self, i: int) -> GazeSample:
        raise NotImplementedError

    def _time_us(self, i: int) -> int:
        """Device time of sample ``i`` (us from :meth:`start`)."""
        return int(i * 1e6 / self.rate_hz)

    def poll(self) -> list[GazeSample]:
        if self._t0 is None:
            self.start()
        assert self._t0 is not None
        upto = int((self._clock() - self._t0) * self.rate_hz / 1e6)
        out = [self._sample(i) for i in range(self._n, upto + 1)]
        self._n = max(self._n, upto + 1)
        return out if self._connected else []


class SimulatedGaze(ClockedGaze):
    """Fixation on the cross with jitter, drift, microsaccades, saccades away, blinks and dropouts.

    Samples lie on a fixed ``rate_hz`` grid from :meth:`start`; their values depend only on the
    seed and the sample index, not on when the frame loop polls. The fixations of calibration
    and validation (:meth:`fixate`) draw from a generator of their own, so they neither shift
    the stream nor depend on how much of it was due when they ran.
    """

    name = "simulated"

    def __init__(self, fixation: FixationGeometry, seed: int = 0,
                 params: SimGazeParams | None = None,
                 clock_us: Callable[[], int] = monotonic_us) -> None:
        self.p = params or SimGazeParams()
        super().__init__(self.p.rate_hz, clock_us)
        self.fixation = fixation
        self.rng = np.random.default_rng(seed)
        self._fix_rng = np.random.default_rng([seed, 1])
        self.seed = seed
        self._drift = np.zeros(2)
        self._away: tuple[np.ndarray, int] | None = None  # (offset, samples left)
        self._blink_left = 0

    def info(self) -> dict[str, Any]:
        return {"name": "simulated", "seed": self.seed, "rate_hz": self.p.rate_hz}

    def _sample(self, i: int) -> GazeSample:
        p, rng = self.p, self.rng
        dt = 1.0 / p.rate_hz
        a = math.exp(-dt / p.drift_tau_s)
        kick = math.sqrt(1 - a * a) * p.drift_sd_deg * rng.standard_normal(2)
        self._drift = a * self._drift + kick
        if rng.uniform() < p.microsaccade_rate * dt:
            self._drift += rng.standard_normal(2) * p.microsaccade_deg / math.sqrt(2)
        if self._away is None and rng.uniform() < p.saccade_rate * dt:
            ang = rng.uniform(0, 2 * math.pi)
            amp = rng.uniform(*p.saccade_deg)
            n = int(rng.uniform(*p.saccade_dwell_s) * p.rate_hz)
            self._away = (amp * np.array([math.cos(ang), math.sin(ang)]), n)
        offset = self._drift.copy()
        if self._away is not None:
            offset += self._away[0]
            left = self._away[1] - 1
            self._away = None if left <= 0 else (self._away[0], left)
        if self._blink_left == 0 and rng.uniform() < p.blink_rate * dt:
            self._blink_left = int(rng.uniform(*p.blink_s) * p.rate_hz)
        blink = self._blink_left > 0
        self._blink_left = max(0, self._blink_left - 1)
        eyes = []
        for sign in (-1.0, 1.0):
            d = (offset + p.jitter_deg * rng.standard_normal(2)
                 + np.array([sign * p.eye_offset_deg, 0]))
            x, y = self.fixation.offset_to_norm(float(d[0]), float(d[1]))
            ok = not blink and rng.uniform() >= p.dropout_prob and 0 <= x <= 1 and 0 <= y <= 1
            eyes.append((x if ok else math.nan, y if ok else math.nan, ok))
        t = self._time_us(i)
        assert self._t0 is not None
        return GazeSample(t, self._t0 + t, *eyes[0], *eyes[1])

    def fixate(self, target: tuple[float, float], n: int) -> list[GazeSample]:
        """``n`` samples fixating ``target`` (normalised) with jitter: the simulated participant
        during calibration and validation."""
        out = []
        t0 = self._clock()
        rng = self._fix_rng
        for i in range(n):
            eyes = []
            for _ in range(2):
                dx, dy = self.p.jitter_deg * 3 * rng.standard_normal(2)
                ok = rng.uniform() >= 0.01
                x, y = self.fixation.offset_to_norm(float(dx), float(dy), origin=target)
                eyes.append((x if ok else math.nan, y if ok else math.nan, ok))
            t = self._time_us(i)
            out.append(GazeSample(t, t0 + t, *eyes[0], *eyes[1]))
        return out


class MouseGaze:
    """The mouse pointer as gaze, for pilot sessions on a desktop: one sample per poll.

    ``position()`` returns the pointer in normalised display coordinates (origin top-left) or
    None when it is outside the window.
    """

    name = "mouse"
    validated = False

    def __init__(self, position: Callable[[], tuple[float, float] | None] | None = None) -> None:
        self.position = position
        self.connected = True

    def start(self) -> None:
        pass

    def stop(self) -> None:
        pass

    def now_us(self) -> int:
        return monotonic_us()

    def poll_events(self) -> list[SourceEvent]:
        return []

    def info(self) -> dict[str, Any]:
        return {"name": "mouse"}

    def poll(self) -> list[GazeSample]:
        if self.position is None:
            return []
        pt = self.position()
        t = monotonic_us()
        if pt is None:
            return [GazeSample(t, t, math.nan, math.nan, False, math.nan, math.nan, False)]
        return [GazeSample(t, t, pt[0], pt[1], True, pt[0], pt[1], True)]


def sample_row(trial_index: int | None, s: GazeSample, ecc: float) -> tuple[Any, ...]:
    """A ``gaze-<session>.csv`` row (see :data:`fovexp.experiment.logs.GAZE_COLUMNS`)."""
    pt = s.point
    return (trial_index, s.device_time_us, s.system_time_us,
            s.left_x, s.left_y, s.left_valid, s.right_x, s.right_y, s.right_valid,
            pt[0] if pt else None, pt[1] if pt else None, s.valid,
            None if math.isinf(ecc) else round(ecc, 4))

