"""The eye-tracker calibration screen and the drift check, as logic without a window.

The screen follows Titta's (Niehorster, Andersson & Nystrom 2020; docs/EXPERIMENT.md says why
Titta itself is not used): a head-position box showing where the eyes are in the tracker's track
box and how far they are from the screen; animated targets (Thaler et al. 2013's "ABC" target,
moving from point to point, shrinking, then pulsing while data are collected, with the sizes and
times of Titta's ``AnimatedCalibrationDisplay``); then a validation and a result screen plotting,
per target and eye, the gaze samples and the mean gaze, with accept, redo one point, redo all,
revalidate and a quit key with confirmation. The operator drives it with the keyboard; a dry run
answers every screen itself (accept when the validation passed, else recalibrate, twice, then
fail).

:class:`CalibrationFlow` and :class:`DriftCheck` are state machines fed with the time (the gaze
source's clock, us), the gaze samples and the keys pressed; :meth:`view` says what to draw as
plain data (:class:`HeadBoxView`, :class:`TargetView`, :class:`ResultView`, :class:`TextView`),
which ``window.PsychoScreen.calibration_frame`` draws. The tracker's own calibration (the Tobii
SDK's) is a :class:`CalibrationBackend`; its blocking calls run on a worker thread, so the target
keeps moving while the tracker collects.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from .gaze import DisplayArea, GazeSample, Vec3
from .quality import (
    CENTRE,
    EYES,
    DriftResult,
    QualityLimits,
    TargetData,
    ValidationResult,
    drift_result,
    validation_result,
)
from .simulated import SimulatedGaze

#: Keys the calibration screens read (PsychoPy names).
CAL_KEYS = ["space", "return", "num_enter", "q", "y", "n", "escape", "r", "v", "s", "t", "c",
            "d", *[str(i) for i in range(1, 10)]]
#: The eye-to-screen distance may be off the profile's by this much (mm) for the head-position
#: box to show it as right: 30 mm is 4 % of 71.5 cm, so every angle (the 1.25 deg window's
#: included) is off by at most 4 %, 0.05 deg at the window's edge.
DISTANCE_TOLERANCE_MM = 30.0
#: Eyes within this margin of the track box's edges are shown as "near the edge".
BOX_MARGIN = 0.15
#: A dry run's automatic answers: recalibrations before it gives up.
AUTO_RETRIES = 2
#: Gaze origins older than this (s) no longer say where the eyes are.
ORIGIN_STALE_S = 0.5
#: Samples drawn per target and eye on the result screen.
PLOT_SAMPLES = 60


# -- the tracker's calibration -----------------------------------------------------------------

@dataclass
class PointSamples:
    """The tracker's calibration samples at one point, per eye: (x, y, used), normalised."""

    left: list[tuple[float, float, bool]] = field(default_factory=list)
    right: list[tuple[float, float, bool]] = field(default_factory=list)


@dataclass
class CalibrationOutcome:
    """What computing a calibration gave: whether it failed (and why) and, where the tracker
    reports them, its samples per calibration point."""

    failed: bool
    status: str
    points: dict[tuple[float, float], PointSamples] = field(default_factory=dict)
    reason: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {"failed": self.failed, "status": self.status, "reason": self.reason,
                "points": [{"target": list(t), "left_used": sum(u for *_, u in p.left),
                            "right_used": sum(u for *_, u in p.right), "samples": len(p.left)}
                           for t, p in self.points.items()]}


class CalibrationBackend(Protocol):
    """A tracker's own calibration (``tobii.TobiiCalibration``; :class:`SimulatedCalibration`
    and the ioHub sources' on :class:`TrackerOwnCalibration`).
    The calls may block; the flow runs them on a worker thread."""

    def begin(self) -> None: ...
    def collect(self, x: float, y: float) -> bool: ...
    def discard(self, x: float, y: float) -> None: ...
    def compute(self) -> CalibrationOutcome: ...
    def end(self) -> None: ...
    def user_position(self) -> tuple[Vec3 | None, Vec3 | None]: ...


class TrackerOwnCalibration:
    """The steps of a :class:`CalibrationBackend` for a tracker that collects nothing at
    fovexp's targets (a simulated gaze, a tracker calibrated by its own software, a pointer):
    the targets are shown and validated by fovexp; only :meth:`compute` differs."""

    def begin(self) -> None:
        pass

    def collect(self, x: float, y: float) -> bool:
        return True

    def discard(self, x: float, y: float) -> None:
        pass

    def compute(self) -> CalibrationOutcome:
        raise NotImplementedError

    def end(self) -> None:
        pass

    def user_position(self) -> tuple[Vec3 | None, Vec3 | None]:
        return None, None


#: The track box assumed where a tracker gives no position guide (mm: width, height, depth around
#: the nominal eye; about a Tobii Pro Spectrum's at 65 cm).
TRACK_BOX_MM = (340.0, 260.0, 300.0)


def guide_from_origins(origins: Sequence[Vec3 | None], area: DisplayArea,
                       distance_mm: float) -> tuple[Vec3 | None, Vec3 | None]:
    """Eye positions (the area's frame, mm) as a position guide would give them: normalised in a
    :data:`TRACK_BOX_MM` box centred on the nominal eye, Tobii's convention (x towards the
    participant's left, y down, z away from the screen, 0.5 the middle)."""
    tl, tr, bl = (np.asarray(c, dtype=np.float64) for c in
                  (area.top_left, area.top_right, area.bottom_left))
    right = (tr - tl) / np.linalg.norm(tr - tl)
    up = (tl - bl) / np.linalg.norm(tl - bl)
    nominal = area.eye_mm(distance_mm)
    w, h, d = TRACK_BOX_MM
    out: list[Vec3 | None] = []
    for o in origins:
        if o is None:
            out.append(None)
            continue
        rel = np.asarray(o, dtype=np.float64) - nominal
        out.append((0.5 - float(rel @ right) / w, 0.5 - float(rel @ up) / h,
                    0.5 + float(rel @ area.normal) / d))
    return out[0], out[1]


class SimulatedCalibration(TrackerOwnCalibration):
    """The simulated tracker's calibration: it resets the simulated gaze's error at targets to
    the parameters' ``target_offset_deg`` (whatever drift was added since); its position guide
    comes from the simulated eyes' positions (:func:`guide_from_origins`)."""

    def __init__(self, gaze: SimulatedGaze) -> None:
        self.gaze = gaze

    def compute(self) -> CalibrationOutcome:
        # a calibration removes any drift: what is left is the simulated calibration's error
        self.gaze.calibration_error_deg = tuple(self.gaze.p.target_offset_deg)
        return CalibrationOutcome(failed=False, status="simulated")

    def user_position(self) -> tuple[Vec3 | None, Vec3 | None]:
        g = self.gaze
        return guide_from_origins(g._eyes_mm, g.area, 10.0 * float(g.fixation.display.distance_cm))


# -- what to draw --------------------------------------------------------------------------------

@dataclass
class TargetView:
    """An ABC target (Thaler et al. 2013): a dark disc of ``back_px`` diameter, a light cross
    and a dark centre dot of ``front_px``, centred exactly on ``pos`` (normalised)."""

    pos: tuple[float, float]
    back_px: float
    front_px: float


@dataclass
class HeadBoxView:
    """Where the eyes are in the track box, as a mirror shows them (x right, y down, 0...1),
    with a head outline scaled by how near the eyes are; ``ok`` when both eyes are well inside
    the box and at the right distance from the screen."""

    eyes: tuple[tuple[float, float] | None, tuple[float, float] | None]
    scale: float
    distance_mm: float | None
    ok: bool
    text: str
    prompt: str


@dataclass
class ResultPoint:
    number: int
    target: tuple[float, float]
    #: per eye ("left", "right"): samples (normalised) and the mean gaze, or None
    samples: dict[str, list[tuple[float, float]]]
    mean: dict[str, tuple[float, float] | None]
    label: str
    ok: bool


@dataclass
class ResultView:
    title: str
    mode: str  # "validation" or "calibration"
    points: list[ResultPoint]
    text: str
    prompt: str
    passed: bool
    #: the fixation window's radius (px) drawn around the central target
    window_radius_px: float
    #: the targets' size (px)
    target_px: float


@dataclass
class TextView:
    text: str
    prompt: str = ""
    #: drawn dimmed behind the text (the screen a quit confirmation interrupts)
    behind: Any = None


View = TargetView | HeadBoxView | ResultView | TextView


@dataclass(frozen=True)
class CalibrationTiming:
    """Durations (s). Defaults: Titta's (``settings.cal/val.paceDuration`` 0.8 s, validation
    ``collectDuration`` 0.5 s; ``AnimatedCalibrationDisplay``: a move across the whole screen
    width in 1 s, shrinking in 0.5 s, a 1.5 s pulse)."""

    move_s_per_width: float = 1.0
    shrink_s: float = 0.5
    cal_pace_s: float = 0.8
    val_pace_s: float = 0.8
    collect_s: float = 0.5
    oscillate_s: float = 1.5
    #: samples stamped inside a collection window may arrive this much later
    late_s: float = 0.05
    #: a dry run answers a screen that waits for a key after this long (None: never)
    auto_s: float | None = None

    @classmethod
    def dry_run(cls) -> CalibrationTiming:
        """Short enough for CI, long enough for the simulated eye's 0.15 s saccade latency."""
        return cls(move_s_per_width=0.1, shrink_s=0.05, cal_pace_s=0.05, val_pace_s=0.2,
                   collect_s=0.1, late_s=0.02, auto_s=0.1)


@dataclass(frozen=True)
class TargetStyle:
    """Target sizes (deg): Titta's ``AnimatedCalibrationDisplay`` (50/15/35/5 px at its 40-ish
    px/deg) in degrees, so the target looks the same on the 4K screen."""

    back_max_deg: float = 1.2
    back_min_deg: float = 0.35
    back_pulse_deg: float = 0.85
    front_deg: float = 0.12


class _Animator:
    """Titta's target animation: move (accelerating then decelerating) to the next point,
    shrink, then pulse."""

    def __init__(self, size_px: tuple[int, int], ppd_px: float, timing: CalibrationTiming,
                 style: TargetStyle) -> None:
        self.w, self.h = size_px
        self.timing = timing
        self.back_max = style.back_max_deg * ppd_px
        self.back_min = style.back_min_deg * ppd_px
        self.back_pulse = style.back_pulse_deg * ppd_px
        self.front = max(2.0, style.front_deg * ppd_px)
        self.pos: tuple[float, float] | None = None
        self.src: tuple[float, float] | None = None
        self.t_move = 0.0
        self.move_s = 0.0
        self.t_arrive: float | None = None

    def go(self, pos: tuple[float, float], t: float) -> None:
        self.src = self.pos if self.pos is not None else pos
        dist = math.hypot((pos[0] - self.src[0]) * self.w, (pos[1] - self.src[1]) * self.h)
        self.move_s = self.timing.move_s_per_width * dist / self.w
        self.pos, self.t_move, self.t_arrive = pos, t, None

    def arrived(self, t: float) -> bool:
        """True once the target is at its point (the first call that sees it sets the arrival
        time: the shrinking and the pace count from then)."""
        if self.t_arrive is None and t - self.t_move >= self.move_s - 1e-9:
            self.t_arrive = t
        return self.t_arrive is not None

    def view(self, t: float) -> TargetView:
        assert self.pos is not None and self.src is not None
        tm = self.timing
        if self.t_arrive is None:  # moving: constant acceleration, then deceleration
            f = min(1.0, (t - self.t_move) / self.move_s) if self.move_s > 0 else 1.0
            e = 2 * f * f if f < 0.5 else 1 - 2 * (1 - f) ** 2
            pos = (self.src[0] + e * (self.pos[0] - self.src[0]),
                   self.src[1] + e * (self.pos[1] - self.src[1]))
            return TargetView(pos, self.back_max, self.front)
        dt = t - self.t_arrive
        if dt < tm.shrink_s:
            back = self.back_max - (self.back_max - self.back_min) * dt / tm.shrink_s
        else:  # pulse, starting small
            phase = math.cos((dt - tm.shrink_s) / tm.oscillate_s * 2 * math.pi)
            back = self.back_min + (1 - (phase / 2 + 0.5)) * (self.back_pulse - self.back_min)
        return TargetView(self.pos, back, self.front)


#: The keys that ask to quit, on every screen of the runner.
QUIT_KEYS = ("q", "escape")
#: The one confirmation they lead to (also the session's message screens'): Y quits, N or
#: Escape goes back.
QUIT_QUESTION = "Quit the session? Everything so far is saved; continue later with --resume."
QUIT_PROMPT = "Y: quit    N: go back"


def _confirm(behind: Any) -> TextView:
    return TextView(QUIT_QUESTION, QUIT_PROMPT, behind)


def head_box_view(guide: tuple[Vec3 | None, Vec3 | None], distance_mm: float | None,
                  nominal_mm: float, prompt: str,
                  tolerance_mm: float = DISTANCE_TOLERANCE_MM) -> HeadBoxView:
    """The head-position screen from the position guide (track box coordinates, Tobii's
    convention) and the eyes' measured distance from the screen."""
    eyes = tuple(None if g is None else (1.0 - g[0], g[1]) for g in guide)  # as in a mirror
    lines = []
    found = [e is not None for e in eyes]
    if not any(found):
        lines.append("No eyes found: look at the screen, chin on the rest.")
    elif not all(found):
        lines.append(f"Only the {'left' if found[0] else 'right'} eye found.")
    inside = all(e is not None and BOX_MARGIN <= e[0] <= 1 - BOX_MARGIN
                 and BOX_MARGIN <= e[1] <= 1 - BOX_MARGIN for e in eyes)
    if any(found) and not inside:
        lines.append("Near the edge of the tracker's box: centre the head (move the chin-rest).")
    if distance_mm is None:
        lines.append("Distance to the screen: not measured.")
        dist_ok = False
    else:
        off = distance_mm - nominal_mm
        dist_ok = abs(off) <= tolerance_mm
        verdict = "right" if dist_ok else ("too far" if off > 0 else "too close")
        lines.append(f"Distance to the screen: {distance_mm / 10:.1f} cm, {verdict} (should be "
                     f"{nominal_mm / 10:.1f} +/- {tolerance_mm / 10:.0f} cm).")
    ok = all(found) and inside and dist_ok
    if ok:
        lines.append("Position is good.")
    scale = nominal_mm / distance_mm if distance_mm else 1.0
    return HeadBoxView((eyes[0], eyes[1]), scale, distance_mm, ok, "\n".join(lines), prompt)


class _Base:
    """What the calibration flow and the drift check share: the clock, the eyes' latest
    positions, the quit confirmation."""

    def __init__(self, area: DisplayArea, distance_mm: float, rate_hz: float,
                 size_px: tuple[int, int], ppd_px: float, timing: CalibrationTiming,
                 look_at: Callable[[tuple[float, float] | None], None] | None,
                 auto: bool, eyes: Sequence[str] = EYES) -> None:
        self.area, self.distance_mm, self.rate_hz = area, float(distance_mm), float(rate_hz)
        #: the eyes the tracker records (a monocular tracker's other eye is not judged)
        self.eyes = tuple(eyes)
        self.size_px, self.ppd_px = size_px, float(ppd_px)
        self.timing = timing
        self.look_at = look_at or (lambda target: None)
        self.auto = auto
        self.anim = _Animator(size_px, ppd_px, timing, TargetStyle())
        self.now = 0.0
        self.now_us = 0
        self.phase = "start"
        self.t_phase = 0.0
        self.outcome: str | None = None
        self._confirm_return: str | None = None
        self._confirm_behind: Any = None
        self._origins: list[tuple[float, Vec3] | None] = [None, None]
        self._window: tuple[int, int] | None = None
        self._window_samples: list[GazeSample] = []

    @property
    def finished(self) -> bool:
        return self.outcome is not None

    def _set(self, phase: str) -> None:
        self.phase, self.t_phase = phase, self.now

    def _auto_due(self) -> bool:
        t = self.timing.auto_s
        return self.auto and t is not None and self.now - self.t_phase >= t

    def feed(self, samples: Sequence[GazeSample]) -> None:
        """Gaze samples as they arrive (the session also logs them)."""
        for s in samples:
            for i, o in enumerate((s.left_origin_mm, s.right_origin_mm)):
                if o is not None:
                    self._origins[i] = (s.system_time_us / 1e6, o)
            if self._window is not None and self._window[0] <= s.system_time_us < self._window[1]:
                self._window_samples.append(s)

    def _recent_origins(self) -> list[Vec3 | None]:
        return [o[1] if o is not None and self.now - o[0] <= ORIGIN_STALE_S else None
                for o in self._origins]

    def eye_distance_mm(self) -> float | None:
        """The eyes' mean distance from the screen plane, from recent gaze origins."""
        d = [self.area.distance_mm(o) for o in self._recent_origins() if o is not None]
        return float(np.mean(d)) if d else None

    def _ask_quit(self, behind: Any) -> None:
        self._confirm_return, self._confirm_behind = self.phase, behind
        self._set("confirm_quit")

    def _step_confirm(self, keys: list[str]) -> bool:
        """The quit confirmation; True when it went back to the screen it interrupted."""
        for k in keys:
            if k == "y":
                self.outcome = "quit"
                return False
            if k in ("n", "escape"):
                assert self._confirm_return is not None
                self._set(self._confirm_return)
                return True
        return False

    def _start_window(self) -> None:
        self._window = (self.now_us, self.now_us + int(self.timing.collect_s * 1e6))
        self._window_samples = []

    def _window_done(self) -> bool:
        assert self._window is not None
        return self.now_us >= self._window[1] + int(self.timing.late_s * 1e6)

    def _take_window(self, target: tuple[float, float]) -> TargetData:
        out = TargetData(target, self._window_samples, self.timing.collect_s, self.rate_hz)
        self._window, self._window_samples = None, []
        return out


class CalibrationFlow(_Base):
    """The calibration screen's state machine (see the module docstring).

    Phases: ``position`` (head box; Space goes on), ``targets`` (calibration or validation
    points), ``compute`` (the tracker computes the calibration), ``result`` (per-point plot;
    Space accepts a validation that passed, 1-9 redoes a point, R recalibrates, V revalidates,
    S goes back to the head box, T switches between the validation's and the calibration's
    plot), ``cal_failed``, ``confirm_quit``. :attr:`outcome` ends it: ``accepted`` (then
    :attr:`result`), ``quit`` or ``failed`` (then :attr:`failure`). ``on_record(record, new)``
    is called with every calibration and validation record (dicts for the session file), and
    again when one is accepted.
    """

    def __init__(self, backend: CalibrationBackend, cal_points: Sequence[tuple[float, float]],
                 val_points: Sequence[tuple[float, float]], limits: QualityLimits,
                 area: DisplayArea, distance_mm: float, rate_hz: float,
                 size_px: tuple[int, int], ppd_px: float, window_radius_deg: float,
                 timing: CalibrationTiming | None = None,
                 look_at: Callable[[tuple[float, float] | None], None] | None = None,
                 on_record: Callable[[dict[str, Any], bool], None] | None = None,
                 auto: bool = False, seed: int = 0, now_iso: Callable[[], str] | None = None,
                 start_with_head_box: bool = True, eyes: Sequence[str] = EYES) -> None:
        super().__init__(area, distance_mm, rate_hz, size_px, ppd_px,
                         timing or CalibrationTiming(), look_at, auto, eyes)
        self.backend = backend
        #: a tracker with a set-up of its own (an ioHub tracker's ``runSetupProcedure``): it
        #: replaces the head box and the calibration targets; this says what it is
        self.own_procedure: str | None = getattr(backend, "own_procedure", None)
        if self.own_procedure:
            cal_points, start_with_head_box = [], False
        self.cal_points = [tuple(map(float, p)) for p in cal_points]
        self.val_points = [tuple(map(float, p)) for p in val_points]
        self.limits = limits
        self.window_radius_px = float(window_radius_deg) * ppd_px
        self.on_record = on_record or (lambda rec, new: None)
        self._now_iso = now_iso or (lambda: "")
        self.rng = np.random.default_rng(seed)
        self.start_with_head_box = start_with_head_box
        self.result: ValidationResult | None = None
        self.cal_outcome: CalibrationOutcome | None = None
        self.failure: str | None = None
        self.mode = "validation"  # which plot the result screen shows
        self._pool: ThreadPoolExecutor | None = None
        self._job: Future[Any] | None = None
        self._begun = False
        self._kind = ""  # "calibrate" / "validate" while in the targets phase
        self._queue: list[int] = []
        self._qpos = 0
        self._sub = ""
        self._collected: set[int] = set()
        self._cal_ok: dict[int, bool] = {}
        self._cal_stream: dict[int, list[GazeSample]] = {}
        self._val_data: dict[int, TargetData] = {}
        self._then_validate = True
        self._auto_tries = 0
        self._record: dict[str, Any] | None = None
        self._note = ""
        self._redone: list[str] = []
        self._quit_pending = False
        self._rv: tuple[Any, ResultView] | None = None
        self._n_results = 0

    # -- driving ---------------------------------------------------------------------------
    def start(self, now_us: int) -> None:
        self._tick(now_us)
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="fovexp-calibration")
        if self.start_with_head_box:
            self._set("position")
        else:
            self._calibrate(list(range(len(self.cal_points))))

    def close(self) -> None:
        """Leave the tracker's calibration mode and stop the worker (after any outcome)."""
        self.look_at(None)
        if self._pool is not None:
            if self._job is not None:
                try:
                    self._job.result()
                except Exception:  # ending anyway: the job's error no longer matters
                    pass
            if self._begun:
                self._pool.submit(self.backend.end).result()
            self._pool.shutdown()
            self._pool = None

    def _tick(self, now_us: int) -> None:
        self.now_us = int(now_us)
        self.now = now_us / 1e6

    def feed(self, samples: Sequence[GazeSample]) -> None:
        super().feed(samples)
        if self.phase == "targets" and self._kind == "calibrate" and self._sub == "collect":
            self._cal_stream.setdefault(self._queue[self._qpos], []).extend(samples)

    def step(self, keys: list[str], now_us: int) -> None:
        self._tick(now_us)
        if self.finished:
            return
        handler = {"position": self._step_position, "targets": self._step_targets,
                   "compute": self._step_compute, "result": self._step_result,
                   "cal_failed": self._step_cal_failed, "confirm_quit": self._step_confirm}
        handler[self.phase](keys)

    # -- phases ----------------------------------------------------------------------------
    def _step_position(self, keys: list[str]) -> None:
        if self._auto_due():
            keys = ["space"]
        for k in keys:
            if k in ("space", "return", "num_enter"):
                self._calibrate(list(range(len(self.cal_points))))
                return
            if k in QUIT_KEYS:
                self._ask_quit(self.view())
                return

    def _calibrate(self, indices: list[int], then_validate: bool = True) -> None:
        if self.own_procedure:  # the tracker's own set-up, on the worker thread
            self._kind, self._then_validate = "calibrate", then_validate
            self._job = self._submit(self._own_job)
            self._set("compute")
            return
        order = list(indices)
        self.rng.shuffle(order)  # as Titta: a random order, so the next point is not expected
        self._start_targets("calibrate", order)
        self._then_validate = then_validate

    def _validate(self, indices: list[int]) -> None:
        order = list(indices)
        self.rng.shuffle(order)
        self._start_targets("validate", order)

    def _start_targets(self, kind: str, order: list[int]) -> None:
        self._kind, self._queue, self._qpos = kind, order, 0
        self.anim.pos = None  # the first point appears where it is
        self._set("targets")
        self._next_point()

    def _points(self) -> list[tuple[float, float]]:
        return self.cal_points if self._kind == "calibrate" else self.val_points

    def _next_point(self) -> None:
        pos = self._points()[self._queue[self._qpos]]
        self.anim.go(pos, self.now)
        self._sub = "move"

    def _step_targets(self, keys: list[str]) -> None:
        idx = self._queue[self._qpos]
        pos = self._points()[idx]
        if any(k in QUIT_KEYS for k in keys):
            self._quit_pending = True
        if self._quit_pending and self._job is None:  # not while the tracker collects
            self._quit_pending = False
            self._sub = "move"  # after "no", this point starts again
            self.anim.t_arrive = None
            self._window = None
            self._ask_quit(self.view())
            return
        if self._sub == "move":
            if self.anim.arrived(self.now):
                self.look_at(pos)
                self._sub = "wait"
        elif self._sub == "wait":
            assert self.anim.t_arrive is not None
            pace = (self.timing.cal_pace_s if self._kind == "calibrate"
                    else self.timing.val_pace_s)
            if self.now - self.anim.t_arrive >= pace:
                self._sub = "collect"
                if self._kind == "calibrate":
                    self._cal_stream[idx] = []
                    self._job = self._submit(self._collect_job, idx, pos)
                else:
                    self._start_window()
        elif self._sub == "collect":
            if self._kind == "calibrate":
                assert self._job is not None
                if not self._job.done():
                    return
                job, self._job = self._job, None
                try:
                    self._cal_ok[idx] = bool(job.result())
                except Exception as exc:  # the SDK's own error types
                    self._calibration_failed(f"{type(exc).__name__}: {exc}")
                    return
            else:
                if not self._window_done():
                    return
                self._val_data[idx] = self._take_window(pos)
            self._qpos += 1
            if self._qpos < len(self._queue):
                self._next_point()
            else:
                self._targets_done()

    def _submit(self, fn: Callable[..., Any], *args: Any) -> Future[Any]:
        assert self._pool is not None
        return self._pool.submit(fn, *args)

    def _collect_job(self, idx: int, pos: tuple[float, float]) -> bool:
        if not self._begun:
            self.backend.begin()
            self._begun = True
        if idx in self._collected:
            self.backend.discard(*pos)  # a redone point replaces its earlier data
        ok = self.backend.collect(*pos)
        self._collected.add(idx)
        return ok

    def _own_job(self) -> CalibrationOutcome:
        if not self._begun:
            self.backend.begin()
            self._begun = True
        return self.backend.compute()

    def _targets_done(self) -> None:
        self.look_at(None)
        if self._kind == "calibrate":
            self._job = self._submit(self.backend.compute)
            self._set("compute")
            return
        self._finish_validation()

    def _step_compute(self, keys: list[str]) -> None:
        assert self._job is not None
        if not self._job.done():
            return
        job, self._job = self._job, None
        try:
            out = job.result()
        except Exception as exc:  # the SDK's own error types
            self._calibration_failed(f"{type(exc).__name__}: {exc}")
            return
        failed_points = [i + 1 for i, ok in sorted(self._cal_ok.items()) if not ok]
        if failed_points and not out.reason:
            out.reason = f"points {failed_points} collected no data"
        if out.failed:
            self._calibration_failed(out.reason or "the calibration could not be computed", out)
            return
        self.cal_outcome = out
        if self._then_validate:
            self._validate(list(range(len(self.val_points))))

    def _calibration_failed(self, reason: str, outcome: CalibrationOutcome | None = None) -> None:
        self.look_at(None)
        self.failure = f"eye-tracker calibration failed ({reason})"
        cal = outcome.to_dict() if outcome is not None else {"status": "error"}
        cal.update(failed=True, reason=reason)
        self.on_record({"time": self._now_iso(), "calibration": cal}, True)
        self._set("cal_failed")

    def _step_cal_failed(self, keys: list[str]) -> None:
        if self._auto_due():
            self._auto_tries += 1
            keys = ["r"] if self._auto_tries <= AUTO_RETRIES else []
            if not keys:
                self.outcome = "failed"
                return
        for k in keys:
            if k == "r":
                self._redone.append("all")
                self._calibrate(list(range(len(self.cal_points))))
                return
            if k == "s":
                self._set("position")
                return
            if k in QUIT_KEYS:
                self._ask_quit(self.view())
                return

    def _finish_validation(self) -> None:
        data = [self._val_data[i] for i in range(len(self.val_points)) if i in self._val_data]
        self.result = validation_result(self.area, self.distance_mm, data, self.limits,
                                        self.eyes)
        self._n_results += 1
        self.failure = None if self.result.passed else (
            f"eye-tracker validation failed: {self.result.failure}")
        self._record = {"time": self._now_iso(),
                        "calibration": self.cal_outcome.to_dict() if self.cal_outcome else None,
                        "validation": self.result.to_dict(), "redone": list(self._redone),
                        "accepted": False}
        self._redone = []
        self.on_record(self._record, True)
        self.mode = "validation"
        self._note = ""
        self._set("result")

    def _step_result(self, keys: list[str]) -> None:
        assert self.result is not None
        if self._auto_due():
            if self.result.passed:
                keys = ["space"]
            else:
                self._auto_tries += 1
                if self._auto_tries > AUTO_RETRIES:
                    self.outcome = "failed"
                    return
                keys = ["r"]
        for k in keys:
            if k in ("space", "return", "num_enter"):
                if self.result.passed:
                    assert self._record is not None
                    self._record["accepted"] = True
                    self.on_record(self._record, False)
                    self.outcome = "accepted"
                else:
                    self._note = "Cannot accept: " + (self.result.failure or "")
                return
            if k == "r":
                self._redone.append("all")
                self._calibrate(list(range(len(self.cal_points))))
                return
            if k == "v":
                self._redone.append("validation")
                self._validate(list(range(len(self.val_points))))
                return
            if k == "s":
                self._set("position")
                return
            if k == "t":
                self.mode = "calibration" if self.mode == "validation" else "validation"
                return
            if k in QUIT_KEYS:
                self._ask_quit(self.view())
                return
            if k.isdigit():
                n = int(k)
                pts = self.cal_points if self.mode == "calibration" else self.val_points
                if 1 <= n <= len(pts):
                    if self.mode == "calibration":
                        # a new calibration: the old validation no longer describes it
                        self._redone.append(f"calibration point {n}")
                        self._calibrate([n - 1])
                    else:
                        self._redone.append(f"validation point {n}")
                        self._start_targets("validate", [n - 1])
                    return

    def _step_confirm(self, keys: list[str]) -> bool:
        back = super()._step_confirm(keys)
        if back and self.phase == "targets":
            self._window = None
            self.anim.t_move = self.now  # the interrupted point starts again
        return back

    # -- what to draw ----------------------------------------------------------------------
    def view(self) -> View:
        if self.phase == "confirm_quit":
            return _confirm(self._confirm_behind)
        if self.phase == "position":
            guide = self.backend.user_position()
            if guide == (None, None):  # no position guide: the gaze origins say where the eyes are
                guide = guide_from_origins(self._recent_origins(), self.area, self.distance_mm)
            return head_box_view(guide, self.eye_distance_mm(), self.distance_mm,
                                 "Space: start the calibration    Q: quit")
        if self.phase == "targets":
            return self.anim.view(self.now)
        if self.phase == "compute":
            if self.own_procedure:
                return TextView(f"Calibrating: {self.own_procedure} ...",
                                "fovexp's validation follows")
            return TextView("Computing the calibration ...")
        if self.phase == "cal_failed":
            return TextView(f"{self.failure}.",
                            "R: calibrate again    S: head position    Q: quit")
        if self.phase == "result":
            key = (self._n_results, self.mode, self._note)
            if self._rv is None or self._rv[0] != key:  # one view while nothing changes: the
                self._rv = (key, self._result_view())  # window builds its plot once per view
            return self._rv[1]
        return TextView("")

    def _result_view(self) -> ResultView:
        assert self.result is not None
        res = self.result
        points = []
        if self.mode == "validation":
            for i, p in enumerate(self.val_points):
                left = res.left.targets[i] if i < len(res.left.targets) else None
                right = res.right.targets[i] if i < len(res.right.targets) else None
                data = self._val_data.get(i)
                samples, mean = _plot_samples(data.samples if data else [])
                lab = "L {} R {}".format(*(f"{q.accuracy_deg:.2f}" if q else "-"
                                           for q in (left, right)))
                ok = True
                if p == CENTRE:
                    ok = res.central_accuracy_deg <= self.limits.max_central_accuracy_deg
                points.append(ResultPoint(i + 1, p, samples, mean, lab + " deg", ok))
        else:
            outcome = self.cal_outcome
            for i, p in enumerate(self.cal_points):
                ps = outcome.points.get(p) if outcome else None
                if ps is not None and (ps.left or ps.right):
                    samples = {"left": [(x, y) for x, y, used in ps.left if used],
                               "right": [(x, y) for x, y, used in ps.right if used]}
                    mean = {e: (tuple(np.mean(v, axis=0)) if v else None)
                            for e, v in samples.items()}
                else:
                    samples, mean = _plot_samples(self._cal_stream.get(i, []))
                ok = self._cal_ok.get(i, False)
                points.append(ResultPoint(i + 1, p, samples, mean, "" if ok else "no data", ok))
        verdict = "Validation passed." if res.passed else f"Validation failed: {res.failure}."
        lim = self.limits
        text = (f"{verdict}\n{res.summary()}\nLimits: centre {lim.max_central_accuracy_deg:g} "
                f"deg, mean {lim.max_accuracy_deg:g} deg, data loss "
                f"{100 * lim.max_data_loss:g}%; angles from the {res.origins}.")
        if self._note:
            text += "\n" + self._note
        accept = "Space: accept    " if res.passed else ""
        other = "calibration" if self.mode == "validation" else "validation"
        prompt = (f"{accept}1-9: redo that point    R: recalibrate all    V: validate again    "
                  f"S: head position    T: show the {other}    Q: quit")
        title = ("Validation: gaze per target (green left eye, blue right eye; circle: the "
                 "fixation window)" if self.mode == "validation" else
                 "Calibration: the tracker's samples per point")
        return ResultView(title, self.mode, points, text, prompt, res.passed,
                          self.window_radius_px, self.anim.back_min)


def _plot_samples(samples: Sequence[GazeSample]) -> tuple[dict[str, list[tuple[float, float]]],
                                                          dict[str, tuple[float, float] | None]]:
    out: dict[str, list[tuple[float, float]]] = {}
    mean: dict[str, tuple[float, float] | None] = {}
    for eye in ("left", "right"):
        pts = [((s.left_x, s.left_y) if eye == "left" else (s.right_x, s.right_y))
               for s in samples if (s.left_valid if eye == "left" else s.right_valid)]
        mean[eye] = (float(np.mean([p[0] for p in pts])),
                     float(np.mean([p[1] for p in pts]))) if pts else None
        step = max(1, len(pts) // PLOT_SAMPLES)
        out[eye] = pts[::step]
    return out, mean


class DriftCheck(_Base):
    """A drift check between trials: the central target (animated as in the calibration),
    the offset of the mean gaze over a short window, per eye; when the worse eye's exceeds
    ``limit_deg`` (or too much was lost) the operator chooses: Space continue anyway, C
    recalibrate, D check again, Q quit (with confirmation). :attr:`outcome`: ``ok``,
    ``continued``, ``recalibrate`` or ``quit``; :attr:`result` the last check's figures; a dry
    run recalibrates when a check fails."""

    def __init__(self, area: DisplayArea, distance_mm: float, rate_hz: float,
                 size_px: tuple[int, int], ppd_px: float, limit_deg: float,
                 max_data_loss: float, timing: CalibrationTiming | None = None,
                 look_at: Callable[[tuple[float, float] | None], None] | None = None,
                 auto: bool = False, eyes: Sequence[str] = EYES) -> None:
        super().__init__(area, distance_mm, rate_hz, size_px, ppd_px,
                         timing or CalibrationTiming(), look_at, auto, eyes)
        self.limit_deg, self.max_data_loss = float(limit_deg), float(max_data_loss)
        self.result: DriftResult | None = None
        self.results: list[DriftResult] = []
        self._sub = ""

    def start(self, now_us: int) -> None:
        self.now_us, self.now = int(now_us), now_us / 1e6
        self._target()

    def close(self) -> None:
        self.look_at(None)

    def _target(self) -> None:
        self.anim.pos = None
        self.anim.go(CENTRE, self.now)
        self._sub = "move"
        self._set("target")

    def step(self, keys: list[str], now_us: int) -> None:
        self.now_us, self.now = int(now_us), now_us / 1e6
        if self.finished:
            return
        if self.phase == "confirm_quit":
            if self._step_confirm(keys) and self.phase == "target":
                self._target()
            return
        if self.phase == "target":
            if any(k in QUIT_KEYS for k in keys):
                self._ask_quit(self.view())
                return
            if self._sub == "move":
                if self.anim.arrived(self.now):
                    self.look_at(CENTRE)
                    self._sub = "wait"
            elif self._sub == "wait":
                assert self.anim.t_arrive is not None
                if self.now - self.anim.t_arrive >= self.timing.val_pace_s:
                    self._sub = "collect"
                    self._start_window()
            elif self._window_done():
                self.look_at(None)
                self.result = drift_result(self.area, self.distance_mm,
                                           self._take_window(CENTRE), self.limit_deg,
                                           self.max_data_loss, self.eyes)
                self.results.append(self.result)
                if self.result.passed:
                    self.outcome = "ok"
                else:
                    self._set("decide")
            return
        if self.phase == "decide":
            if self._auto_due():
                keys = ["c"]
            for k in keys:
                if k in ("space", "return", "num_enter"):
                    self.outcome = "continued"
                elif k in ("c", "r"):
                    self.outcome = "recalibrate"
                elif k == "d":
                    self._target()
                elif k in QUIT_KEYS:
                    self._ask_quit(self.view())
                if self.outcome is not None or self.phase != "decide":
                    return

    def view(self) -> View:
        if self.phase == "confirm_quit":
            return _confirm(self._confirm_behind)
        if self.phase == "target":
            return self.anim.view(self.now)
        r = self.result
        assert r is not None
        return TextView(
            f"Drift check: {r.failure}.\nLeft eye {r.left.accuracy_deg:.2f} deg, right eye "
            f"{r.right.accuracy_deg:.2f} deg off the centre (limit {self.limit_deg:g} deg); "
            f"data loss {100 * r.data_loss:.0f}%.",
            "Space: continue anyway    C: recalibrate    D: check again    Q: quit")
