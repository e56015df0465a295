"""The screens around a session's trials (docs/EXPERIMENT.md): messages, the quit key's
confirmation, the pause screen, the lost tracker's wait, the instructions and the operator's
display checklist.

While any of them is up the gaze stream keeps going into the gaze log (``drain``: a long break
would otherwise overflow the tracker's buffer), and Escape or Q asks to quit on every screen;
Y quits, keeping everything logged (:class:`~fovexp.experiment.trackers.setup.Aborted`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from fovexp.results.format import now_iso

from ..interfaces import GazeSource, Screen, SessionRecord
from ..trackers.calibration import QUIT_KEYS, QUIT_PROMPT, QUIT_QUESTION
from ..trackers.setup import Aborted
from .operator import DISPLAY_CHECKLIST, checklist_text

#: the quit key's confirmation screen
QUIT_TEXT = f"{QUIT_QUESTION}\n\n{QUIT_PROMPT}"
#: the pause screen (a trial paused by the participant or the operator)
PAUSE_TEXT = ("Paused.\n\nSpace: continue (this trial starts again)\n"
              "Q: quit - progress is saved; continue later with --resume")
#: the lost tracker's screen
RECONNECT_TEXT = ("The eye tracker connection was lost. The trial will start again when it is "
                  "back.\n\nQ: quit (progress is saved; continue later with --resume)")
#: the instructions when a protocol has none
DEFAULT_INSTRUCTIONS = "Adjust the right half to match the left."


class Screens:
    """The message screens of one run on ``screen``; ``file`` gets their events, ``live`` (a
    :class:`fovexp.experiment.records.live.LivePublisher`) the state shown, ``drain`` is
    called while a screen waits. In a dry run each message stays ``dry_message_s``."""

    def __init__(self, screen: Screen, file: SessionRecord, live: Any,
                 drain: Callable[[], None], dry_message_s: float | None = None) -> None:
        self.screen, self.file, self.live, self.drain = screen, file, live, drain
        self.dry_message_s = dry_message_s

    def message(self, text: str, keys: Sequence[str], timeout_s: float | None = None,
                state: str = "message") -> str | None:
        """A message until one of ``keys`` (or ``timeout_s``); a quit key asks to quit
        (:meth:`confirm_quit`), and going back shows the message again."""
        if self.dry_message_s is not None:
            timeout_s = self.dry_message_s
        self.live.set_state(state, text)
        quit_keys = [k for k in QUIT_KEYS if k not in keys]
        while True:
            key = self.screen.message(text, [*keys, *quit_keys], timeout_s, self.drain)
            if key not in quit_keys:
                return key
            self.confirm_quit()

    def confirm_quit(self, trial_index: int | None = None) -> None:
        """Y quits (raises :class:`Aborted`, the event logged); N or Escape goes back. The
        calibration screens ask the same (:data:`QUIT_QUESTION`)."""
        key = self.screen.message(QUIT_TEXT, ["y", "n", "escape"], None, self.drain)
        if key == "y":
            self.file.event("aborted", trial_index=trial_index)
            raise Aborted()

    def pause(self, trial_index: int) -> None:
        """A paused trial: Space continues (the trial starts again), Q quits. Waits for the
        operator even in a dry run."""
        self.file.event("paused", trial_index=trial_index)
        self.live.set_state("paused")
        key = self.screen.message(PAUSE_TEXT, ["space", "q"], None, self.drain)
        if key == "q":
            self.file.event("aborted", trial_index=trial_index)
            raise Aborted()

    def wait_reconnect(self, gaze: GazeSource, trial_index: int) -> None:
        """The tracker lost mid-session: the screen blanked, a message, a wait; Q quits."""
        self.file.event("tracker_disconnected", trial_index=trial_index)
        self.live.set_state("disconnected")
        while not gaze.connected:
            # The stream is drained here too: a stalled tracker counts as back only when its
            # samples arrive again (and they belong in the gaze log, between trials).
            self.drain()
            for ev in gaze.poll_events():
                self.file.event(ev.kind, **ev.detail)
            key = self.screen.message(RECONNECT_TEXT, ["q", "escape"], 0.1, self.drain)
            if key is not None:
                self.confirm_quit(trial_index)
        self.file.event("tracker_reconnected", trial_index=trial_index)
        self.live.event("tracker_reconnected")

    def instructions(self, title: str, text: str, resumed: bool,
                     notes: Sequence[str] = ()) -> None:
        """The protocol's instructions, with the operator's notes (backend, budget) below."""
        more = " (continuing where the last session stopped)" if resumed else ""
        body = text.strip() or DEFAULT_INSTRUCTIONS
        tail = "".join(f"\n\nOperator: {n}" for n in notes)
        self.message(f"{title}{more}\n\n{body}\n\nPress Space to start.{tail}", ["space"])

    def display_checklist(self, dry_run: bool) -> None:
        """The operator confirms the display checklist (docs/EXPERIMENT.md) with C; recorded in
        this run's entry. A dry run records it as skipped."""
        if dry_run:
            entry: dict[str, Any] = {"skipped": "dry run"}
        else:
            self.message(checklist_text(), ["c"], None)
            entry = {"confirmed": True, "time": now_iso(), "items": list(DISPLAY_CHECKLIST)}
        self.file.set_in_run("display_setup", entry)
