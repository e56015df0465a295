"""The one definition of the runner's log formats (docs/LOGS.md): columns, types, the
participant-ID rule, CSV formatting, and the ``trials.csv`` reader that detects a torn last row.

Both the runner (:mod:`fovexp.experiment.records.logs`) and the analysis (:mod:`fovexp.analysis`)
use this module. It imports nothing of the runner but the package itself, and no PsychoPy.
"""

from __future__ import annotations

import csv
import datetime as _dt
import io
import math
import re
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fovexp import METHODS, FovexpError

#: ``trials.csv`` columns, in the documented order.
TRIAL_COLUMNS: tuple[str, ...] = (
    "participant", "session", "experiment", "protocol_sha256", "trial_index", "practice",
    "repetition", "image", "blur_rate", "method", "adjusted_parameter", "f_e", "s_k", "s_f",
    "start_value", "final_value", "response_time_s", "wheel_events", "blanked_fraction",
    "dropped_frames", "tracker", "seed", "software_version", "timestamp",
)
STR_COLUMNS = frozenset({
    "participant", "session", "experiment", "protocol_sha256", "image", "method",
    "adjusted_parameter", "tracker", "software_version", "timestamp",
})
INT_COLUMNS = frozenset({"trial_index", "repetition", "wheel_events", "dropped_frames", "seed"})
BOOL_COLUMNS = frozenset({"practice"})
FLOAT_COLUMNS = frozenset({
    "blur_rate", "f_e", "s_k", "s_f", "start_value", "final_value", "response_time_s",
    "blanked_fraction",
})
#: Columns that may not be empty (a row without them is corrupt).
REQUIRED_VALUES: tuple[str, ...] = (
    "participant", "session", "experiment", "protocol_sha256", "trial_index", "practice",
    "image", "blur_rate", "method", "adjusted_parameter", "final_value", "timestamp",
)
ADJUSTABLE: tuple[str, ...] = ("f_e", "s_k", "s_f", "blur_rate")
#: Gaze sources (the ``tracker`` column); the simulated one marks dry runs, never a participant
#: (a dry run through ioHub too). ``iohub``: any ioHub eye tracker (its MouseGaze is ``mouse``).
TRACKERS: tuple[str, ...] = ("tobii", "simulated", "mouse", "iohub")
SIMULATED_TRACKER = "simulated"
#: Mouse gaze: a person, but a pilot (no eye tracker): the analysis and the calibration chain
#: leave pilot sessions out unless asked (``--include-pilots``).
PILOT_TRACKER = "mouse"
#: A participant ID, safe as a folder name.
PARTICIPANT_PATTERN = r"[A-Za-z0-9_-]{1,32}"
#: ``\Z``, not ``$``: ``$`` also matches before a final newline ("P01\n").
PARTICIPANT_RE = re.compile(rf"\A{PARTICIPANT_PATTERN}\Z")
#: Names Windows reserves for devices, whatever the case (a lab's share may be on Windows).
RESERVED_NAMES = frozenset({"con", "prn", "aux", "nul", *(f"com{i}" for i in range(10)),
                            *(f"lpt{i}" for i in range(10))})


def is_participant_id(text: object) -> bool:
    """The participant-ID rule: the pattern, and not a Windows device name such as ``CON``."""
    return (isinstance(text, str) and PARTICIPANT_RE.match(text) is not None
            and text.lower() not in RESERVED_NAMES)
ISO_RE = re.compile(
    r"^\d{4}-\d{2}-\d{2}[T ]\d{2}:\d{2}(:\d{2}(\.\d+)?)?(Z|[+-]\d{2}(:?\d{2})?)?$"
)


def now_iso() -> str:
    """The logs' time stamp (``timestamp``, the session file's times): local time with its
    offset, to the millisecond, as :data:`ISO_RE` reads it."""
    return _dt.datetime.now().astimezone().isoformat(timespec="milliseconds")

#: The gaze log's last columns: each eye's position (the tracker's gaze origin, mm, in the
#: frame of the session's ``display_area``), empty where not measured.
GAZE_ORIGIN_COLUMNS: tuple[str, ...] = (
    "left_origin_x_mm", "left_origin_y_mm", "left_origin_z_mm",
    "right_origin_x_mm", "right_origin_y_mm", "right_origin_z_mm",
)
#: ``gaze-<session>.csv``: one row per tracker sample; times in microseconds; ``attempt`` as in
#: the frame log (empty between trials); ``received_system_time_us``: when the runner had the
#: sample (issue 28; minus ``system_time_us``: the delivery latency); ``true_ecc_deg``: the
#: simulated eye's true eccentricity (dry runs; empty for a real eye). A log written before the
#: last two columns reads with them empty.
GAZE_COLUMNS: tuple[str, ...] = (
    "trial_index", "attempt", "device_time_us", "system_time_us", "left_x", "left_y",
    "left_valid", "right_x", "right_y", "right_valid", "x", "y", "valid", "eccentricity_deg",
    *GAZE_ORIGIN_COLUMNS, "received_system_time_us", "true_ecc_deg",
)
#: ``frames-<session>.csv``: one row per stimulus frame; ``value`` is the adjusted value of the
#: frame actually on screen; ``gaze_system_time_us`` and ``gaze_ecc_deg`` are the newest gaze
#: sample the frame's blanking decision used, ``flip_system_time_us`` the flip and
#: ``decide_system_time_us`` the decision, all on the tracker's system clock (flip minus
#: sample is the gaze-to-flip latency, decision minus sample the sample's age the blanking
#: rule limits, flip minus decision the frame's draw latency).
FRAME_COLUMNS: tuple[str, ...] = (
    "trial_index", "attempt", "frame", "flip_time_s", "interval_s", "dropped", "blanked", "value",
    "gaze_system_time_us", "gaze_ecc_deg", "flip_system_time_us", "decide_system_time_us",
    "attempt_start_system_time_us",
)
#: The frame log's format versions (docs/LOGS.md, "Format versions"), each by its columns: a
#: reader tells them apart by the header, and a newer version only appends columns, so an older
#: log reads with the new columns empty. 1: issue 9 (to ``flip_system_time_us``); 2: issue 18
#: (``decide_system_time_us``); 3: issue 28 (``attempt_start_system_time_us``: when the
#: attempt began, on the tracker's clock, the same in each of its rows).
FRAME_LOG_VERSIONS: dict[int, tuple[str, ...]] = {1: FRAME_COLUMNS[:11], 2: FRAME_COLUMNS[:12],
                                                  3: FRAME_COLUMNS}
FRAME_LOG_VERSION = max(FRAME_LOG_VERSIONS)


def frame_log_version(header: Sequence[str]) -> int | None:
    """The frame-log version whose columns ``header`` has (a log written before version 1
    lacks the latency columns: 0); None when it is none of them."""
    cols = tuple(header)
    for version, columns in sorted(FRAME_LOG_VERSIONS.items(), reverse=True):
        if cols == columns:
            return version
    if cols == FRAME_COLUMNS[:8]:
        return 0
    return None


#: ``blanking-<session>.csv``: one row per blanking episode.
BLANKING_COLUMNS: tuple[str, ...] = (
    "trial_index", "attempt", "start_s", "end_s", "frames", "reason",
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


def parse_value(column: str, text: str) -> Any:
    """One ``trials.csv`` field, typed (None when empty); ValueError with a short reason."""
    text = text.strip()
    if text == "":
        if column in REQUIRED_VALUES:
            raise ValueError("is empty but required")
        return None
    if column in FLOAT_COLUMNS:
        try:
            value = float(text)
        except ValueError:
            raise ValueError("is not a number") from None
        if not math.isfinite(value):
            raise ValueError("is not a finite number")
        return value
    if column in INT_COLUMNS:
        try:
            return int(text)
        except ValueError:
            raise ValueError("is not an integer") from None
    if column in BOOL_COLUMNS:
        low = text.lower()
        if low in ("1", "true"):
            return True
        if low in ("0", "false"):
            return False
        raise ValueError("is not 0 or 1")
    if column == "participant" and not is_participant_id(text):
        raise ValueError(f"is not a valid participant ID ({PARTICIPANT_PATTERN})")
    if column == "method" and text not in METHODS:
        raise ValueError(f"is not a method ({', '.join(sorted(METHODS))})")
    if column == "adjusted_parameter" and text not in ADJUSTABLE:
        raise ValueError(f"is not an adjustable parameter ({', '.join(sorted(ADJUSTABLE))})")
    if column == "timestamp" and not ISO_RE.match(text):
        raise ValueError("is not an ISO 8601 time")
    return text


@dataclass
class TrialsFile:
    """A parsed ``trials.csv`` (see :func:`read_trials_file`)."""

    path: Path
    header: list[str]
    #: typed rows, the documented columns only
    rows: list[dict[str, Any]] = field(default_factory=list)
    #: the file's line number (from 1) of each row
    lines: list[int] = field(default_factory=list)
    #: bytes of the valid part (header and complete rows): a resumed run cuts the file there
    good_len: int = 0
    #: why the last row was dropped, and its line (None: nothing dropped)
    torn: str | None = None
    torn_line: int | None = None
    #: documented columns missing from the header (then no row is read)
    missing: list[str] = field(default_factory=list)
    extra: list[str] = field(default_factory=list)
    #: rows left out by a lenient read (``strict=False``): (line, problem)
    skipped: list[tuple[int, str]] = field(default_factory=list)


def read_trials_file(path: str | Path, strict: bool = True) -> TrialsFile:
    """Read a ``trials.csv``: typed rows, a torn last row dropped with a warning naming the file.

    The last row counts as torn (an interrupted write: the runner writes each row in one
    fsync'ed write ending in a newline) when it lacks its final newline, has the wrong field
    count or an unparsable value. Any other bad row raises :class:`FovexpError` naming the file
    and line: the file is damaged and nothing is guessed. A header lacking a documented column
    gives ``missing`` and no rows. Blank lines are skipped.

    ``strict=False`` (a live view of a file being written, ``fovexp monitor``) raises and warns
    for nothing: every bad row, the last or another, is left out and listed in ``skipped``.
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        return TrialsFile(path, [])
    except OSError as exc:
        raise FovexpError(f"{path}: cannot read: {exc.strerror}") from None
    raw_lines = data.split(b"\n")
    tail_complete = raw_lines[-1] == b""  # after a final newline split() leaves b""
    if tail_complete:
        raw_lines = raw_lines[:-1]
    if not raw_lines or not data.strip():
        return TrialsFile(path, [])

    def decode(raw: bytes, line: int) -> str:
        try:
            return raw.decode("utf-8").rstrip("\r")
        except UnicodeDecodeError as exc:
            raise ValueError(f"not UTF-8 text (byte {exc.start})") from None

    try:
        head_text = decode(raw_lines[0].removeprefix(b"\xef\xbb\xbf"), 1)
    except ValueError as exc:
        if not strict:
            return TrialsFile(path, [], skipped=[(1, f"header: {exc}")])
        raise FovexpError(f"{path}: line 1: {exc}") from None
    header = [h.strip() for h in next(csv.reader([head_text]), [])]
    out = TrialsFile(path, header)
    out.missing = [c for c in TRIAL_COLUMNS if c not in header]
    out.extra = [h for h in header if h not in TRIAL_COLUMNS]
    if out.missing:
        if len(raw_lines) == 1 and not tail_complete:
            out.torn, out.torn_line = "torn header", 1
            if strict:
                warnings.warn(f"{path}: line 1: torn header dropped", stacklevel=2)
            out.missing = []
        return out
    index = {c: header.index(c) for c in TRIAL_COLUMNS}
    out.good_len = len(raw_lines[0]) + 1
    body = [(i, raw) for i, raw in enumerate(raw_lines[1:], start=2)]
    last_nonblank = max((i for i, raw in body if raw.strip()), default=None)
    for i, raw in body:
        if not raw.strip():
            if i < len(raw_lines) or tail_complete:
                out.good_len += len(raw) + 1
            continue
        last = i == last_nonblank
        problem = None
        row: dict[str, Any] = {}
        try:
            fields = next(csv.reader([decode(raw, i)]), [])
        except (ValueError, csv.Error) as exc:
            problem, fields = str(exc), []
        if problem is None and last and i == len(raw_lines) and not tail_complete:
            problem = "no final newline"
        elif problem is None and len(fields) != len(header):
            problem = f"{len(fields)} fields, expected {len(header)}"
        elif problem is None:
            for col in TRIAL_COLUMNS:
                value = fields[index[col]]
                try:
                    row[col] = parse_value(col, value)
                except ValueError as exc:
                    problem = f"column {col}: {value.strip()!r} {exc}"
                    break
        if problem is not None:
            if not strict:
                out.skipped.append((i, problem))
                continue
            if last:
                out.torn, out.torn_line = problem, i
                warnings.warn(f"{path}: line {i}: torn last row dropped ({problem})",
                              stacklevel=2)
                break
            raise FovexpError(f"{path}: line {i}: {problem}")
        out.rows.append(row)
        out.lines.append(i)
        out.good_len += len(raw) + 1
    return out
