"""The order of a session's screens around its trials, without a window: the practice and
main-part announcements, the breaks, and where a trial stands in the plan (the console line).

Practice trials come first (paper section 6.1, "Participants": a sample was shown beforehand,
with a method not under test), then the trials in the session's order. Breaks are the runner's
own (the paper does not say): after every ``break_every`` main trials of the session's plan,
counted over the whole session, so that a resumed session breaks at the same places as one
that ran through.
"""

from __future__ import annotations

from collections.abc import Collection, Sequence

from ..protocol.spec import Trial

PRACTICE_TEXT = "Practice trials first.\n\nPress Space."
MAIN_TEXT = "Practice finished. The experiment starts now.\n\nPress Space."


def break_text(to_go: int) -> str:
    return f"Break. {to_go} trials to go.\n\nPress Space to continue."


class TrialSequence:
    """A run's trials (``remaining``) within the session's plan (``trials``); ``done`` is the
    set of trial indices logged so far, updated by the session as trials are confirmed (read
    live here)."""

    def __init__(self, trials: Sequence[Trial], remaining: Sequence[Trial], done: Collection[int],
                 break_every: int) -> None:
        self.trials, self.remaining, self.done = list(trials), list(remaining), done
        self.break_every = break_every
        self.n_main = sum(not t.practice for t in self.trials)
        self._practice_announced = False
        # a resumed session (trials already done) starts without the announcements
        self._main_announced = bool(done)

    def before(self, trial: Trial) -> list[str]:
        """The messages to show before ``trial`` (the trials are taken in order)."""
        out = []
        if trial.practice and not self._practice_announced:
            self._practice_announced = True
            out.append(PRACTICE_TEXT)
        if not trial.practice and not self._main_announced:
            self._main_announced = True
            if self._practice_announced:
                out.append(MAIN_TEXT)
        return out

    def left_after(self, trial: Trial) -> int:
        """This run's trials after ``trial``."""
        return sum(t.index > trial.index for t in self.remaining)

    def after(self, trial: Trial) -> str | None:
        """The break message due after ``trial`` (once it is done), or None."""
        main_done = sum(not t.practice and t.index in self.done for t in self.trials)
        if (not trial.practice and self.break_every and self.left_after(trial)
                and main_done % self.break_every == 0):
            return break_text(self.n_main - main_done)
        return None

    def position(self, trial: Trial) -> tuple[int, int]:
        """``trial``'s number among the plan's practice (or main) trials, and how many there
        are: "trial i/N" of the console line."""
        same = [t for t in self.trials if t.practice == trial.practice]
        return sum(t.index <= trial.index for t in same), len(same)


__all__ = ["MAIN_TEXT", "PRACTICE_TEXT", "TrialSequence", "break_text"]
