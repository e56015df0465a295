"""The screens around a session's trials (:mod:`fovexp.experiment.tasks.sequence`), without a
window: announcements once, breaks at the same places of the plan whether or not the session was
resumed, positions for the console line."""

from __future__ import annotations

from fovexp.experiment.protocol.spec import Trial
from fovexp.experiment.tasks.sequence import MAIN_TEXT, PRACTICE_TEXT, TrialSequence, break_text


def plan(n_practice: int, n_main: int) -> list[Trial]:
    return [Trial(i, i < n_practice, 0, "scene-00", "contrast", 0.34, None, 0.0)
            for i in range(n_practice + n_main)]


def screens(trials: list[Trial], done: set[int], break_every: int) -> list[str]:
    """What a run shows, trial by trial, as the session drives it (every trial confirmed)."""
    remaining = [t for t in trials if t.index not in done]
    seq = TrialSequence(trials, remaining, done, break_every)
    out = []
    for t in remaining:
        out += seq.before(t)
        out.append(f"trial {t.index}")
        done.add(t.index)
        if (b := seq.after(t)) is not None:
            out.append(b)
    return out


def test_announcements_and_breaks() -> None:
    trials = plan(2, 5)
    assert screens(trials, set(), 2) == [
        PRACTICE_TEXT, "trial 0", "trial 1", MAIN_TEXT, "trial 2", "trial 3", break_text(3),
        "trial 4", "trial 5", break_text(1), "trial 6"]  # none after the last trial
    assert screens(plan(0, 3), set(), 0) == ["trial 0", "trial 1", "trial 2"]


def test_resumed_session_breaks_at_the_same_places() -> None:
    """Stopped after the 3rd main trial and resumed: no announcements, the break after the
    4th main trial as in a session that ran through."""
    trials = plan(2, 5)
    assert screens(trials, {0, 1, 2, 3, 4}, 2) == ["trial 5", break_text(1), "trial 6"]
    # trials done out of order (a resumed session that had skipped one) count too
    assert screens(trials, {0, 1, 3}, 2) == ["trial 2", break_text(3), "trial 4", "trial 5",
                                             break_text(1), "trial 6"]


def test_positions_and_trials_left() -> None:
    trials = plan(2, 5)
    seq = TrialSequence(trials, trials[3:], {0, 1, 2}, 0)
    assert seq.position(trials[1]) == (2, 2) and seq.position(trials[4]) == (3, 5)
    assert seq.left_after(trials[3]) == 3 and seq.left_after(trials[6]) == 0
