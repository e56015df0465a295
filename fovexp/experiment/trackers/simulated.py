"""The simulated eye tracker of dry runs and CI: fixation with jitter, drift, microsaccades,
saccades away from the cross, blinks and dropouts, from a seed, sampled on a fixed-rate grid of
the monotonic clock (:class:`ClockedGaze`, the base the tests also script gaze paths with);
it looks at calibration, validation and drift-check targets when told
(:meth:`SimulatedGaze.look_at`), with a stated calibration error.

Its behaviour is a :class:`SimGazeParams`, by name (:data:`PRESETS`: ``steady``, the default,
and ``wandering``) with single settings on top (:func:`parse_sim_gaze`: ``fovexp run --dry-run
--sim-gaze wandering,blink_rate=0.3``). A saccade away from the cross and back follows the main
sequence: it lasts :func:`saccade_duration_s` (Carpenter 1988's 2.2 ms/deg + 21 ms) on a
minimum-jerk path, so its landing is a moment a study can measure against. Each sample carries
the eye's true eccentricity (the gaze without its measurement noise), and reaches the runner
after a delivery latency, constant or with jitter (``latency_ms``, ``latency_jitter_ms``):
its time stamps stay those of the measurement."""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from fovexp import FovexpError

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
    #: the tracker's delivery latency: each sample reaches the runner this long after it was
    #: measured (ms), plus a normal jitter of this sd, truncated at 0 (in order, as a tracker's)
    latency_ms: float = 0.0
    latency_jitter_ms: float = 0.0


#: Named behaviours of the simulated eye (``--sim-gaze``). ``steady``: the default, a
#: participant who keeps fixating; ``wandering``: one who looks away about once a second for
#: 0.15-0.5 s, blinks every two seconds and loses 2 % of the samples per eye, so that a trial
#: is blanked about a third of its time or more (the gating study's hard case).
PRESETS: dict[str, SimGazeParams] = {
    "steady": SimGazeParams(),
    "wandering": SimGazeParams(saccade_rate=1.0, saccade_deg=(2.0, 10.0), blink_rate=0.5,
                               dropout_prob=0.02),
}
#: Carpenter (1988), "Movements of the Eyes": a saccade's duration grows linearly with its
#: amplitude, about 2.2 ms per degree plus 21 ms (the main sequence, up to ~50 deg).
SACCADE_MS_PER_DEG = 2.2
SACCADE_MIN_MS = 21.0


def saccade_duration_s(amplitude_deg: float) -> float:
    """A saccade's duration on the main sequence (:data:`SACCADE_MS_PER_DEG`)."""
    return (SACCADE_MIN_MS + SACCADE_MS_PER_DEG * abs(amplitude_deg)) / 1e3


def minimum_jerk(tau: float) -> float:
    """The minimum-jerk position profile from 0 to 1 over ``tau`` in [0, 1] (Flash and Hogan
    1985): its peak velocity, 1.875 amplitudes per duration, matches the main sequence's
    within its scatter (8 deg in 38.6 ms: 389 deg/s)."""
    t = min(max(tau, 0.0), 1.0)
    return t * t * t * (10.0 - 15.0 * t + 6.0 * t * t)


def parse_sim_gaze(text: str) -> SimGazeParams:
    """``PRESET[,field=value,...]`` as :class:`SimGazeParams` (a pair as ``lo:hi``); raises
    :class:`FovexpError` naming what is wrong."""
    import dataclasses

    name, *pairs = [p.strip() for p in text.split(",") if p.strip()] or ["steady"]
    if "=" in name:
        name, pairs = "steady", [name, *pairs]
    if name not in PRESETS:
        raise FovexpError(f"--sim-gaze: no preset {name!r} (presets: {', '.join(PRESETS)})")
    fields = {f.name: f for f in dataclasses.fields(SimGazeParams)}
    values: dict[str, Any] = {}
    for pair in pairs:
        key, _, raw = pair.partition("=")
        key = key.strip()
        if key not in fields or not raw:
            raise FovexpError(f"--sim-gaze: {pair!r} is not a setting=value of the simulated "
                              f"eye (settings: {', '.join(fields)})")
        try:
            nums = tuple(float(v) for v in raw.split(":"))
        except ValueError:
            raise FovexpError(f"--sim-gaze: {key}={raw!r} is not a number") from None
        default = getattr(PRESETS["steady"], key)
        want = len(default) if isinstance(default, tuple) else 1
        if len(nums) != want or any(not math.isfinite(v) or v < 0 for v in nums):
            raise FovexpError(f"--sim-gaze: {key} takes {want} non-negative number(s)"
                              f"{' as lo:hi' if want == 2 else ''}, not {raw!r}")
        values[key] = nums if want > 1 else nums[0]
    params = dataclasses.replace(PRESETS[name], **values)
    if params.rate_hz <= 0:
        raise FovexpError("--sim-gaze: rate_hz must be above 0")
    return params


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
                 clock_us: Callable[[], int] = monotonic_us, latency_ms: float = 0.0,
                 latency_jitter_ms: float = 0.0, latency_seed: int = 0) -> None:
        self.rate_hz = float(rate_hz)
        self._clock = clock_us
        self._t0: int | None = None
        self._n = 0
        self._connected = True
        self.latency_ms, self.latency_jitter_ms = float(latency_ms), float(latency_jitter_ms)
        self._latency_seed = latency_seed
        self._in_flight: deque[GazeSample] = deque()  # measured, not yet delivered

    def start(self) -> None:
        self._t0 = self._clock()
        self._n = 0
        self._in_flight.clear()
        self._last_received = self._t0
        self._latency_rng = np.random.default_rng([self._latency_seed, 2])

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

    def _received(self, s: GazeSample) -> GazeSample:
        """``s`` with when it reaches the runner: after the delivery latency, in order."""
        lat_us = 1e3 * self.latency_ms
        if self.latency_jitter_ms > 0:
            lat_us += 1e3 * self.latency_jitter_ms * float(self._latency_rng.standard_normal())
        received = max(s.system_time_us + max(0, round(lat_us)), self._last_received)
        self._last_received = received
        return s._replace(received_system_time_us=received)

    def _measured_by(self, now: int) -> list[GazeSample]:
        """The samples measured since the last poll, up to ``now`` (on the rate's grid)."""
        assert self._t0 is not None
        upto = int((now - self._t0) * self.rate_hz / 1e6)
        out = [self._sample(i) for i in range(self._n, upto + 1)]
        self._n = max(self._n, upto + 1)
        return out

    def poll(self) -> list[GazeSample]:
        """The samples received by now: those measured up to now, each after its delivery
        latency (none while disconnected: samples due then are lost)."""
        if self._t0 is None:
            self.start()
        now = self._clock()
        self._in_flight.extend(self._received(s) for s in self._measured_by(now))
        out = []
        while self._in_flight and self._in_flight[0].received_us <= now:
            out.append(self._in_flight.popleft())
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
        super().__init__(self.p.rate_hz, clock_us, self.p.latency_ms, self.p.latency_jitter_ms,
                         seed)
        self.fixation = fixation
        self.rng = np.random.default_rng(seed)
        self.seed = seed
        self._drift = np.zeros(2)
        #: a look away: (offset at landing, samples since its start, samples of the flight
        #: out, of the dwell, of the flight back)
        self._away: tuple[np.ndarray, int, int, int, int] | None = None
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
        import dataclasses

        return {"name": "simulated", "seed": self.seed, "rate_hz": self.p.rate_hz,
                "params": dataclasses.asdict(self.p)}

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
            fly = max(1, round(saccade_duration_s(amp) * p.rate_hz))
            self._away = (amp * np.array([math.cos(ang), math.sin(ang)]), 0, fly, n, fly)
        offset = self._drift.copy()
        if self._away is not None:
            land, k, out, dwell, back = self._away
            # out along the main sequence, the dwell, back to the cross the same way
            f = (minimum_jerk((k + 1) / out) if k < out else 1.0 if k < out + dwell
                 else 1.0 - minimum_jerk((k + 1 - out - dwell) / back))
            offset += f * land
            k += 1
            self._away = None if k >= out + dwell + back else (land, k, out, dwell, back)
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
        true_ecc: float | None = self.fixation.eccentricity(
            self.fixation.offset_to_norm(float(offset[0]), float(offset[1])))
        if target is not None:
            eyes, true_ecc = self._on_target(i, target), None
        assert self._t0 is not None
        origins = [o if e[2] else None for o, e in zip(self._eyes_mm, eyes, strict=True)]
        return GazeSample(t, self._t0 + t, *eyes[0], *eyes[1], *origins,
                          true_ecc_deg=true_ecc)

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
