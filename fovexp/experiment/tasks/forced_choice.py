"""The forced-choice task (``task: 2afc``, issue 30): which half is degraded?

Each trial shows the split screen of the adjustment task (:mod:`.adjust`; paper section 5.1:
the reference half and its mirror image meeting at the fixation cross, the same gaze-contingent
blanking and frame loop), with one half at full resolution and the other, on a side drawn per
trial (:func:`fovexp.experiment.protocol.forced_choice.degraded_side`), processed by the trial's
method at the blur-rate its procedure chooses (:mod:`.procedures`; practice trials at the
grid's top). The stimulus stays on screen for the protocol's presentation time, then a blank
response screen (the cross alone) waits, without a time limit, for the left or right key;
feedback, if the protocol asks for it, follows. The frame log covers the presentation; the
trial's row (``trials.csv``, written through the same :class:`.adjust.TrialSink`) carries the
blur-rate, the side, the answer, whether it was correct and the response time, from the
response screen's first flip to the key press.

A degraded left half is the whole screen mirrored about the seam: the processed half drawn
flipped on the left, the reference flipped on the right (``Screen.set_mirrored``), so the
blur still grows away from the cross.

On ``--resume`` each method's procedure is rebuilt from this session's logged answers
(:func:`.procedures.rebuild`): the next blur-rate is the one the run that was killed would
have shown.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

from fovexp.results.choices import TASK_2AFC

from ..protocol.forced_choice import ForcedChoiceSpec, degraded_side
from ..protocol.spec import Trial
from ..trackers.gaze import BlankingMonitor
from .adjust import AdjustmentTask
from .frameloop import TrialIO, TrialLoop
from .procedures import ConstantStimuli, Procedure, QuestPlus, rebuild
from .simulated_observer import SimulatedObserver
from .trial import InputEvent, Key, TrialState, ValueAdjuster


class ChoiceState(TrialState):
    """A forced-choice trial: the presentation's frames (as :class:`TrialState` records
    them, at one blur-rate), then the answer."""

    def __init__(self, blur_rate: float, top: float, side: str, grid_index: int | None,
                 fc: ForcedChoiceSpec, refresh_hz: float) -> None:
        super().__init__(ValueAdjuster(0.0, top, top, top, blur_rate), refresh_hz)
        self.blur_rate, self.side, self.grid_index, self.fc = blur_rate, side, grid_index, fc
        self.answer: str | None = None
        self.t_response_start: float | None = None
        self.t_answer: float | None = None

    def handle(self, events: list[InputEvent], now_s: float | None = None) -> str | None:
        """During the presentation only Escape (pause) counts: the wheel and Enter do nothing,
        and an answer key before the response screen is not an answer."""
        return "pause" if any(isinstance(e, Key) and e.name == "escape" for e in events) else None

    def answered(self, answer: str, t: float) -> None:
        self.answer, self.t_answer = answer, t

    @property
    def correct(self) -> bool:
        return self.answer == self.side

    @property
    def response_time_s(self) -> float:
        """From the response screen's first flip to the answer key's press (s)."""
        if self.t_response_start is None or self.t_answer is None:
            return float("nan")
        return self.t_answer - self.t_response_start

    def extra_columns(self) -> dict[str, object]:
        return {"task": TASK_2AFC, "degraded_side": self.side, "answer": self.answer,
                "correct": self.correct, "presentation_s": self.fc.presentation_s,
                "procedure": self.fc.procedure, "grid_index": self.grid_index}


def make_procedure(fc: ForcedChoiceSpec, method_index: int, seed: int) -> Procedure:
    """A method's procedure as the protocol states it (``method_index``: the method's place in
    the protocol's list, so that constant stimuli draw a different order per method)."""
    if fc.procedure == "questplus":
        return QuestPlus(fc.grid_values, fc.slopes, fc.lapse_rates)
    return ConstantStimuli(fc.grid_values, fc.trials_per_method, seed * 8 + method_index)


@dataclass
class ForcedChoiceTask(AdjustmentTask):
    """A run's forced-choice trials (module docstring): the adjustment task's order of
    trials, announcements, breaks, console line and tracker checks, with a forced-choice
    attempt (:meth:`run_attempt`)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        spec = self.protocol.spec
        assert spec.forced_choice is not None, "a task: 2afc protocol"
        self.fc = spec.forced_choice
        rows = sorted((r for r in self.sink.session_rows() if not r["practice"]),
                      key=lambda r: r["trial_index"])
        self.procedures: dict[str, Procedure] = {}
        for k, method in enumerate(spec.methods):
            self.procedures[method] = rebuild(
                make_procedure(self.fc, k, self.seed),
                [(float(r["blur_rate"]), bool(r["correct"])) for r in rows
                 if r["method"] == method], f"{self.protocol.path}: resuming {method}")

    def _blur_rate(self, trial: Trial) -> tuple[float, int | None]:
        """The trial's blur-rate and its index on the grid (practice: the grid's top)."""
        grid = self.fc.grid_values
        value = grid[-1] if trial.practice else self.procedures[trial.method].next_blur_rate()
        return value, grid.index(value)

    def run_attempt(self, trial: Trial, attempt: int = 0
                    ) -> tuple[str, TrialState, list[float]]:
        """One attempt: the presentation (the frame loop for ``presentation_s``), the
        response screen, the row; ``done``, ``pause`` or ``disconnected`` as in the adjustment
        task (a paused attempt starts again at the same blur-rate and side)."""
        spec, fc = self.protocol.spec, self.fc
        blur_rate, grid_index = self._blur_rate(trial)
        side = degraded_side(self.seed, trial.index)
        frame = self.load_frame(trial)
        w = frame.shape[1]
        self.screen.set_reference(frame[:, : w // 2])
        self.screen.set_mirrored(side == "left")
        st = ChoiceState(blur_rate, fc.grid_values[-1], side, grid_index, fc, self.refresh_hz)
        self.renderer.set_image(frame[:, w // 2:], (w, frame.shape[0]))
        monitor = BlankingMonitor(self.fixation, spec.fixation.radius_deg,
                                  spec.fixation.gaze_timeout_s)
        latency_ms: list[float] = []

        def frame_row(row: tuple[object, ...]) -> None:
            self.sink.frame(row)
            if row[8] is not None:  # gaze-to-flip, for the console line
                latency_ms.append((row[10] - row[8]) / 1e3)  # type: ignore[operator]

        def event(kind: str, detail: dict[str, object]) -> None:
            self.file.event(kind, **detail)
            self.live.event(kind, detail)

        loop = TrialLoop(
            screen=self.screen, gaze=self.gaze, renderer=self.renderer, monitor=monitor,
            state=st, params_for=lambda v: self.params(trial, v), parameter="blur_rate",
            trial_index=trial.index, attempt=attempt, latch=self.latch,
            io=TrialIO(frame=frame_row, gaze=self.sink.gaze, event=event))
        position, total = self.seq.position(trial)
        self.live.begin_attempt(trial.index, attempt, position=position, total=total,
                                practice=trial.practice, method=trial.method,
                                image=trial.image, parameter="blur_rate",
                                blur_rate=blur_rate, start_value=blur_rate)
        outcome = "error"
        try:
            loop.show_first()
            outcome = loop.run(max_s=fc.presentation_s)
            if outcome == "timeout":
                outcome = self._respond(trial, attempt, st)
        finally:
            st.finish(time.monotonic())
            self.sink.blanking(trial.index, attempt, st.blanking.episodes)
            self.live.end_attempt(outcome)
            self.screen.set_mirrored(False)
        if outcome == "done":
            self.sink.commit(self.protocol, trial, st, participant=self.participant,
                             seed=self.seed, tracker=self.tracker)
            self.done.add(trial.index)
            if not trial.practice:  # after the row: a resumed run replays the same answers
                self.procedures[trial.method].update(blur_rate, st.correct)
            if fc.feedback_s > 0:
                self.screens.message("Correct" if st.correct else "Wrong", [], fc.feedback_s)
        return outcome, st, latency_ms

    def _respond(self, trial: Trial, attempt: int, st: ChoiceState) -> str:
        """The blank response screen until an answer key (``done``), Escape (``pause``) or a
        lost tracker (``disconnected``); the simulated observer answers after its response
        time."""
        left, right = self.fc.keys
        # a dry run's observer, its stream drawn from the trial (a resumed run answers the
        # trials it runs as the run that was killed would have)
        observer = None if self.sim is None else SimulatedObserver(
            self.sim.truth, (self.seed + 2) * 100_003 + trial.index, self.sim.speed)
        wait_s = None if observer is None else observer.response_time_s()
        while True:
            flip = self.screen.draw(blank=True)
            if st.t_response_start is None:
                st.t_response_start = flip.flip_s
            self.sink.gaze(trial.index, attempt, self.gaze.poll())
            for ev in self.screen.poll_input():
                if not isinstance(ev, Key):
                    continue
                if ev.name == "escape":
                    return "pause"
                if ev.name in (left, right):
                    t = ev.t_s if ev.t_s is not None else time.monotonic()
                    st.answered("left" if ev.name == left else "right", t)
                    return "done"
            if observer is not None and wait_s is not None and (
                    time.monotonic() - st.t_response_start >= wait_s):
                st.answered(observer.answer(trial.method, st.blur_rate, st.side),
                            time.monotonic())
                return "done"
            if not self.gaze.connected:
                return "disconnected"


#: the task class of each protocol ``task`` (the session runs the one its protocol names)
TASKS: dict[str, type[AdjustmentTask]] = {"adjust": AdjustmentTask, "2afc": ForcedChoiceTask}

__all__ = ["TASKS", "ChoiceState", "ForcedChoiceTask", "make_procedure"]
