"""The live status file (``live-<session>.json``, docs/LOGS.md): what a running session shows
now, for ``fovexp monitor``.

The runner (:mod:`fovexp.experiment.records.live`) rewrites it a few times a second from a thread of
its own; the monitor reads it from disk and shares nothing else with the runner, so it can
neither slow a frame nor stop a session. Each write is whole: a temporary file renamed over the
old one (``os.replace``), so a reader sees the old text or the new, never half. It is not
fsync'ed (four times a second would only load the disk; the session's own logs are): after a
power cut it may be empty or old, and :func:`read_live` says so instead of failing.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

#: the value of the file's ``format`` key; a reader refuses another
LIVE_FORMAT = "fovexp-live/1"
#: how often the runner rewrites the file (s)
LIVE_PERIOD_S = 0.25
#: the gaze the file keeps: the last seconds, at most this many samples per second
GAZE_WINDOW_S = 3.0
GAZE_MAX_RATE_HZ = 100.0
#: a runner whose file has not changed for this long has stopped (killed, crashed, machine off)
STALE_AFTER_S = 3.0
#: a status file larger than this is not read (it is a few kB)
MAX_LIVE_BYTES = 1 << 20
#: how a run ended, by the ``state`` of its last write (the session file's ``state`` values),
#: in the words the monitor's page says it with
ENDINGS = {
    "completed": "completed",
    "incomplete": "ended with trials left (fovexp run --resume continues)",
    "aborted": "quit by the operator",
    "interrupted": "interrupted (Ctrl-C or a signal)",
    "failed": "crashed (an error; the session file names it)",
}
#: the ``state`` of a run that has ended
FINAL_STATES = frozenset(ENDINGS)
#: what a running session may be doing (``state``)
RUN_STATES = frozenset({"starting", "calibrating", "message", "trial", "between trials",
                        "break", "paused", "disconnected"})


def live_path(folder: str | Path, session: str) -> Path:
    """The status file of ``session`` in its participant's folder."""
    return Path(folder) / f"live-{session}.json"


def write_live(path: str | Path, data: dict[str, Any]) -> None:
    """Write the status file whole (a temporary file renamed over it; no fsync). A failed
    write (a full disk) leaves no temporary file behind; a folder that is gone is not made
    again."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write(json.dumps(data, separators=(",", ":"), allow_nan=False, default=str))
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


@dataclass(frozen=True)
class LiveRead:
    """A status file as read: its content, or why there is none (``problem``)."""

    data: dict[str, Any] | None
    problem: str | None = None
    #: the file's modification time (s since the epoch; None when it could not be read)
    mtime: float | None = None


def read_live(path: str | Path, max_bytes: int = MAX_LIVE_BYTES) -> LiveRead:
    """Read a status file; never raises. A file that is missing, too large, not JSON (empty
    after a power cut, or not the runner's) or of another format gives ``data`` None and the
    reason."""
    path = Path(path)
    try:
        st = path.stat()
        if st.st_size > max_bytes:
            return LiveRead(None, f"{st.st_size} bytes, more than a status file's {max_bytes}",
                            st.st_mtime)
        raw = path.read_bytes()[: max_bytes + 1]
    except FileNotFoundError:
        return LiveRead(None, "no status file")
    except OSError as exc:
        return LiveRead(None, f"cannot read: {exc.strerror}")
    try:
        data = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as exc:
        what = "empty" if not raw.strip() else f"not JSON ({str(exc)[:80]})"
        return LiveRead(None, what, st.st_mtime)
    if not isinstance(data, dict):
        return LiveRead(None, "not a JSON object", st.st_mtime)
    if data.get("format") != LIVE_FORMAT:
        return LiveRead(None, f"format {str(data.get('format'))[:40]!r}, not {LIVE_FORMAT!r}",
                        st.st_mtime)
    return LiveRead(data, None, st.st_mtime)


__all__ = ["ENDINGS", "FINAL_STATES", "GAZE_MAX_RATE_HZ", "GAZE_WINDOW_S", "LIVE_FORMAT",
           "LIVE_PERIOD_S", "MAX_LIVE_BYTES", "RUN_STATES", "STALE_AFTER_S", "LiveRead",
           "live_path", "read_live", "write_live"]
