"""The adjustment task of the paper's section 5.1 ("Task"), trial by trial: each trial in the
plan's order until one attempt at it is confirmed, with the announcements and breaks around
it, the console line after it and the tracker's checks between trials.

An attempt is the frame loop's (:class:`.frameloop.TrialLoop`: the reference's left half on the
left, the mirrored half processed with the current value on the right, a fixation cross on the
seam; the wheel changes the value, Enter confirms; whenever the gaze leaves the 1.25 deg window
around the cross, or is invalid or lost, the next frame is black). What is logged is what was on
screen: each frame's value is that of the render shown in it, and ``final_value`` is the value on
screen when Enter was pressed. What the task writes goes to its :class:`TrialSink`
(:class:`fovexp.experiment.records.runlogs.RunLogs` in a session).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from ..interfaces import GazeSource, Renderer, Screen, SessionRecord
from ..protocol.spec import LoadedProtocol, Trial
from ..trackers.gaze import BlankingMonitor, FixationGeometry, GazeSample
from .frameloop import LateLatch, TrialIO, TrialLoop
from .operator import eta_s, trial_line
from .screens import Screens
from .sequence import TrialSequence
from .simulated_participant import SimulatedParticipant
from .trial import Episode, TrialState, ValueAdjuster

if TYPE_CHECKING:
    from fovexp import EnhanceParams


class TrialSink(Protocol):
    """Where an adjustment task's output goes; each call only buffers, except :meth:`commit`,
    which puts the side logs on disk and then the trial's row."""

    def frame(self, row: tuple[Any, ...]) -> None: ...

    def gaze(self, trial_index: int | None, attempt: int | None,
             samples: list[GazeSample]) -> None: ...

    def blanking(self, trial_index: int, attempt: int, episodes: list[Episode]) -> None: ...

    def commit(self, protocol: LoadedProtocol, trial: Trial, st: TrialState, *,
               participant: str, seed: int, tracker: str) -> None: ...

    def raise_error(self) -> None: ...

    def session_rows(self) -> list[dict[str, Any]]: ...


@dataclass
class AdjustmentTask:
    """A run's adjustment trials (module docstring). ``attempts`` (attempts begun per trial,
    all runs) and ``done`` (trials with a row) are the session's, updated in place;
    ``load_frame(trial)`` gives the trial's split-screen frame; ``between_trials(trial,
    more_trials)`` is the tracker's drift check and recalibration; ``say`` the console."""

    protocol: LoadedProtocol
    participant: str
    seed: int
    tracker: str
    trials: list[Trial]
    remaining: list[Trial]
    done: set[int]
    attempts: dict[int, int]
    screen: Screen
    gaze: GazeSource
    renderer: Renderer
    fixation: FixationGeometry
    refresh_hz: float
    latch: LateLatch | None
    screens: Screens
    file: SessionRecord
    live: Any
    sink: TrialSink
    load_frame: Callable[[Trial], np.ndarray]
    between_trials: Callable[[Trial, bool], None]
    say: Callable[[str], None]
    sim: SimulatedParticipant | None = None

    def __post_init__(self) -> None:
        self.seq = TrialSequence(self.trials, self.remaining, self.done,
                                 self.protocol.spec.break_every)
        self._trial_seconds: list[float] = []  # this run's trial durations (the console's ETA)

    def params(self, trial: Trial, value: float) -> EnhanceParams:
        return self.protocol.make_params(trial, value, self.seed)

    def run(self) -> None:
        """The run's trials in order (announcements and breaks at the same places of the plan
        whatever runs it took); each until an attempt is confirmed; after each, the console
        line and the tracker's checks."""
        for trial in self.remaining:
            self.sink.raise_error()
            for text in self.seq.before(trial):
                self.screens.message(text, ["space"])
            position, total = self.seq.position(trial)
            # said as it starts too: a trial can take minutes (a 4K dry run on a CPU)
            self.say(f"{'practice ' if trial.practice else ''}trial {position}/{total}: "
                     f"{trial.image}, {trial.method}, on screen")
            t0 = time.monotonic()
            st, latency_ms = self._attempts_until_done(trial)
            self._trial_seconds.append(time.monotonic() - t0)
            left = self.seq.left_after(trial)
            self._console_line(trial, st, latency_ms, left)
            pause = self.seq.after(trial)
            if pause is not None:
                self.screens.message(pause, ["space"], state="break")
            self.live.set_state("between trials")
            self.between_trials(trial, left > 0)
            self.live.tracker_quality(self.file.info.get("tracker_quality"))

    def _attempts_until_done(self, trial: Trial) -> tuple[TrialState, list[float]]:
        """Attempts at ``trial`` until one is confirmed: a pause or a lost tracker restarts it
        (the next attempt); Q on the pause screen quits."""
        while True:
            attempt = self.attempts.get(trial.index, 0)
            self.attempts[trial.index] = attempt + 1
            # on disk before its first frame: a resumed session numbers on from it
            self.file.update(attempts={str(k): v for k, v in self.attempts.items()})
            outcome, st, latency_ms = self.run_attempt(trial, attempt)
            if outcome == "done":
                return st, latency_ms
            if outcome == "pause":
                self.screens.pause(trial.index)
            elif outcome == "disconnected":
                self.screens.wait_reconnect(self.gaze, trial.index)

    def _console_line(self, trial: Trial, st: TrialState, latency_ms: list[float],
                      left: int) -> None:
        """trial i/N, blanked %, dropped frames, gaze-to-flip latency, ETA (docs/EXPERIMENT.md)."""
        position, total = self.seq.position(trial)
        eta = eta_s(self._trial_seconds, left)
        self.live.set_eta(eta)
        self.say(trial_line(position=position, total=total, practice=trial.practice,
                            blanked_fraction=st.blanking.fraction, dropped=st.timer.dropped,
                            frames=st.n_frames, latency_ms=np.array(latency_ms, dtype=float),
                            eta_s=eta))

    def run_attempt(self, trial: Trial, attempt: int = 0
                    ) -> tuple[str, TrialState, list[float]]:
        """One attempt at a trial; returns ``done``, ``pause`` or ``disconnected``, its state
        and its frames' gaze-to-flip latencies (ms).

        Every frame goes to the frame log as it is shown and every attempt's blanking episodes
        to the blanking log, however the attempt ends (an interrupted one included), tagged
        with ``attempt``. From the first flip after the attempt ends the cross is alone on
        screen; the trial's row is committed after it.
        """
        loop, st, latency_ms = self._trial_loop(trial, attempt)
        position, total = self.seq.position(trial)
        adj = self.protocol.spec.adjust
        self.live.begin_attempt(trial.index, attempt, position=position, total=total,
                                practice=trial.practice, method=trial.method,
                                image=trial.image, parameter=adj.parameter,
                                blur_rate=trial.blur_rate, start_value=trial.start_value)
        outcome = "error"
        try:
            loop.show_first()
            outcome = loop.run()
        finally:
            st.finish(time.monotonic())  # when the loop could not flip its closing frame
            self.sink.blanking(trial.index, attempt, st.blanking.episodes)
            self.live.end_attempt(outcome)
        if outcome == "done":
            self.sink.commit(self.protocol, trial, st, participant=self.participant,
                             seed=self.seed, tracker=self.tracker)
            self.done.add(trial.index)
        return outcome, st, latency_ms

    def _trial_loop(self, trial: Trial, attempt: int
                    ) -> tuple[TrialLoop, TrialState, list[float]]:
        """The frame loop of an attempt, wired to this run's screen, gaze, renderer and sink
        (its frames' gaze-to-flip latencies kept for the console line)."""
        spec = self.protocol.spec
        adj = spec.adjust
        frame = self.load_frame(trial)
        w = frame.shape[1]
        self.screen.set_reference(frame[:, : w // 2])
        adjuster = ValueAdjuster(adj.range[0], adj.range[1], adj.step, adj.fine_step,
                                 trial.start_value)
        st = TrialState(adjuster, self.refresh_hz)
        self.renderer.set_image(frame[:, w // 2:], (w, frame.shape[0]))
        monitor = BlankingMonitor(self.fixation, spec.fixation.radius_deg,
                                  spec.fixation.gaze_timeout_s)
        participant = None
        if self.sim is not None:
            self.sim.begin(adj.parameter, trial.method, trial.blur_rate, trial.s_f,
                           adj.range[0], adj.range[1], adj.step, adj.fine_step,
                           start=adjuster.value)
            participant = self.sim.poll
        latency_ms: list[float] = []

        def frame_row(row: tuple[Any, ...]) -> None:
            self.sink.frame(row)
            if row[8] is not None:  # gaze-to-flip, for the console line
                latency_ms.append((row[10] - row[8]) / 1e3)

        def event(kind: str, detail: dict[str, Any]) -> None:
            self.file.event(kind, **detail)
            self.live.event(kind, detail)

        loop = TrialLoop(
            screen=self.screen, gaze=self.gaze, renderer=self.renderer, monitor=monitor,
            state=st, params_for=lambda v: self.params(trial, v), parameter=adj.parameter,
            trial_index=trial.index, attempt=attempt, participant=participant,
            latch=self.latch, io=TrialIO(frame=frame_row, gaze=self.sink.gaze, event=event))
        return loop, st, latency_ms
