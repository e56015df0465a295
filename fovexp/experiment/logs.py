"""Trial, gaze, frame and session logs (format: docs/LOGS.md).

Crash safety (issue item 7): every trial row is written with one ``write`` call ending in a
newline, then flushed and fsync'ed, so a SIGKILL leaves at most one torn last line. Readers
(this module's :func:`read_trials` and the analysis) detect a torn last line by its missing
newline, wrong field count or unparsable values, and drop it; :func:`repair_tail` cuts it off
before a resumed session appends, so the fragment never merges with a new row.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import threading
import warnings
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from fovexp.errors import FovexpError

#: ``trials.csv`` columns, in the documented order (docs/LOGS.md).
TRIAL_COLUMNS: tuple[str, ...] = (
    "participant", "session", "experiment", "protocol_sha256", "trial_index", "practice",
    "repetition", "image", "blur_rate", "method", "adjusted_parameter", "f_e", "s_k", "s_f",
    "start_value", "final_value", "response_time_s", "wheel_events", "blanked_fraction",
    "dropped_frames", "tracker", "seed", "software_version", "timestamp",
)
_INT = {"trial_index", "repetition", "wheel_events", "dropped_frames", "seed"}
_FLOAT = {"blur_rate", "f_e", "s_k", "s_f", "start_value", "final_value", "response_time_s",
          "blanked_fraction"}
_BOOL = {"practice"}

#: ``gaze-<session>.csv``: one row per tracker sample; times in microseconds.
GAZE_COLUMNS: tuple[str, ...] = (
    "trial_index", "device_time_us", "system_time_us", "left_x", "left_y", "left_valid",
    "right_x", "right_y", "right_valid", "x", "y", "valid", "eccentricity_deg",
)
#: ``frames-<session>.csv``: one row per stimulus frame (issue item 6, frame intervals).
FRAME_COLUMNS: tuple[str, ...] = (
    "trial_index", "frame", "flip_time_s", "interval_s", "dropped", "blanked", "value",
)
#: ``blanking-<session>.csv``: one row per blanking episode (issue item 3).
BLANKING_COLUMNS: tuple[str, ...] = (
    "trial_index", "start_s", "end_s", "frames", "reason",
)


def format_value(v: Any) -> str:
    """CSV text of a value: empty for None/NaN, 0/1 for bools, round-trip floats."""
    if v is None:
        return ""
    if isinstance(v, bool):
        return "1" if v else "0"
    if isinstance(v, float):
        return "" if math.isnan(v) else repr(v)
    return str(v)


def format_line(values: Sequence[Any]) -> str:
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerow([format_value(v) for v in values])
    return buf.getvalue()


def _parse_trial(fields: list[str]) -> dict[str, Any]:
    """Typed trial row; raises ValueError for a wrong field count or an unparsable value."""
    if len(fields) != len(TRIAL_COLUMNS):
        raise ValueError(f"{len(fields)} fields, expected {len(TRIAL_COLUMNS)}")
    row: dict[str, Any] = {}
    for k, v in zip(TRIAL_COLUMNS, fields, strict=True):
        if v == "":
            row[k] = None
        elif k in _INT:
            row[k] = int(v)
        elif k in _FLOAT:
            row[k] = float(v)
        elif k in _BOOL:
            if v not in ("0", "1"):
                raise ValueError(f"{k}={v!r} is not 0/1")
            row[k] = v == "1"
        else:
            row[k] = v
    for k in ("participant", "session", "trial_index", "timestamp"):
        if row[k] is None:
            raise ValueError(f"empty {k}")
    return row


def read_trials(path: Path) -> tuple[list[dict[str, Any]], int]:
    """Rows of a ``trials.csv`` and the byte length of its valid part.

    A torn last line is dropped with a warning naming the file; a bad row elsewhere is an error
    (the file is damaged and nothing is guessed).
    """
    path = Path(path)
    if not path.exists():
        return [], 0
    data = path.read_bytes()
    lines = data.split(b"\n")
    # After a final newline split() leaves b"": that is a complete file.
    tail_complete = lines[-1] == b""
    lines = lines[:-1] if tail_complete else lines
    if not lines:
        return [], 0
    header = lines[0].decode("utf-8", errors="replace").split(",")
    if tuple(header) != TRIAL_COLUMNS:
        if len(lines) == 1 and not tail_complete:
            warnings.warn(f"{path}: torn header dropped", stacklevel=2)
            return [], 0
        raise FovexpError(f"{path}: header does not match docs/LOGS.md ({','.join(header)[:80]})")
    rows: list[dict[str, Any]] = []
    good_len = len(lines[0]) + 1
    for i, raw in enumerate(lines[1:], start=2):
        last = i == len(lines)
        try:
            text = raw.decode("utf-8")
            fields = next(csv.reader([text]))
            row = _parse_trial(fields)
            if last and not tail_complete:
                raise ValueError("no final newline")
        except (ValueError, UnicodeDecodeError, StopIteration) as exc:
            if last:
                warnings.warn(f"{path}: torn last row (line {i}) dropped: {exc}", stacklevel=2)
                break
            raise FovexpError(f"{path}: line {i} is corrupt: {exc}") from None
        rows.append(row)
        good_len += len(raw) + 1
    return rows, good_len


def repair_tail(path: Path, good_len: int) -> bytes:
    """Cut ``path`` to ``good_len`` bytes (a torn tail), keeping the cut bytes in
    ``<path>.torn`` for inspection; returns them."""
    path = Path(path)
    size = path.stat().st_size
    if size <= good_len:
        return b""
    with open(path, "r+b") as fh:
        fh.seek(good_len)
        cut = fh.read()
        with open(str(path) + ".torn", "ab") as keep:
            keep.write(cut + b"\n")
        fh.truncate(good_len)
        fh.flush()
        os.fsync(fh.fileno())
    return cut


def _csv_good_length(path: Path) -> int:
    """Length of a batch CSV up to its last complete line (torn tails of gaze/frame logs)."""
    data = path.read_bytes()
    return data.rfind(b"\n") + 1


class TrialLog:
    """Appends one fsync'ed row per completed trial to ``trials.csv``."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        rows, good = read_trials(self.path)
        if self.path.exists():
            repair_tail(self.path, good)
        self.rows = rows
        if good == 0:
            self._write(format_line(TRIAL_COLUMNS))

    def _write(self, line: str) -> None:
        # One write of a whole line, then flush + fsync: at most this line can be torn.
        with open(self.path, "a", encoding="utf-8", newline="") as fh:
            fh.write(line)
            fh.flush()
            os.fsync(fh.fileno())

    def append(self, row: dict[str, Any]) -> None:
        missing = set(TRIAL_COLUMNS) - set(row)
        if missing:
            raise KeyError(f"trial row lacks {sorted(missing)}")
        self._write(format_line([row[k] for k in TRIAL_COLUMNS]))
        self.rows.append(row)


class BatchLog:
    """A CSV written in batches from a memory buffer (gaze samples, frames, blanking episodes).

    ``add`` only appends to a list under a lock; ``flush`` writes what has accumulated. On
    resume an existing file's torn tail is cut off first.
    """

    def __init__(self, path: Path, columns: Sequence[str]) -> None:
        self.path = Path(path)
        self.columns = tuple(columns)
        self._lock = threading.Lock()
        self._pending: list[Sequence[Any]] = []
        self.path.parent.mkdir(parents=True, exist_ok=True)
        if self.path.exists() and self.path.stat().st_size > 0:
            repair_tail(self.path, _csv_good_length(self.path))
        if not self.path.exists() or self.path.stat().st_size == 0:
            with open(self.path, "w", encoding="utf-8", newline="") as fh:
                fh.write(format_line(self.columns))

    def add(self, row: Sequence[Any]) -> None:
        with self._lock:
            self._pending.append(row)

    def extend(self, rows: Iterable[Sequence[Any]]) -> None:
        with self._lock:
            self._pending.extend(rows)

    def flush(self, sync: bool = False) -> int:
        with self._lock:
            rows, self._pending = self._pending, []
        if not rows and not sync:
            return 0
        text = "".join(format_line(r) for r in rows)
        with open(self.path, "a", encoding="utf-8", newline="") as fh:
            fh.write(text)
            fh.flush()
            if sync:
                os.fsync(fh.fileno())
        return len(rows)


class PeriodicFlusher:
    """A thread that flushes :class:`BatchLog` objects every ``period_s`` (disk work off the
    frame loop and out of the tracker callback)."""

    def __init__(self, logs: Sequence[BatchLog], period_s: float = 0.5) -> None:
        self.logs = list(logs)
        self.period_s = period_s
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="fovexp-log-flusher", daemon=True)

    def start(self) -> PeriodicFlusher:
        self._thread.start()
        return self

    def _run(self) -> None:
        while not self._stop.wait(self.period_s):
            for log in self.logs:
                log.flush()

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=5)
        for log in self.logs:
            log.flush(sync=True)


def write_json_atomic(path: Path, data: dict[str, Any]) -> None:
    """Write JSON via a temporary file and ``os.replace``: a reader sees old or new, never half."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w", encoding="utf-8") as fh:
        json.dump(data, fh, indent=2, sort_keys=False, default=str)
        fh.write("\n")
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)
    dfd = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(dfd)
    finally:
        os.close(dfd)
