"""The frame loop of one attempt at a trial (paper section 5.1, "Task"), without PsychoPy.

The session runs every trial through :class:`TrialLoop`, and ``benchmarks/display_loop.py``
drives the same class at 4K to measure it. Per frame, on the display thread, in this order:

1. tracker status events; a lost tracker ends the attempt;
2. input (wheel, keys, and a simulated participant's) through :class:`TrialState`: a wheel step
   requests a render; Enter ends the attempt at once: the value on screen is the answer and a
   render still pending is dropped (``final_value`` is what the participant saw); Escape
   pauses;
3. a finished render becomes the test half (an 8-bit upload, or a texture switch: the render
   thread prepared either);
4. gaze: the samples since the last frame, taken as late as possible, so that the newest one
   decides whether the frame about to be drawn is black (beyond 1.25 deg, invalid, or no
   sample newer than ``gaze_timeout_s``);
5. draw and flip; the flip time is put on the tracker's clock (``now_us`` read right after);
6. the frame's log row: the gaze sample that decided it and the flip, on one clock.

On leaving (Enter, pause, lost tracker) the loop flips a black frame with the cross at once:
from the first flip after Enter nothing but the cross is on screen until the next trial's
stimulus. Nothing here writes a file or waits for the render thread: log rows and events go
to callbacks that only buffer them (the session's logs are written by their own threads).
"""

from __future__ import annotations

import gc
import math
import os
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from .gaze import BlankDecision, BlankingMonitor, GazeSample
from .interfaces import GazeSource, Renderer, Screen
from .trial import InputEvent, TrialState

if TYPE_CHECKING:
    from fovexp import EnhanceParams

#: While a session runs, a thread that wants the GIL waits at most about this long for another
#: to give it up (Python's default is 5 ms, most of a 120 Hz frame; sys.setswitchinterval).
SWITCH_INTERVAL_S = 0.0005


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


@dataclass(frozen=True)
class FrameTiming:
    """The display thread's own time on one frame (``benchmarks/display_loop.py``)."""

    #: from the frame's first step to the flip call (wall clock)
    work_s: float
    #: the display thread's CPU time over the same span (less than ``work_s`` when it waited:
    #: for the GIL, or for a core on a busy machine)
    work_cpu_s: float
    #: from the start of the gaze poll to the flip call
    gaze_to_flip_call_s: float
    #: the gaze source's poll alone (a simulated source generates its samples in it)
    gaze_poll_s: float
    #: samples that poll returned
    samples: int
    #: the test half's upload (or texture switch) in this frame; None without one
    upload_s: float | None
    #: the flip call itself (swap; with vsync or pacing, the wait for the vertical blank)
    flip_s: float


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
    ``timings``, when a list, gets one :class:`FrameTiming` per frame.
    """

    def __init__(self, *, screen: Screen, gaze: GazeSource, renderer: Renderer,
                 monitor: BlankingMonitor,
                 state: TrialState, params_for: Callable[[float], EnhanceParams], parameter: str,
                 trial_index: int, attempt: int, io: TrialIO,
                 participant: Callable[[float, float, bool], list[InputEvent]] | None = None,
                 timings: list[FrameTiming] | None = None) -> None:
        self.screen, self.gaze, self.renderer = screen, gaze, renderer
        self.monitor, self.st = monitor, state
        self.params_for, self.parameter = params_for, parameter
        self.trial_index, self.attempt = trial_index, attempt
        self.io, self.participant, self.timings = io, participant, timings
        self._visible = False  # the stimulus is on screen now (the last frame's decision)

    # -- before the first frame ------------------------------------------------------------------
    def show_first(self, poll_s: float = 0.05) -> None:
        """Request the start value's render and show the cross alone (black frames) until it is
        done; the samples meanwhile go to the gaze log without a trial and tell the blanking
        monitor where the gaze is, so the first frame is not blanked as "lost"."""
        serial = self.renderer.request(self.params_for(self.st.value))
        while True:
            try:
                got = self.renderer.wait(serial, timeout=poll_s)
                break
            except TimeoutError:
                self.screen.draw(blank=True)
                self._between_frames()
        self.screen.set_test(got)
        self.st.show(float(getattr(got.params, self.parameter)))
        self._between_frames()

    def _between_frames(self) -> None:
        samples = self.gaze.poll()
        self.monitor.update(samples, self.gaze.now_us())
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
                t = self.screen.draw(blank=True)
                # the samples up to this closing frame belong to the attempt (the gaze log)
                self.io.gaze(self.trial_index, self.attempt, self.gaze.poll())
            except Exception:  # leaving on an error: that error is the one to report
                t = time.monotonic()
            st.finish(t)
            if collecting:
                gc.enable()
        return outcome

    def _frame(self) -> str | None:
        st, screen, gaze = self.st, self.screen, self.gaze
        t0 = time.perf_counter()
        c0 = time.thread_time()
        # 1. tracker status
        for ev in gaze.poll_events():
            self.io.event(ev.kind, {"trial_index": self.trial_index, **ev.detail})
        if not gaze.connected:
            return "disconnected"  # the trial restarts once the tracker is back
        # 2. input
        events = screen.poll_input()
        if self.participant is not None and st.t_start is not None:
            # what is on screen; a participant cannot judge it while it is black or still
            # shows an older value than the wheel asked for
            events = events + self.participant(time.monotonic() - st.t_start, st.shown_value,
                                               self._visible and st.shown_value == st.value)
        outcome = st.handle(events)
        if outcome == "pause":
            return "pause"
        if outcome == "confirm":
            st.confirm(time.monotonic())
            self.renderer.drop_pending()  # the answer is the value on screen
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
        # 4. gaze, as late as possible
        t_gaze = time.perf_counter()
        samples = gaze.poll()
        t_polled = time.perf_counter()
        decision = self.monitor.update(samples, gaze.now_us())
        self.io.gaze(self.trial_index, self.attempt, samples)
        # 5. draw and flip
        screen.prepare(decision.blank)
        t_call = time.perf_counter()
        c_call = time.thread_time()
        t_flip = screen.flip()
        flip_us = gaze.now_us() - round((time.monotonic() - t_flip) * 1e6)
        t_done = time.perf_counter()
        self._visible = not decision.blank
        # 6. the frame's row
        dt, dropped = st.flip(t_flip, decision.blank, decision.reason)
        sample_us, ecc = self._decided_by(decision)
        self.io.frame((self.trial_index, self.attempt, st.n_frames - 1, round(t_flip, 6),
                       None if dt is None else round(dt, 6), dropped, decision.blank,
                       st.shown_value, sample_us, ecc, flip_us))
        if self.timings is not None:
            self.timings.append(FrameTiming(t_call - t0, c_call - c0, t_call - t_gaze,
                                            t_polled - t_gaze, len(samples), upload_s,
                                            t_done - t_call))
        return None

    def _decided_by(self, decision: BlankDecision) -> tuple[int | None, float | None]:
        """The newest sample the decision used: its system time and eccentricity (None when
        there is none, or it is invalid)."""
        s = self.monitor.last
        if s is None:
            return None, None
        if decision.reason in ("", "outside"):
            ecc = decision.eccentricity_deg
        elif decision.reason == "lost" and s.valid:  # too old, but it has a position
            ecc = self.monitor.fixation.eccentricity(s.point)
        else:
            ecc = math.inf
        return int(s.system_time_us), (None if math.isinf(ecc) else round(float(ecc), 4))


__all__ = ["SWITCH_INTERVAL_S", "FrameTiming", "TrialIO", "TrialLoop", "display_thread_first"]
