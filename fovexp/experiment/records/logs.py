"""Trial, gaze, frame and session logs (format: docs/LOGS.md).

The formats themselves (columns, types, the torn-row reader) are defined once in
:mod:`fovexp.results.format`, which the analysis uses too.

Crash safety (issue item 7): every trial row is written with one ``write`` call ending in a
newline, then flushed and fsync'ed, so a SIGKILL leaves at most one torn last line. Readers
(this module's :func:`read_trials` and the analysis) detect a torn last line by its missing
newline, wrong field count or unparsable values, and drop it; :func:`repair_tail` cuts it off
before a resumed session appends, so the fragment never merges with a new row.
"""

from __future__ import annotations

import json
import os
import threading
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from fovexp import FovexpError
from fovexp.results.choices import FORCED_CHOICE_COLUMNS, choice_fields, typed_choice
from fovexp.results.format import (
    BLANKING_COLUMNS,
    FRAME_COLUMNS,
    GAZE_COLUMNS,
    TRIAL_COLUMNS,
    format_line,
    format_value,
    read_trials_file,
)

__all__ = ["BLANKING_COLUMNS", "FRAME_COLUMNS", "GAZE_COLUMNS", "TRIAL_COLUMNS", "BatchLog",
           "JsonWriter", "PeriodicFlusher", "TrialLog", "format_line", "format_value",
           "TRIAL_HEADERS", "read_trials", "repair_tail", "upgrade_header",
           "write_json_atomic"]

#: the headers a ``trials.csv`` may have: the adjustment task's, the forced-choice task's
TRIAL_HEADERS = (TRIAL_COLUMNS, (*TRIAL_COLUMNS, *FORCED_CHOICE_COLUMNS))


def read_trials(path: Path) -> tuple[list[dict[str, Any]], int]:
    """Rows of a ``trials.csv`` and the byte length of its valid part
    (:func:`fovexp.results.format.read_trials_file`: a torn last row is dropped with a
    warning naming the file; a bad row elsewhere is an error). The header must be exactly one
    of :data:`TRIAL_HEADERS`, since rows are appended in that order; a forced-choice file's
    rows carry its answers too (:func:`fovexp.results.choices.typed_choice`).
    """
    tf = read_trials_file(path)
    if tf.header and tuple(tf.header) not in TRIAL_HEADERS and tf.torn != "torn header":
        raise FovexpError(f"{path}: header does not match docs/LOGS.md "
                          f"({','.join(tf.header)[:80]})")
    if tf.rows and tuple(tf.header) == TRIAL_HEADERS[1]:
        fields = choice_fields(path) or {}
        for row, line in zip(tf.rows, tf.lines, strict=True):
            row.update(typed_choice(fields.get(line, {})))
    return tf.rows, tf.good_len


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


@contextmanager
def _cut_back_on_error(path: Path) -> Iterator[None]:
    """Appends to ``path`` in the block; if they fail (a full disk: part of them may have
    reached the file), the file is cut back to its length before them, and the error goes on."""
    try:
        before = path.stat().st_size
    except FileNotFoundError:
        before = 0
    try:
        yield
    except OSError:
        try:
            os.truncate(path, before)  # frees blocks: needs no space
        except OSError:
            pass
        raise


def _csv_good_length(path: Path) -> int:
    """Length of a batch CSV up to its last complete line (torn tails of gaze/frame logs)."""
    data = path.read_bytes()
    return data.rfind(b"\n") + 1


def upgrade_header(path: Path, columns: Sequence[str]) -> bool:
    """A batch CSV written by an older format version, whose columns are the first of
    ``columns`` (a newer version only appends columns: docs/LOGS.md, "Format versions"), is
    rewritten with the current header and its rows padded with empty fields, in one atomic
    replace; a resumed session then appends rows of the current format to it. Returns whether
    it was rewritten; raises :class:`FovexpError` naming the file when its header is not an
    older version of ``columns``."""
    path = Path(path)
    with open(path, "rb") as fh:
        head = fh.readline()
    header = head.decode("utf-8", "replace").rstrip("\r\n").split(",")
    cols = list(columns)
    if header == cols:
        return False
    if len(header) >= len(cols) or header != cols[: len(header)]:
        raise FovexpError(f"{path}: its columns are not those of docs/LOGS.md "
                          f"({','.join(header)[:80]}): move it aside to resume")
    pad = b"," * (len(cols) - len(header))
    data = path.read_bytes()[len(head):]
    body = b"".join(line + pad + b"\n" for line in data.split(b"\n") if line)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as fh:
        fh.write(format_line(cols).encode() + body)
        fh.flush()
        os.fsync(fh.fileno())
    os.replace(tmp, path)
    return True


class TrialLog:
    """Appends one fsync'ed row per completed trial to ``trials.csv``."""

    def __init__(self, path: Path, columns: Sequence[str] = TRIAL_COLUMNS) -> None:
        self.path = Path(path)
        self.columns = tuple(columns)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        rows, good = read_trials(self.path)
        if self.path.exists():
            repair_tail(self.path, good)
        self.rows = rows
        if good == 0:
            self._write(format_line(self.columns))
        elif read_trials_file(self.path).header != list(self.columns):
            raise FovexpError(f"{self.path}: written by another task (its header is not this "
                              "protocol's): use another --results folder or experiment name")

    def _write(self, line: str) -> None:
        # One write of a whole line, then flush + fsync: at most this line can be torn, and a
        # write that fails (a full disk) is cut back off, so the file stays whole.
        with _cut_back_on_error(self.path):
            with open(self.path, "a", encoding="utf-8", newline="") as fh:
                fh.write(line)
                fh.flush()
                os.fsync(fh.fileno())

    def append(self, row: dict[str, Any]) -> None:
        missing = set(self.columns) - set(row)
        if missing:
            raise KeyError(f"trial row lacks {sorted(missing)}")
        self._write(format_line([row[k] for k in self.columns]))
        self.rows.append(row)


class BatchLog:
    """A CSV written in batches from a memory buffer (gaze samples, frames, blanking episodes).

    ``add`` only appends to a list under a lock; ``flush`` writes what has accumulated. On
    resume an existing file's torn tail is cut off first. ``formatter`` turns what was added
    into a row when it is written, on the flushing thread (the gaze log's eccentricities are
    computed there, not in the frame loop). ``tap``, when set, is also handed what is added, as
    it is added (the live status file's publisher: :mod:`.live`); it must only queue it.
    """

    tap: Callable[[Iterable[Any]], None] | None = None

    def __init__(self, path: Path, columns: Sequence[str],
                 formatter: Callable[[Any], Sequence[Any]] | None = None) -> None:
        self.path = Path(path)
        self.columns = tuple(columns)
        self._formatter = formatter
        self._lock = threading.Lock()
        self._write_lock = threading.Lock()  # one writer at a time, in the order rows came
        self._pending: list[Sequence[Any]] = []
        self.path.parent.mkdir(parents=True, exist_ok=True)
        if self.path.exists() and self.path.stat().st_size > 0:
            repair_tail(self.path, _csv_good_length(self.path))
            if self.path.stat().st_size > 0:
                upgrade_header(self.path, self.columns)
        if not self.path.exists() or self.path.stat().st_size == 0:
            with open(self.path, "w", encoding="utf-8", newline="") as fh:
                fh.write(format_line(self.columns))

    def add(self, row: Sequence[Any]) -> None:
        with self._lock:
            self._pending.append(row)
        if self.tap is not None:
            self.tap((row,))

    def extend(self, rows: Iterable[Sequence[Any]]) -> None:
        if self.tap is not None:
            rows = rows if isinstance(rows, list) else list(rows)
            self.tap(rows)
        with self._lock:
            self._pending.extend(rows)

    def flush(self, sync: bool = False) -> int:
        """Append the pending rows; ``sync`` also fsyncs. A flush waits for one already under
        way (the periodic flusher's), so that when ``flush(sync=True)`` returns every row added
        before it is on disk, in order: the trial row that follows never precedes its samples."""
        with self._write_lock:
            with self._lock:  # held only for the swap: add() from the tracker never waits on disk
                rows, self._pending = self._pending, []
            if not rows and not sync:
                return 0
            fmt = self._formatter
            text = "".join(format_line(fmt(r) if fmt is not None else r) for r in rows)
            try:
                with _cut_back_on_error(self.path):
                    with open(self.path, "a", encoding="utf-8", newline="") as fh:
                        fh.write(text)
                        fh.flush()
                        if sync:
                            os.fsync(fh.fileno())
            except OSError:
                with self._lock:  # not written: pending again, before any added since
                    self._pending[:0] = rows
                raise
            return len(rows)


class PeriodicFlusher:
    """A thread that flushes :class:`BatchLog` objects every ``period_s`` (disk work off the
    frame loop and out of the tracker callback).

    A write that fails (a full disk) leaves its log as it was and its rows pending; the thread
    keeps the first error in :attr:`error` (the session stops on it: no traceback from the
    thread) and tries again each period. :meth:`stop` flushes a last time and keeps a failure
    there too."""

    def __init__(self, logs: Sequence[BatchLog], period_s: float = 0.5) -> None:
        self.logs = list(logs)
        self.period_s = period_s
        self.error: OSError | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="fovexp-log-flusher", daemon=True)

    def start(self) -> PeriodicFlusher:
        self._thread.start()
        return self

    def _flush_all(self, sync: bool) -> None:
        for log in self.logs:
            try:
                log.flush(sync=sync)
            except OSError as exc:
                if self.error is None:
                    self.error = exc

    def _run(self) -> None:
        while not self._stop.wait(self.period_s):
            self._flush_all(sync=False)

    def stop(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=5)
        self._flush_all(sync=True)


def json_text(data: dict[str, Any]) -> str:
    """The session file's text (indented JSON; values JSON lacks, such as paths, as text)."""
    return json.dumps(data, indent=2, sort_keys=False, default=str) + "\n"


def write_json_atomic(path: Path, data: dict[str, Any] | str) -> None:
    """Write JSON (a dict, or :func:`json_text` already made) via a temporary file and
    ``os.replace``, fsync'ed: a reader sees old or new, never half (a write that fails, a
    full disk, leaves the old one and no temporary file)."""
    path = Path(path)
    text = data if isinstance(data, str) else json_text(data)
    tmp = path.with_name(path.name + ".tmp")
    try:
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
    except OSError:
        tmp.unlink(missing_ok=True)
        raise
    os.replace(tmp, path)
    dfd = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(dfd)
    finally:
        os.close(dfd)


class JsonWriter:
    """Writes a session file with :func:`write_json_atomic` on its own thread, so that events
    noticed in the frame loop never wait on a disk (fsync can take tens of ms).

    ``snapshot()`` returns the file's current text (the session serialises its state under its
    own lock). :meth:`request` asks for a write soon, coalescing requests that arrive while one
    is under way (the newest state is what gets written); :meth:`write_now` writes on the
    calling thread (state changes that must be on disk before anything else happens: the
    start, the end, a failure) after any write under way. Every write is whole and atomic, so
    the file is valid JSON whenever a crash comes.
    """

    def __init__(self, path: Path, snapshot: Callable[[], str]) -> None:
        self.path = Path(path)
        self._snapshot = snapshot
        self._write_lock = threading.Lock()
        self._wanted = threading.Event()
        self._stop = False
        self.error: Exception | None = None
        self._thread = threading.Thread(target=self._run, name="fovexp-session-file",
                                        daemon=True)
        self._thread.start()

    def request(self) -> None:
        self._wanted.set()

    def write_now(self) -> None:
        with self._write_lock:
            write_json_atomic(self.path, self._snapshot())

    def _run(self) -> None:
        while True:
            self._wanted.wait()
            self._wanted.clear()
            if self._stop:
                return
            try:
                self.write_now()
            except Exception as exc:  # a full disk: kept, reported by close()
                self.error = exc

    def close(self) -> None:
        """Stop the thread, then write the final state on the caller's thread."""
        self._stop = True
        self._wanted.set()
        self._thread.join(timeout=10)
        self.write_now()
