"""The results disk: whether a session's logs fit before its first trial, and one line, not a
traceback, when it fills up during the session.

A session's logs grow with its length: the gaze log by a row per tracker sample (about 0.11 MB/s
at 600 Hz: 0.4 GB an hour), the frame log by a row per frame, the rest is small. Before the
first trial :func:`check_space` compares the disk's free space with :func:`estimate_log_bytes`
for the trials still to run, and refuses with both figures when they cannot fit. When the disk
fills anyway (another program, a longer session), every write that fails leaves its file as it
was before (the logs cut back what they had half written), the session stops, and
:func:`disk_full_message` says, in one line, that the disk is full, how full, and what to do:
free space, then continue with ``--resume`` (the trials logged so far are kept; the one under
way runs again).
"""

from __future__ import annotations

import errno
import shutil
from dataclasses import dataclass
from pathlib import Path

from fovexp import FovexpError

#: Bytes of a gaze-log row: a binocular sample with both eyes' positions, as the runner
#: writes it (182 on average, 187 at most in a simulated 600 Hz stream; a Tobii's floats are
#: as long).
GAZE_ROW_BYTES = 190
#: Bytes of a frame-log row (89 in a 4K dry run's log).
FRAME_ROW_BYTES = 95
#: Seconds of session per trial, breaks, instructions and tracker set-up included: the paper's
#: validation experiment took about 15 minutes for its 20 trials (section 6.1), 45 s a trial.
SESSION_S_PER_TRIAL = 45.0
#: The session file, the trial log and the blanking log, whatever the length (bytes).
FIXED_BYTES = 1_000_000
#: Errors that mean the disk (or the user's quota on it) is full.
FULL_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT})
MB = 1e6


@dataclass(frozen=True)
class LogEstimate:
    """A session's log size, estimated (:func:`estimate_log_bytes`)."""

    trials: int
    seconds: float
    gaze_bytes_per_s: float
    frame_bytes_per_s: float
    total_bytes: int

    def text(self) -> str:
        return (f"about {self.total_bytes / MB:.0f} MB for {self.trials} trial(s) "
                f"(~{self.seconds / 60:.0f} min at {SESSION_S_PER_TRIAL:g} s a trial; the gaze "
                f"log {self.gaze_bytes_per_s / MB:.2f} MB/s, the frame log "
                f"{self.frame_bytes_per_s / MB:.3f} MB/s)")


def estimate_log_bytes(trials: int, tracker_hz: float, refresh_hz: float) -> LogEstimate:
    """The logs of a session with ``trials`` trials still to run, with gaze at ``tracker_hz``
    and frames at ``refresh_hz``: :data:`SESSION_S_PER_TRIAL` of both per trial (gaze is
    logged between trials too; frames only in them, so this errs large), plus
    :data:`FIXED_BYTES`."""
    seconds = trials * SESSION_S_PER_TRIAL
    gaze = tracker_hz * GAZE_ROW_BYTES
    frames = refresh_hz * FRAME_ROW_BYTES
    return LogEstimate(trials, seconds, gaze, frames,
                       int(seconds * (gaze + frames)) + FIXED_BYTES)


def disk_usage(path: Path) -> tuple[int, int]:
    """(free, total) bytes of the disk ``path`` is on (or would be: its nearest existing
    folder)."""
    p = Path(path).absolute()
    while not p.exists() and p != p.parent:
        p = p.parent
    usage = shutil.disk_usage(p)
    return int(usage.free), int(usage.total)


def check_space(folder: Path, estimate: LogEstimate) -> dict[str, float]:
    """Refuse (:class:`FovexpError` with the figures) when the disk of ``folder`` has less
    free space than ``estimate``; returns the figures (MB) for the session file."""
    free, total = disk_usage(folder)
    figures = {"free_mb": round(free / MB, 1), "total_mb": round(total / MB, 1),
               "estimated_mb": round(estimate.total_bytes / MB, 1)}
    if free < estimate.total_bytes:
        raise FovexpError(
            f"the results disk has {free / MB:.1f} MB free (of {total / MB:.0f} MB) at "
            f"{folder}, but this session's logs need {estimate.text()}: free space there, or "
            "pass --results on a disk with room, or run fewer trials (--limit-trials)")
    return figures


def is_disk_full(exc: BaseException) -> bool:
    """Whether ``exc`` says the disk or the quota is full."""
    return isinstance(exc, OSError) and exc.errno in FULL_ERRNOS


def disk_full_message(folder: Path, resume: str) -> str:
    """The one line an operator gets when the results disk fills during a session: how full
    it is, and what to do (``resume``: the command that continues the session)."""
    try:
        free, total = disk_usage(folder)
        how = f"{free / MB:.1f} MB free of {total / MB:.1f} MB"
    except OSError:
        how = "no free space"
    return (f"the results disk is full ({folder}: {how}): the session stopped; everything "
            "logged so far is kept and the trial under way will run again. Free space on that "
            f"disk, then continue with: {resume}")


__all__ = ["FIXED_BYTES", "FRAME_ROW_BYTES", "GAZE_ROW_BYTES", "SESSION_S_PER_TRIAL",
           "LogEstimate", "check_space", "disk_full_message", "disk_usage",
           "estimate_log_bytes", "is_disk_full"]
