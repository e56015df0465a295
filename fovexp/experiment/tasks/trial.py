"""One adjustment trial, without a window: value stepping, input events, frame timing, blanking
episodes, and the trial's result row.

Paper section 5.1 ("Task"): the participant changes one parameter with the mouse wheel, the test
half updates in real time, Enter confirms. Here each wheel notch moves the value by the
protocol's coarse step, or by the fine step while the modifier (Shift) is held; values are clamped
to the protocol's range.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field


@dataclass(frozen=True)
class Wheel:
    """``notches`` wheel notches (positive: value up); ``fine`` while the modifier is held."""

    notches: int
    fine: bool = False


#: What :func:`wheel_notches` carries from one call to the next: the fraction of a notch turned
#: so far, and whether it was turned with the modifier (fine) held.
WheelCarry = tuple[float, bool]


def wheel_notches(scrolls: list[tuple[float, bool]],
                  carry: WheelCarry = (0.0, False)) -> tuple[list[Wheel], WheelCarry]:
    """Whole wheel notches from scroll deltas ``(dy, fine)`` in order, and what is left over.

    High-resolution wheels and touchpads report fractions of a notch per event; rounding each
    event would lose them all, so they are summed and a notch is emitted each time the sum
    passes a whole one. The fraction is kept per modifier state (a fine half-turn and a coarse
    half-turn are not one coarse notch). Consecutive notches with the same modifier state are
    merged.
    """
    frac, frac_fine = carry
    out: list[Wheel] = []
    for dy, fine in scrolls:
        if fine != frac_fine:
            frac, frac_fine = 0.0, fine
        frac += dy
        # towards zero: a notch only once a whole one has been turned (ten 0.1 sum to 0.999...)
        n = math.trunc(round(frac, 9))
        frac -= n
        if not n:
            continue
        if out and out[-1].fine == fine:
            out[-1] = Wheel(out[-1].notches + n, fine)
        else:
            out.append(Wheel(n, fine))
    return [w for w in out if w.notches], (frac, frac_fine)


@dataclass(frozen=True)
class Key:
    """A key press: ``return`` (confirm), ``escape`` (pause), ``space``, ``q`` ...

    ``t_s`` is when the key went down, on ``time.monotonic``'s clock (the flips' clock), where
    the keyboard stamps the press itself (PsychoPy's ``Keyboard`` with its 'ptb' or 'iohub'
    backend); None where the key is known only from the poll that saw it (then the poll's time
    stands for it). Not part of equality: ``Key("return")`` names the key.
    """

    name: str
    t_s: float | None = field(default=None, compare=False)


InputEvent = Wheel | Key


class ValueAdjuster:
    """The adjusted value, moved in coarse or fine steps and clamped to ``[lo, hi]``."""

    def __init__(self, lo: float, hi: float, step: float, fine_step: float, start: float) -> None:
        if not lo < hi:
            raise ValueError("lo must be < hi")
        self.lo, self.hi, self.step, self.fine_step = lo, hi, step, fine_step
        self.value = self.clamp(start)
        self.notches = 0

    def clamp(self, v: float) -> float:
        return min(max(float(v), self.lo), self.hi)

    def apply(self, ev: Wheel) -> bool:
        """Move by ``ev``; returns True when the value changed. Every notch counts as a wheel
        event, also one that hits the end of the range."""
        self.notches += abs(ev.notches)
        step = self.fine_step if ev.fine else self.step
        # Rounded so repeated steps do not accumulate binary floating-point drift.
        new = self.clamp(round(self.value + ev.notches * step, 10))
        changed = new != self.value
        self.value = new
        return changed


#: a frame whose interval exceeds this many refresh periods counts as dropped
DROPPED_FRAME_PERIODS = 1.5


class FrameTimer:
    """Frame intervals of a trial; a frame whose interval exceeds 1.5 refresh periods counts as
    dropped (docs/LOGS.md, ``dropped_frames``)."""

    def __init__(self, refresh_hz: float) -> None:
        self.period_s = 1.0 / refresh_hz
        self.last: float | None = None
        self.intervals: list[float] = []
        self.dropped = 0

    def flip(self, t: float) -> tuple[float | None, bool]:
        if self.last is None:
            self.last = t
            return None, False
        dt = t - self.last
        self.last = t
        self.intervals.append(dt)
        dropped = dt > DROPPED_FRAME_PERIODS * self.period_s
        self.dropped += int(dropped)
        return dt, dropped


@dataclass
class Episode:
    start_s: float
    end_s: float | None
    frames: int
    reason: str


@dataclass
class BlankingLog:
    """Blanking episodes (runs of consecutive black frames) of one trial, and the time blanked.

    A frame is on screen from its flip to the next flip (the last one until the trial ends), so
    a black frame followed by a dropped one counts for as long as it really stayed black; the
    blanked fraction and the episodes' durations are measured on that one time base.
    """

    episodes: list[Episode] = field(default_factory=list)
    frames: int = 0
    blanked: int = 0
    shown_s: float = 0.0  # time on screen of the frames so far, up to the last flip
    blanked_s: float = 0.0
    _last: tuple[float, bool] | None = None  # (flip time, black) of the last frame
    _closed: bool = False

    def _account(self, t_s: float) -> None:
        if self._last is not None:
            dt = max(0.0, t_s - self._last[0])
            self.shown_s += dt
            if self._last[1]:
                self.blanked_s += dt

    def frame(self, t_s: float, blank: bool, reason: str) -> None:
        self._account(t_s)
        self._last = (t_s, blank)
        self.frames += 1
        cur = self.episodes[-1] if self.episodes and self.episodes[-1].end_s is None else None
        if blank:
            self.blanked += 1
            if cur is None:
                self.episodes.append(Episode(t_s, None, 1, reason))
            else:
                cur.frames += 1
        elif cur is not None:
            cur.end_s = t_s

    def close(self, t_s: float) -> None:
        """The trial ended at ``t_s``: the last frame's time counts up to here."""
        if self._closed:
            return
        self._closed = True
        self._account(t_s)
        self._last = None
        if self.episodes and self.episodes[-1].end_s is None:
            self.episodes[-1].end_s = t_s

    @property
    def fraction(self) -> float:
        """Fraction of the trial's time the screen was black (by frame count while no time has
        passed, e.g. a trial of one frame)."""
        if self.shown_s > 0:
            return self.blanked_s / self.shown_s
        return self.blanked / self.frames if self.frames else 0.0


#: the keys that confirm the value on screen
CONFIRM_KEYS = ("return", "enter", "num_enter")


class TrialState:
    """The state of one trial between its first frame and Enter.

    ``handle`` consumes input events and returns ``"changed"``, ``"confirm"``, ``"pause"`` or
    None; ``flip`` records a shown frame (its time, whether it was black and why). ``value`` is
    the requested value (the wheel's), ``shown_value`` that of the render the next frames show,
    which lags while a render is computed. The answer, :attr:`final_value`, is the value the
    participant saw when Enter went down: that of the last stimulus frame flipped at or before
    the press (:meth:`confirm`), not of a render that reached the screen between the press and
    the poll that saw it.
    """

    def __init__(self, adjuster: ValueAdjuster, refresh_hz: float) -> None:
        self.adjuster = adjuster
        self.start_value = adjuster.value
        self.timer = FrameTimer(refresh_hz)
        self.blanking = BlankingLog()
        self.t_start: float | None = None
        self.t_end: float | None = None
        self.t_confirm: float | None = None
        self.n_frames = 0
        self.shown_value: float = adjuster.value
        #: every frame so far: (flip time, black, value of its test half)
        self.frames: list[tuple[float, bool, float]] = []

    @property
    def value(self) -> float:
        return self.adjuster.value

    def handle(self, events: list[InputEvent], now_s: float | None = None) -> str | None:
        """Input events in order; ``now_s``: the poll's time (``time.monotonic``), the press
        time of a key the keyboard did not stamp. Enter confirms (:meth:`confirm`, at the key's
        own time) once the stimulus was on screen: a press before the first stimulus frame's
        flip does not count."""
        outcome = None
        for ev in events:
            if isinstance(ev, Wheel):
                if self.t_start is None:
                    continue  # before the stimulus is first shown the wheel does nothing
                if self.adjuster.apply(ev):
                    outcome = "changed"
            elif ev.name in CONFIRM_KEYS:
                t = ev.t_s if ev.t_s is not None else now_s
                if self.t_start is not None and (t is None or t >= self.t_start):
                    if t is not None:
                        self.confirm(t)
                    return "confirm"
            elif ev.name == "escape":
                return "pause"
        return outcome

    def flip(self, t: float, blank: bool, reason: str) -> tuple[float | None, bool]:
        if self.t_start is None:
            self.t_start = t
        self.n_frames += 1
        self.frames.append((t, blank, self.shown_value))
        self.blanking.frame(t - self.t_start, blank, reason)
        return self.timer.flip(t)

    def show(self, value: float) -> None:
        """A render computed for ``value`` is now the test half of the next frames."""
        self.shown_value = float(value)

    def confirm(self, t: float) -> None:
        """Enter pressed at ``t`` (``time.monotonic``; the response time ends here)."""
        if self.t_confirm is None:
            self.t_confirm = t

    def value_at(self, t: float) -> float:
        """The value the participant saw at ``t``: that of the last stimulus (not black) frame
        flipped at or before ``t``; the start value when none was (the trial's first frames
        were black)."""
        for flip_s, blank, value in reversed(self.frames):
            if flip_s <= t and not blank:
                return value
        return self.start_value

    @property
    def final_value(self) -> float:
        """The answer: the value on screen when Enter went down (:meth:`value_at`), or, without
        a press time, when the trial ended; before either, the value the next frames show."""
        t = self.t_confirm if self.t_confirm is not None else self.t_end
        return self.shown_value if t is None else self.value_at(t)

    def finish(self, t: float) -> None:
        if self.t_end is not None:
            return
        self.t_end = t
        if self.t_start is not None:
            self.blanking.close(t - self.t_start)

    def extra_columns(self) -> dict[str, object]:
        """Columns a task writes after the documented ones (``trials.csv``): none here; a
        forced-choice trial's answer (:class:`.forced_choice.ChoiceState`)."""
        return {}

    @property
    def response_time_s(self) -> float:
        end = self.t_confirm if self.t_confirm is not None else self.t_end
        if self.t_start is None or end is None:
            return math.nan
        return end - self.t_start
