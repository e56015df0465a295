"""The logs of one run, opened, fed and closed together (docs/LOGS.md): ``trials.csv`` (one
row per confirmed trial, the commit point) and the session's gaze, frame and blanking logs,
written by one flusher thread off the frame loop.

A task writes through :class:`RunLogs` as its sink
(:class:`fovexp.experiment.tasks.adjust.TrialSink`): the frame loop's rows and samples as they
come, an attempt's blanking episodes however it ends, and a confirmed trial's row only after
the side logs are on disk.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..protocol.spec import LoadedProtocol, Trial
from ..tasks.trial import Episode, TrialState
from ..trackers.gaze import FixationGeometry, GazeSample
from .logs import (
    BLANKING_COLUMNS,
    FRAME_COLUMNS,
    GAZE_COLUMNS,
    TRIAL_HEADERS,
    BatchLog,
    PeriodicFlusher,
    TrialLog,
)
from .rows import GazeItem, blanking_rows, gaze_items, gaze_row, trial_row


class RunLogs:
    """The four logs of a run in ``folder`` for session ``session_id``."""

    def __init__(self, folder: Path, session_id: str, fixation: FixationGeometry,
                 task: str = "adjust") -> None:
        self.session_id, self.fixation = session_id, fixation
        # a forced-choice task's rows carry its answers after the documented columns
        self.trial_log = TrialLog(folder / "trials.csv", TRIAL_HEADERS[task == "2afc"])
        self.gaze_log = BatchLog(folder / f"gaze-{session_id}.csv", GAZE_COLUMNS,
                                 formatter=self._gaze_row)
        self.frame_log = BatchLog(folder / f"frames-{session_id}.csv", FRAME_COLUMNS)
        self.blank_log = BatchLog(folder / f"blanking-{session_id}.csv", BLANKING_COLUMNS)
        self.flusher: PeriodicFlusher | None = None

    def _gaze_row(self, item: GazeItem) -> tuple[Any, ...]:
        """A gaze log row (made on the log's flusher thread)."""
        return gaze_row(self.fixation, item)

    def start(self, live: Any = None) -> None:
        """The flusher thread from now on; ``live`` (:class:`.live.LivePublisher`) gets what the
        gaze and frame logs are given."""
        if live is not None:
            self.gaze_log.tap = live.gaze
            self.frame_log.tap = live.frames
        self.flusher = PeriodicFlusher([self.gaze_log, self.frame_log, self.blank_log]).start()

    # -- what a task writes (tasks.adjust.TrialSink) ---------------------------------------------
    def gaze(self, trial_index: int | None, attempt: int | None,
             samples: list[GazeSample]) -> None:
        """Samples into the gaze log (``trial_index`` None: between trials)."""
        self.gaze_log.extend(gaze_items(trial_index, samples, attempt))

    def frame(self, row: tuple[Any, ...]) -> None:
        self.frame_log.add(row)

    def blanking(self, trial_index: int, attempt: int, episodes: list[Episode]) -> None:
        self.blank_log.extend(blanking_rows(trial_index, attempt, episodes))

    def commit(self, protocol: LoadedProtocol, trial: Trial, st: TrialState, *,
               participant: str, seed: int, tracker: str) -> None:
        """A confirmed trial: the side logs synced first, then its row (the commit point)."""
        for log in (self.gaze_log, self.frame_log, self.blank_log):
            log.flush(sync=True)
        self.trial_log.append(trial_row(protocol, trial, st, participant=participant,
                                        session_id=self.session_id, seed=seed,
                                        tracker=tracker))

    def raise_error(self) -> None:
        """A log the flusher thread could not write (a full disk) stops the session here,
        between trials, with that error."""
        if self.flusher is not None and self.flusher.error is not None:
            raise self.flusher.error

    def session_rows(self) -> list[dict[str, Any]]:
        """This session's rows of ``trials.csv`` so far (earlier runs' too), in order: what a
        forced-choice task rebuilds its procedures from."""
        return [r for r in self.trial_log.rows if r["session"] == self.session_id]

    def done(self) -> set[int]:
        """The trials of this session with a row in ``trials.csv``."""
        return {int(r["trial_index"]) for r in self.trial_log.rows
                if r["session"] == self.session_id}

    def stop(self) -> OSError | None:
        """The last flush; returns the error of a write that failed, if any."""
        if self.flusher is None:
            return None
        self.flusher.stop()
        return self.flusher.error
