"""The simulated eye tracker of dry runs and CI: fixation with jitter, drift, microsaccades,
saccades away from the cross, blinks and dropouts, from a seed, sampled on a fixed-rate grid of
the monotonic clock (:class:`ClockedGaze`, the base the tests also script gaze paths with);
it looks at calibration, validation and drift-check targets when told
(:meth:`SimulatedGaze.look_at`), with a stated calibration error."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..protocol.defaults import TRACKER_RATE_HZ
from .gaze import (
    HALF_IPD_MM,
    DisplayArea,
    FixationGeometry,
    GazeSample,
    SourceEvent,
    Vec3,
    monotonic_us,
)


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
    #: looking at a calibration, validation or drift-check target (:meth:`SimulatedGaze.look_at`)
    target_latency_s: float = 0.15  # the saccade to a new target lands this much later
    target_jitter_deg: float = 0.09  # per-sample noise around the target, per axis
    target_loss: float = 0.01  # fraction of samples lost per eye
    #: systematic error (deg, x right, y down) of the gaze at targets that a calibration leaves
    target_offset_deg: tuple[float, float] = (0.0, 0.0)
    #: the head's offset (mm) from the nominal eye position (the profile's distance on the screen
    #: normal through its centre), in the nominal display area's frame (x right, y up, z out)
    head_offset_mm: tuple[float, float, float] = (0.0, 0.0, 0.0)


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
    """Fixation on the cross with jitter, drift, microsaccades, saccades away, blinks and dropouts;
    or, after :meth:`look_at`, on a calibration/validation target.

    Samples lie on a fixed ``rate_hz`` grid from :meth:`start`; their values depend only on the
    seed, the sample index and the target being looked at, not on when the frame loop polls.
    The fixation stream draws the same random numbers whether or not a target is looked at, and
    the samples on a target draw from a generator of their own per sample index, so looking at
    targets shifts neither the stream after it nor depends on when it was asked for. Each
    sample carries the eyes' positions (gaze origins) in the nominal display area's frame
    (:meth:`DisplayArea.nominal`), the eyes half an interpupillary distance either side of the
    nominal eye position.
    """

    name = "simulated"

    def __init__(self, fixation: FixationGeometry, seed: int = 0,
                 params: SimGazeParams | None = None,
                 clock_us: Callable[[], int] = monotonic_us) -> None:
        self.p = params or SimGazeParams()
        super().__init__(self.p.rate_hz, clock_us)
        self.fixation = fixation
        self.rng = np.random.default_rng(seed)
        self.seed = seed
        self._drift = np.zeros(2)
        self._away: tuple[np.ndarray, int] | None = None  # (offset, samples left)
        self._blink_left = 0
        #: (device time from start, target or None) in time order: what the eye looks at
        self._targets: list[tuple[int, tuple[float, float] | None]] = []
        self.area = DisplayArea.nominal(fixation.display)
        self._eyes_mm = self._eye_positions()
        #: the systematic error at targets now (deg): ``target_offset_deg`` after a
        #: calibration (``calibration.SimulatedCalibration``); add to it to simulate drift
        self.calibration_error_deg: tuple[float, float] = tuple(self.p.target_offset_deg)

    def _eye_positions(self) -> tuple[Vec3, Vec3]:
        eye = self.area.eye_mm(10.0 * float(self.fixation.display.distance_cm))
        eye = eye + np.asarray(self.p.head_offset_mm, dtype=np.float64)
        half = np.array([HALF_IPD_MM, 0.0, 0.0])
        left, right = eye - half, eye + half
        return ((float(left[0]), float(left[1]), float(left[2])),
                (float(right[0]), float(right[1]), float(right[2])))

    def info(self) -> dict[str, Any]:
        return {"name": "simulated", "seed": self.seed, "rate_hz": self.p.rate_hz}

    def display_area(self) -> DisplayArea:
        """The frame the simulated gaze origins are in (the profile's nominal screen)."""
        return self.area

    def look_at(self, target: tuple[float, float] | None) -> None:
        """From ``target_latency_s`` from now the eye fixates ``target`` (normalised; None: back
        to the cross)."""
        if self._t0 is None:
            self.start()
        assert self._t0 is not None
        t = self._clock() - self._t0 + int(self.p.target_latency_s * 1e6)
        self._targets.append((t, target))

    def _target_at(self, t_us: int) -> tuple[float, float] | None:
        for start, target in reversed(self._targets):
            if start <= t_us:
                return target
        return None

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
        target = self._target_at(t)
        if target is not None:
            eyes = self._on_target(i, target)
        assert self._t0 is not None
        origins = [o if e[2] else None for o, e in zip(self._eyes_mm, eyes, strict=True)]
        return GazeSample(t, self._t0 + t, *eyes[0], *eyes[1], *origins)

    def _on_target(self, i: int, target: tuple[float, float]) -> list[tuple[float, float, bool]]:
        """Sample ``i`` of the eyes fixating ``target``: its own generator per index."""
        p = self.p
        rng = np.random.default_rng([self.seed, 1, i])
        eyes = []
        for _ in range(2):
            dx, dy = (np.asarray(self.calibration_error_deg)
                      + p.target_jitter_deg * rng.standard_normal(2))
            ok = rng.uniform() >= p.target_loss
            x, y = self.fixation.offset_to_norm(float(dx), float(dy), origin=target)
            eyes.append((x if ok else math.nan, y if ok else math.nan, ok))
        return eyes
