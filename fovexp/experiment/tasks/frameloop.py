"""The frame loop of one attempt at a trial (paper section 5.1, "Task"), without PsychoPy.

The session runs every trial through :class:`TrialLoop`, and ``benchmarks/display_loop.py``
drives the same class at 4K to measure it; a rig check can drive it too (it only adds
measuring: :class:`FrameTiming`). Per frame, on the display thread, in this order:

1. tracker status events; a lost tracker ends the attempt;
2. input (wheel, keys, and a simulated participant's) through :class:`TrialState`: a wheel step
   requests a render; Enter ends the attempt at once, and the answer is the value of the
   stimulus on screen when the key went down (its own timestamp, where the keyboard gives one:
   :class:`~fovexp.experiment.tasks.trial.Key`), so a render that reached the screen between the
   press and this poll is not the answer; a render still pending is dropped; Escape pauses;
3. a finished render becomes the test half (an 8-bit upload, or a texture switch: the render
   thread prepared either);
4. the frame drawn as the newest gaze sample predicts it (late latching only; below);
5. the blanking decision: ``now_us`` is read on the gaze source's clock at the poll, the gaze
   samples since the last poll are taken, and the newest sample received by ``now_us``
   decides by the one rule (:class:`fovexp.results.blanking.BlankingRule`): black when it is
   older than the gaze timeout at that moment, invalid, or beyond 1.25 deg (the rule so holds
   against every sample received before the decision, with no gap between poll and clock);
6. draw (if the decision differs from the prediction) and flip; the flip time is put on the
   tracker's clock (``now_us`` read right after);
7. the frame's log row: the sample that decided it, the decision and the flip, on one clock.

Late latching (:class:`LateLatch`, what head-mounted displays call reading the pose as late as
the frame allows): without it the gaze is read right after the previous flip, so the deciding
sample is about a refresh period old at the vertical blank. With it, the loop draws the frame
first (step 4: the stimulus, or the cross alone when the newest sample already says black;
``Screen.prepare`` returns when the drawing is done), then sleeps until a margin before the
vertical blank the frame can make, and only then reads the gaze and decides (step 5). A frame
the decision blanks costs a clear and the cross; one it unblanks is drawn after the decision
(rare: the first frame after a blanking episode). The margin is the longest recent draw time
(decision to ready, :class:`~fovexp.experiment.interfaces.FlipTimes`) times a safety factor,
so it adapts to the machine and the load.

On leaving (Enter, pause, lost tracker) the loop flips a black frame with the cross at once:
from the first flip after the poll that saw Enter nothing but the cross is on screen until the
next trial's stimulus. Nothing here writes a file or waits for the render thread: log rows and
events go to callbacks that only buffer them (the session's logs are written by their own
threads).
"""

from __future__ import annotations

import gc
import math
import os
import signal
import statistics
import sys
import time
from collections import deque
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, NamedTuple

from ..interfaces import GazeSource, Renderer, Screen
from ..trackers.gaze import BlankDecision, BlankingMonitor, GazeSample
from .trial import InputEvent, TrialState

if TYPE_CHECKING:
    from fovexp import EnhanceParams

#: While a session runs, a thread that wants the GIL waits at most about this long for another
#: to give it up (Python's default is 5 ms, most of a 120 Hz frame; sys.setswitchinterval).
SWITCH_INTERVAL_S = 0.0005

#: The late latch's margin before the vertical blank: this factor times the longest draw time
#: (decision to ready) of the last :data:`LATCH_WINDOW` frames. 1.5 absorbs a draw half again
#: as slow as any of the last second's; a miss costs the frame one refresh period (it shows a
#: period later, as any late frame does), a larger factor costs every frame latency.
LATCH_SAFETY = 1.5
#: frames whose draw times set the margin (one second at 120 Hz)
LATCH_WINDOW = 120
#: the margin is never below this (s): the sleep's own wake-up jitter on an idle machine
LATCH_MIN_MARGIN_S = 0.001
#: nor above this (s): a stall (a swap to disk, a debugger) must not stop latching for good
LATCH_MAX_MARGIN_S = 0.5


def _round_robin(on: bool) -> bool:
    """The calling thread under the real-time round-robin policy at its lowest priority (on),
    or back to the normal policy: what PsychoPy's ``core.rush`` does on Linux. Returns whether
    the system allowed it (it needs CAP_SYS_NICE or an rtprio limit; elsewhere: False)."""
    try:
        policy = os.SCHED_RR if on else os.SCHED_OTHER
        os.sched_setscheduler(0, policy, os.sched_param(os.sched_get_priority_min(policy)))
        return True
    except (AttributeError, OSError):
        return False


@contextmanager
def display_thread_first() -> Iterator[dict[str, Any]]:
    """For the block, the calling (display) thread goes first: the interpreter's switch
    interval at :data:`SWITCH_INTERVAL_S`, so it waits at most about that long for the GIL when
    the render, flusher or writer thread holds it between their GIL-free parts; and, where the
    system allows it, the real-time round-robin policy, so that it is not kept waiting for a
    core by threads of normal priority (it sleeps or waits for the vertical blank every frame,
    so it takes no core from them for long). Yields what was set (the session records it)."""
    old = sys.getswitchinterval()
    sys.setswitchinterval(min(old, SWITCH_INTERVAL_S))
    realtime = _round_robin(True)
    try:
        yield {"switch_interval_s": sys.getswitchinterval(), "realtime_round_robin": realtime}
    finally:
        sys.setswitchinterval(old)
        if realtime:
            _round_robin(False)


class Interrupted(Exception):
    """SIGINT/SIGTERM during a run (:func:`interruptible`): stop at once; progress is saved."""


@contextmanager
def interruptible() -> Iterator[None]:
    """For the block, SIGINT and SIGTERM raise :class:`Interrupted` in the main thread (the
    session then closes its logs and records the state); outside the main thread (tests)
    signals are left alone."""
    def handler(signum: int, frame: Any) -> None:
        raise Interrupted(f"signal {signum}")

    old = {}
    for sig in (signal.SIGINT, signal.SIGTERM):
        try:
            old[sig] = signal.signal(sig, handler)
        except ValueError:  # not the main thread
            pass
    try:
        yield
    finally:
        for sig, h in old.items():
            signal.signal(sig, h)


class LatchPlan(NamedTuple):
    """When to decide a frame: ``latch_s``, for the vertical blank at ``target_s`` (None: no
    blank to aim at yet, decide at once); ``time.monotonic`` seconds."""

    target_s: float | None
    latch_s: float


class LateLatch:
    """When the frame loop reads the gaze and decides a frame: a margin before the vertical
    blank the frame can make (module docstring, "Late latching").

    ``period_s`` is the refresh period; the blanks lie on the grid of the last flip (a flip
    returns at a blank). The frame aims at the first blank at least the median recent draw
    time away (so that it shows no later than it would have without the latch: a frame that
    then misses shows a period later, as it would have), and latches at the margin before
    it, or at once when that is past. Every frame's draw time (from the latch to
    ``ready_s``) updates the margin: ``safety`` times the longest of the last ``window``,
    within [``min_margin_s``, :data:`LATCH_MAX_MARGIN_S`]; before the first,
    ``initial_margin_s`` (default: one period, about where the gaze was read without
    latching). Where drawing takes a small part of a period (a rig) the two coincide: the
    frame aims at the next blank and latches the margin before it. One latch serves a whole
    session: the margin carries over from trial to trial.
    """

    def __init__(self, period_s: float, *, safety: float = LATCH_SAFETY,
                 window: int = LATCH_WINDOW, min_margin_s: float = LATCH_MIN_MARGIN_S,
                 initial_margin_s: float | None = None) -> None:
        if not (period_s > 0 and safety >= 1 and window >= 1 and min_margin_s >= 0):
            raise ValueError("LateLatch: period > 0, safety >= 1, window >= 1, min margin >= 0")
        self.period_s = float(period_s)
        self.safety = float(safety)
        self.min_margin_s = float(min_margin_s)
        self.draw_s: deque[float] = deque(maxlen=int(window))
        self.margin_s = self.period_s if initial_margin_s is None else float(initial_margin_s)
        #: frames decided, and those that appeared later than their target blank
        self.frames = 0
        self.misses = 0

    def plan(self, now_s: float, last_blank_s: float | None) -> LatchPlan:
        """Where the frame decided from ``now_s`` on aims, after the blank at
        ``last_blank_s`` (None: none known, decide at once)."""
        if last_blank_s is None:
            return LatchPlan(None, now_s)
        need = statistics.median(self.draw_s) if self.draw_s else self.margin_s
        n = max(1, math.ceil((now_s + need - last_blank_s) / self.period_s))
        target = last_blank_s + n * self.period_s
        return LatchPlan(target, max(now_s, target - self.margin_s))

    def observe(self, plan: LatchPlan, ready_s: float, flip_s: float,
                adapt: bool = True) -> bool:
        """A frame latched by ``plan`` was ready at ``ready_s`` and appeared at ``flip_s``;
        returns whether it missed its target blank. ``adapt`` False: its draw time is not the
        one the margin is for (the frame was drawn after its decision)."""
        self.frames += 1
        missed = plan.target_s is not None and flip_s > plan.target_s + 0.5 * self.period_s
        self.misses += int(missed)
        if adapt:
            self.draw_s.append(max(0.0, ready_s - plan.latch_s))
            self.margin_s = min(LATCH_MAX_MARGIN_S,
                                max(self.min_margin_s, self.safety * max(self.draw_s)))
        return missed

    def info(self) -> dict[str, Any]:
        """Settings and state, for the session file."""
        return {"safety": self.safety, "window_frames": self.draw_s.maxlen,
                "min_margin_ms": 1e3 * self.min_margin_s, "margin_ms": 1e3 * self.margin_s,
                "frames": self.frames, "missed": self.misses}


@dataclass(frozen=True)
class FrameTiming:
    """The display thread's own time on one frame (``benchmarks/display_loop.py``; times in s,
    wall clock unless said)."""

    #: from the frame's first step to the flip call, without the drawing (``prepare``) and the
    #: latch's sleep: the loop's own work
    work_s: float
    #: the display thread's CPU time over the same span as ``work_s`` plus the drawing (less
    #: than their sum when it waited: for the GIL, or for a core on a busy machine)
    work_cpu_s: float
    #: from the start of the deciding gaze poll to the flip call
    gaze_to_flip_call_s: float
    #: the deciding gaze poll alone (a simulated source generates its samples in it)
    gaze_poll_s: float
    #: samples that poll returned
    samples: int
    #: the test half's upload (or texture switch) in this frame; None without one
    upload_s: float | None
    #: the flip call itself (swap; with vsync or pacing, the wait for the vertical blank)
    flip_s: float
    #: the drawing (every ``prepare`` of the frame)
    prepare_s: float = 0.0
    #: the late latch's sleep before the decision (0 without late latching)
    latch_wait_s: float = 0.0
    #: from the decision to the frame being ready (``FlipTimes.ready_s``)
    decide_to_ready_s: float = 0.0
    #: the frame drawn before the decision was the one shown (late latching; False without)
    predicted: bool = False
    #: late latching: the frame appeared later than the blank it aimed at
    missed: bool = False


@dataclass
class TrialIO:
    """Where an attempt's output goes: a frame-log row, gaze samples (with the trial and
    attempt they belong to; trial None before the stimulus), a tracker status event. Each only
    buffers (the frame loop never waits on a disk)."""

    frame: Callable[[tuple[Any, ...]], None]
    gaze: Callable[[int | None, int, list[GazeSample]], None]
    event: Callable[[str, dict[str, Any]], None]


class TrialLoop:
    """One attempt at a trial (module docstring).

    ``params_for(value)`` gives the enhancer's parameters for the adjusted value;
    ``parameter`` names it (to read it back from a render's parameters); ``participant``
    (dry runs, benchmarks) gives input events from ``(t_since_first_frame_s, value_on_screen,
    judgeable)`` (judgeable: the stimulus is on screen and shows the value last asked for).
    ``latch``: late latching with this :class:`LateLatch` (shared by a session's trials);
    None: the gaze is read right after the previous flip. ``timings``, when a list, gets one
    :class:`FrameTiming` per frame.

    Each frame's log row (:data:`fovexp.results.format.FRAME_COLUMNS`): trial, attempt, frame,
    flip time (s, ``time.monotonic``), interval, dropped, blanked, value, the deciding sample's
    ``system_time_us`` and eccentricity, the flip and the decision on the gaze clock (us).
    """

    def __init__(self, *, screen: Screen, gaze: GazeSource, renderer: Renderer,
                 monitor: BlankingMonitor,
                 state: TrialState, params_for: Callable[[float], EnhanceParams], parameter: str,
                 trial_index: int, attempt: int, io: TrialIO,
                 participant: Callable[[float, float, bool], list[InputEvent]] | None = None,
                 latch: LateLatch | None = None,
                 timings: list[FrameTiming] | None = None) -> None:
        self.screen, self.gaze, self.renderer = screen, gaze, renderer
        self.monitor, self.st = monitor, state
        self.params_for, self.parameter = params_for, parameter
        self.trial_index, self.attempt = trial_index, attempt
        self.io, self.participant, self.timings = io, participant, timings
        self.latch = latch
        self._visible = False  # the stimulus is on screen now (the last frame's decision)
        #: when the attempt began (:meth:`show_first`; else its first frame), tracker clock
        self.start_us: int | None = None
        self._last_blank_s: float | None = None  # the last flip: a vertical blank

    # -- before the first frame ------------------------------------------------------------------
    def show_first(self, poll_s: float = 0.05) -> None:
        """Request the start value's render and show the cross alone (black frames) until it is
        done; the samples meanwhile go to the gaze log without a trial and tell the blanking
        monitor where the gaze is."""
        self.start_us = self.gaze.now_us()  # the attempt begins: the frame log's first column
        serial = self.renderer.request(self.params_for(self.st.value))
        while True:
            try:
                got = self.renderer.wait(serial, timeout=poll_s)
                break
            except TimeoutError:
                self._last_blank_s = self.screen.draw(blank=True).flip_s
                self._between_frames()
        self.screen.set_test(got)
        self.st.show(float(getattr(got.params, self.parameter)))
        self._between_frames()

    def _between_frames(self) -> None:
        now_us = self.gaze.now_us()
        samples = self.gaze.poll()
        self.monitor.update(samples, now_us)
        self.io.gaze(None, self.attempt, samples)

    # -- the frames ----------------------------------------------------------------------------
    def run(self, max_s: float | None = None) -> str:
        """Frames until Enter (``done``), Escape (``pause``), a lost tracker
        (``disconnected``), or ``max_s`` seconds (``timeout``: benchmarks)."""
        st = self.st
        t_end = None if max_s is None else time.monotonic() + max_s
        outcome = "timeout"
        # No cyclic garbage collection during the frames (a full one can take tens of ms);
        # it runs again from the black frame on, between trials.
        collecting = gc.isenabled()
        gc.disable()
        try:
            while t_end is None or time.monotonic() < t_end:
                stop = self._frame()
                if stop is not None:
                    outcome = stop
                    break
        finally:
            # The first flip after leaving is black with the cross; the last stimulus frame
            # counted until then.
            try:
                t = self.screen.draw(blank=True).flip_s
                # the samples up to this closing frame belong to the attempt (the gaze log)
                self.io.gaze(self.trial_index, self.attempt, self.gaze.poll())
            except Exception:  # leaving on an error: that error is the one to report
                t = time.monotonic()
            st.finish(t)
            if collecting:
                gc.enable()
        return outcome

    def _decide(self) -> tuple[BlankDecision, int, float, float]:
        """Step 5: the decision at ``now_us``, read at the poll (just before it), on the samples
        received by then (:meth:`BlankingMonitor.update`; a sample the poll brings that arrived
        after it decides the next frame); returns it with the samples' count, when the poll
        started and how long it took."""
        gaze = self.gaze
        t_gaze = time.perf_counter()
        now_us = gaze.now_us()
        samples = gaze.poll()
        t_polled = time.perf_counter()
        decision = self.monitor.update(samples, now_us)
        self.io.gaze(self.trial_index, self.attempt, samples)
        return decision, len(samples), t_gaze, t_polled - t_gaze

    def _frame(self) -> str | None:
        st, screen, gaze = self.st, self.screen, self.gaze
        if self.start_us is None:  # run without show_first (benchmarks)
            self.start_us = gaze.now_us()
        t0 = time.perf_counter()
        c0 = time.thread_time()
        # 1. tracker status
        for ev in gaze.poll_events():
            self.io.event(ev.kind, {"trial_index": self.trial_index, **ev.detail})
        if not gaze.connected:
            return "disconnected"  # the trial restarts once the tracker is back
        # 2. input
        events = screen.poll_input()
        polled_s = time.monotonic()
        if self.participant is not None and st.t_start is not None:
            # what is on screen; a participant cannot judge it while it is black or still
            # shows an older value than the wheel asked for
            events = events + self.participant(polled_s - st.t_start, st.shown_value,
                                               self._visible and st.shown_value == st.value)
        outcome = st.handle(events, polled_s)
        if outcome == "pause":
            return "pause"
        if outcome == "confirm":
            self.renderer.drop_pending()  # the answer is the value on screen at the press
            return "done"
        if outcome == "changed":
            self.renderer.request(self.params_for(st.value))
        # 3. a finished render
        upload_s = None
        got = self.renderer.poll()
        if got is not None:
            t_up = time.perf_counter()
            screen.set_test(got)
            upload_s = time.perf_counter() - t_up
            st.show(float(getattr(got.params, self.parameter)))
        prepare_s = wait_s = 0.0
        predicted = False
        plan: LatchPlan | None = None
        if self.latch is None:
            # 5. the decision, right after the previous flip
            decision, n, t_gaze, poll_s = self._decide()
            decided_s = time.monotonic()
            t_prep = time.perf_counter()
            screen.prepare(decision.blank)
            prepare_s = time.perf_counter() - t_prep
        else:
            # 4. draw the frame the newest sample predicts, then wait for the latch
            guess, n0, _, _ = self._decide()
            t_prep = time.perf_counter()
            screen.prepare(guess.blank)
            prepare_s = time.perf_counter() - t_prep
            plan = self.latch.plan(time.monotonic(), self._last_blank_s)
            wait_s = plan.latch_s - time.monotonic()
            if wait_s > 0:
                time.sleep(wait_s)
            wait_s = max(0.0, wait_s)
            # 5. the decision, late
            decision, n, t_gaze, poll_s = self._decide()
            decided_s = time.monotonic()
            n += n0
            predicted = decision.blank == guess.blank
            if not predicted:
                t_prep = time.perf_counter()
                screen.prepare(decision.blank)
                prepare_s += time.perf_counter() - t_prep
        # 6. flip
        t_call = time.perf_counter()
        c_call = time.thread_time()
        flip = screen.flip()
        flip_us = gaze.now_us() - round((time.monotonic() - flip.flip_s) * 1e6)
        t_done = time.perf_counter()
        missed = False
        if plan is not None and self.latch is not None:
            # a frame unblanked by its decision was drawn after it: not the latch's draw time
            missed = self.latch.observe(plan, flip.ready_s, flip.flip_s,
                                        adapt=predicted or decision.blank)
        self._last_blank_s = flip.flip_s
        self._visible = not decision.blank
        # 7. the frame's row
        dt, dropped = st.flip(flip.flip_s, decision.blank, decision.reason)
        sample_us, ecc = self._decided_by(decision)
        self.io.frame((self.trial_index, self.attempt, st.n_frames - 1, round(flip.flip_s, 6),
                       None if dt is None else round(dt, 6), dropped, decision.blank,
                       st.frames[-1][2], sample_us, ecc, flip_us, decision.decided_us,
                       self.start_us))
        if self.timings is not None:
            self.timings.append(FrameTiming(
                t_call - t0 - prepare_s - wait_s, c_call - c0, t_call - t_gaze, poll_s, n,
                upload_s, t_done - t_call, prepare_s, wait_s,
                max(0.0, flip.ready_s - decided_s), predicted, missed))
        return None

    def _decided_by(self, decision: BlankDecision) -> tuple[int | None, float | None]:
        """The newest sample the decision used: its system time and eccentricity (None when
        there is none, or it is invalid)."""
        s = self.monitor.last
        if s is None:
            return None, None
        ecc = decision.eccentricity_deg
        return int(s.system_time_us), (None if math.isinf(ecc) else round(float(ecc), 4))


__all__ = ["LATCH_MAX_MARGIN_S", "LATCH_MIN_MARGIN_S", "LATCH_SAFETY", "LATCH_WINDOW",
           "SWITCH_INTERVAL_S", "FrameTiming", "LatchPlan", "LateLatch", "TrialIO", "TrialLoop",
           "display_thread_first"]
