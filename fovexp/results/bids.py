"""A BIDS dataset written by ``fovexp export bids`` (docs/SHARING.md), as a source of the
same logs as a results folder.

One definition of where each log goes in the dataset, shared by the writer
(:mod:`fovexp.export.bids`) and the reader here: the trials as ``_events.tsv`` (every
``trials.csv`` column, after BIDS's ``onset``, ``duration`` and ``trial_type``), the gaze log
as one ``_recording-eye1_physio.tsv.gz`` (left eye, and the columns both eyes share) and one
``_recording-eye2_physio.tsv.gz`` (right eye), the frame log and the blanking episodes as the
left eye's ``_physioevents.tsv.gz``, the session file under ``sourcedata/fovexp/``. Every value
is carried as the text the runner wrote (an empty field as BIDS's ``n/a``), so that reading
the dataset back gives the logs value for value.

:func:`read_bids` writes the logs back into a results folder of the usual layout
(``<experiment>/<participant>/trials.csv`` and the session's files), which
:func:`fovexp.results.loading.load_results` then reads as any other: the analysis does not
know where its tables came from. Files changed after the export (their sha256 against the
export's ``sourcedata/fovexp/sha256sums.txt``) are reported, one line each.
"""

from __future__ import annotations

import atexit
import csv
import gzip
import hashlib
import io
import json
import operator
import re
import shutil
import tempfile
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from fovexp import FovexpError

#: The BIDS version the export writes (eye tracking, BEP020, is in the standard since 1.11.0).
BIDS_VERSION = "1.11.0"
#: ``GeneratedBy[0].Name`` of a dataset fovexp wrote: how the reader knows it can read it back.
GENERATOR = "fovexp"
#: BIDS's missing value; the runner's logs leave the field empty.
NA = "n/a"
#: Where the export keeps what the standard has no place for, and its checksums.
SOURCE_FOLDER = "sourcedata/fovexp"
CHECKSUMS = f"{SOURCE_FOLDER}/sha256sums.txt"
#: Columns the events file puts before the ``trials.csv`` columns.
EVENT_COLUMNS: tuple[str, ...] = ("onset", "duration", "trial_type")
#: The physio files' first three columns (BEP020's names) and the gaze-log columns they hold.
EYE_COLUMNS: dict[str, dict[str, str]] = {
    "eye1": {"timestamp": "system_time_us", "x_coordinate": "left_x",
             "y_coordinate": "left_y"},
    "eye2": {"timestamp": "system_time_us", "x_coordinate": "right_x",
             "y_coordinate": "right_y"},
}
#: The physioevents file's first columns (BEP020); the frame log's and the blanking log's
#: columns follow, then ``log_row`` (the row's place in its log).
PHYSIOEVENT_COLUMNS: tuple[str, ...] = ("onset", "duration", "trial_type", "message")
FRAME_EVENT = "frame"
BLANKING_EVENT = "blanking"


def label(text: str) -> str:
    """A BIDS label (letters and digits only) for a participant ID or an experiment name."""
    return re.sub(r"[^A-Za-z0-9]", "", text)


def eye_columns(eye: str, gaze_header: Sequence[str]) -> list[str]:
    """The gaze-log columns a physio file holds, in its order: the three standard ones, then
    this eye's own (``left_*``/``right_*``), then, in ``eye1`` only, those both eyes share."""
    side = "left_" if eye == "eye1" else "right_"
    std = list(EYE_COLUMNS[eye].values())
    own = [c for c in gaze_header if c.startswith(side) and c not in std]
    shared = ([] if eye == "eye2" else
              [c for c in gaze_header if not c.startswith(("left_", "right_")) and c not in std])
    return [*std, *own, *shared]


def tsv_field(text: str) -> str:
    """A log's field as a TSV field: BIDS's ``n/a`` for an empty one."""
    if "\t" in text or "\n" in text or text == NA:
        raise FovexpError(f"the value {text!r} cannot be carried in a TSV file")
    return text if text != "" else NA


def log_field(text: str) -> str:
    return "" if text == NA else text


def write_gzip(path: Path, text: str) -> None:
    """Gzip with no time stamp and no file name in its header: the same text, the same bytes
    (BIDS's validator warns of a time stamp: GZIP_HEADER_MTIME). Level 4, not gzip's 9 nor
    zlib's 6: on a dry run's gaze samples half the time of level 6 for a file 3 % larger
    (level 1: a fifth of the time, 11 % larger)."""
    buf = io.BytesIO()
    with gzip.GzipFile(filename="", mode="wb", fileobj=buf, mtime=0, compresslevel=4) as fh:
        fh.write(text.encode("utf-8"))
    path.write_bytes(buf.getvalue())


def read_log(path: Path) -> pd.DataFrame:
    """A batch log (gaze, frames, blanking) as text, column by column, an empty field as NaN:
    complete lines only (a torn last line is dropped, as the analysis drops it). A large log's
    columns are carried whole (pandas), not value by value. Raises :class:`FovexpError` for a
    log a TSV file cannot carry unchanged (a tab, a quote, a carriage return, ``n/a``)."""
    data = path.read_bytes()
    data = data[: data.rfind(b"\n") + 1]
    if not data.strip():
        raise FovexpError(f"{path}: empty")
    for bad, what in ((b"\t", "a tab"), (b'"', "a quote"), (b"\r", "a carriage return"),
                      (NA.encode(), repr(NA))):
        if bad in data:
            raise FovexpError(f"{path}: holds {what}, which a TSV file cannot carry unchanged")
    return pd.read_csv(io.BytesIO(data), dtype=str, keep_default_na=False, na_values=[""])


def to_tsv(frame: pd.DataFrame) -> str:
    """Rows without a header, tab-separated, an empty (NaN) field as ``n/a``."""
    if frame.empty:
        return ""
    return frame.to_csv(sep="\t", header=False, index=False, lineterminator="\n",
                        quoting=csv.QUOTE_NONE, na_rep=NA)


def gaze_text(path: Path) -> tuple[list[str], list[str]]:
    """A gaze log's header and its complete lines, as text, an empty field as ``n/a`` (a torn
    last line is dropped, as the analysis drops it). The gaze log is a study's largest file
    (600 samples a second): it is carried line by line with str's own methods, not parsed.
    Raises :class:`FovexpError` for a log a TSV file cannot carry unchanged."""
    data = path.read_bytes()
    data = data[: data.rfind(b"\n") + 1]
    for bad, what in ((b"\t", "a tab"), (b'"', "a quote"), (b"\r", "a carriage return"),
                      (NA.encode(), repr(NA))):
        if bad in data:
            raise FovexpError(f"{path}: holds {what}, which a TSV file cannot carry unchanged")
    text = data.decode("utf-8")
    if not text:
        raise FovexpError(f"{path}: empty")
    # Every empty field as n/a, over the whole text at once (an empty field lies between two
    # commas, or a comma and a line's end or start); the regular expression that says the same
    # takes five times as long.
    text = "\n" + text
    for empty, filled in ((",,", f",{NA},"), (",,", f",{NA},"), (",\n", f",{NA}\n"),
                          ("\n,", f"\n{NA},")):
        text = text.replace(empty, filled)
    lines = text[1:].split("\n")[:-1]
    commas = lines[0].count(",")
    for k, ln in enumerate(lines):
        if ln.count(",") != commas:
            raise FovexpError(f"{path}: line {k + 1} has {ln.count(',') + 1} fields, "
                              f"expected {commas + 1}")
    return lines[0].split(","), lines[1:]


def gaze_to_tsv(header: Sequence[str], lines: Sequence[str], columns: Sequence[str]) -> str:
    """The ``columns`` of a gaze log's ``lines`` (:func:`gaze_text`'s) as headerless TSV."""
    pick = operator.itemgetter(*[list(header).index(c) for c in columns])
    return "".join("\t".join(pick(ln.split(","))) + "\n" for ln in lines)


def gaze_from_tsv(eye1: Path, eye2: Path, header: Sequence[str]) -> str:
    """The gaze log's text from its two physio files (:func:`eye_columns` says which columns
    each holds)."""
    texts = [gzip.decompress(p.read_bytes()).decode("utf-8").replace(NA, "").split("\n")[:-1]
             for p in (eye1, eye2)]
    if len(texts[0]) != len(texts[1]):
        raise ValueError("the two eyes' physio files have different numbers of samples")
    both = eye_columns("eye1", header) + eye_columns("eye2", header)
    pick = operator.itemgetter(*[both.index(c) for c in header])
    rows = (",".join(pick(a.split("\t") + b.split("\t")))
            for a, b in zip(texts[0], texts[1], strict=True))
    return ",".join(header) + "\n" + "".join(r + "\n" for r in rows)


def from_tsv(path: Path, columns: Sequence[str]) -> pd.DataFrame:
    """A headerless (gzipped) TSV file written by :func:`to_tsv`, as text, ``n/a`` NaN."""
    data = gzip.decompress(path.read_bytes()) if path.suffix == ".gz" else path.read_bytes()
    if not data.strip():
        return pd.DataFrame(columns=list(columns), dtype=str)
    return pd.read_csv(io.BytesIO(data), sep="\t", header=None, names=list(columns),
                       dtype=str, keep_default_na=False, na_values=[NA],
                       quoting=csv.QUOTE_NONE)


def log_text(frame: pd.DataFrame) -> str:
    """A log's text as the runner writes it (csv, a header, ``\\n`` line ends)."""
    return frame.to_csv(index=False, lineterminator="\n", na_rep="")


def read_tsv(path: Path, header: bool = True) -> tuple[list[str], list[list[str]]]:
    """A TSV file (gzipped when its name ends in .gz): its header (empty without) and rows."""
    data = gzip.decompress(path.read_bytes()) if path.suffix == ".gz" else path.read_bytes()
    lines = data.decode("utf-8").split("\n")
    if lines and lines[-1] == "":
        lines.pop()
    rows = [ln.split("\t") for ln in lines]
    if header:
        return (rows[0] if rows else []), rows[1:]
    return [], rows


def csv_text(header: Sequence[str], rows: Iterable[Sequence[str]]) -> str:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(header)
    writer.writerows(rows)
    return buf.getvalue()


def sha256_file(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def is_fovexp_bids(root: Path) -> bool:
    """Whether ``root`` is a BIDS dataset written by fovexp (its dataset_description.json
    names fovexp first in ``GeneratedBy``)."""
    path = Path(root) / "dataset_description.json"
    if not path.is_file():
        return False
    try:
        desc = json.loads(path.read_text())
        return desc["GeneratedBy"][0]["Name"] == GENERATOR
    except (OSError, ValueError, KeyError, IndexError, TypeError):
        return False


@dataclass
class BidsSource:
    """A fovexp BIDS dataset read back into a results folder (``results``, a temporary folder
    removed when the process ends) and what was found changed since the export."""

    dataset: Path
    results: Path
    changed: list[str] = field(default_factory=list)


def check_sums(root: Path) -> list[str]:
    """One line per file changed, missing or added since the export (against
    ``sourcedata/fovexp/sha256sums.txt``)."""
    path = root / CHECKSUMS
    if not path.is_file():
        return [f"{root}: no {CHECKSUMS}: changes since the export cannot be checked"]
    out = []
    listed: set[str] = set()
    for line in path.read_text().splitlines():
        digest, _, name = line.partition("  ")
        listed.add(name)
        file = root / name
        if not file.is_file():
            out.append(f"{name}: missing (the export wrote it)")
        elif sha256_file(file) != digest:
            out.append(f"{name}: changed since the export (sha256 differs)")
    for file in sorted(root.glob("sub-*/**/*")):
        name = file.relative_to(root).as_posix()
        if file.is_file() and name not in listed:
            out.append(f"{name}: added since the export")
    return out


def _run_files(beh: Path) -> dict[str, Path]:
    """The events files of a participant's ``beh/`` folder by their name's prefix."""
    return {p.name[: -len("_events.tsv")]: p for p in sorted(beh.glob("*_events.tsv"))}


def read_bids(root: str | Path, into: Path | None = None) -> BidsSource:
    """Write the logs of the fovexp BIDS dataset ``root`` back into a results folder
    (``into``, else a temporary folder removed at exit). Raises :class:`FovexpError` when
    ``root`` is not one, or a file of it cannot be read."""
    root = Path(root)
    if not is_fovexp_bids(root):
        raise FovexpError(f"{root}: not a BIDS dataset written by fovexp "
                          "(dataset_description.json's GeneratedBy does not name fovexp)")
    if into is None:
        into = Path(tempfile.mkdtemp(prefix="fovexp-bids-"))
        atexit.register(shutil.rmtree, into, True)
    source = BidsSource(dataset=root, results=into, changed=check_sums(root))
    trials: dict[Path, list[str]] = {}
    headers: dict[Path, list[str]] = {}
    for beh in sorted(root.glob("sub-*/beh")):
        for prefix, events_path in _run_files(beh).items():
            try:
                _read_run(root, beh, prefix, events_path, into, trials, headers)
            except (OSError, ValueError, KeyError, IndexError) as exc:
                raise FovexpError(f"{events_path}: cannot be read back ({exc})") from None
    for path, rows in trials.items():
        path.write_text(csv_text(headers[path], []) + "".join(rows))
    return source


def _read_run(root: Path, beh: Path, prefix: str, events_path: Path, into: Path,
              trials: dict[Path, list[str]], headers: dict[Path, list[str]]) -> None:
    sub = beh.parent.name
    record_path = root / SOURCE_FOLDER / sub / f"{prefix}_session.json"
    info = json.loads(record_path.read_text())
    experiment, participant, session = info["experiment"], info["participant"], info["session"]
    folder = into / experiment / participant
    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"session-{session}.json").write_text(json.dumps(info, indent=1))
    header, rows = read_tsv(events_path)
    columns = header[len(EVENT_COLUMNS):]
    path = folder / "trials.csv"
    if path in headers and headers[path] != columns:
        raise ValueError(f"its columns differ from the earlier run's of {participant}")
    headers[path] = columns
    body = csv_text(columns, ([log_field(v) for v in r[len(EVENT_COLUMNS):]] for r in rows))
    trials.setdefault(path, []).append(body.split("\n", 1)[1])
    # The gaze log: the two eyes' files side by side, in the log's own column order.
    meta = json.loads((beh / f"{prefix}_recording-eye1_physio.json").read_text())
    gaze_header = meta["fovexp"]["log_columns"]
    (folder / f"gaze-{session}.csv").write_text(gaze_from_tsv(
        beh / f"{prefix}_recording-eye1_physio.tsv.gz",
        beh / f"{prefix}_recording-eye2_physio.tsv.gz", gaze_header))
    # The frame log and the blanking episodes, from the left eye's physioevents.
    ev_meta = json.loads((beh / f"{prefix}_recording-eye1_physioevents.json").read_text())
    events = from_tsv(beh / f"{prefix}_recording-eye1_physioevents.tsv.gz", ev_meta["Columns"])
    for kind, name in ((FRAME_EVENT, "frames"), (BLANKING_EVENT, "blanking")):
        cols = ev_meta["fovexp"][f"{name}_columns"]
        if cols is None:  # the session wrote no such log
            continue
        rows = events[events["trial_type"] == kind]
        rows = rows.iloc[rows["log_row"].astype(int).argsort(kind="stable")]
        (folder / f"{name}-{session}.csv").write_text(log_text(rows[cols]))


def _d(description: str, units: str | None = None, **extra: object) -> dict[str, object]:
    out: dict[str, object] = {"Description": description}
    if units:
        out["Units"] = units
    out.update(extra)
    return out


#: Every log column as BIDS describes a column (docs/LOGS.md says the same at more length).
COLUMN_DESCRIPTIONS: dict[str, dict[str, object]] = {
    # trials.csv
    "participant": _d("participant ID as the runner logged it (the sub- label without its "
                      "'_' and '-')"),
    "session": _d("session ID (YYYYmmdd-HHMMSS, the start; shifted with --shift-dates)"),
    "experiment": _d("the protocol's experiment name"),
    "protocol_sha256": _d("sha256 of the protocol file the session ran"),
    "trial_index": _d("position in the session's randomised order, from 0"),
    "practice": _d("1 for a practice trial (left out of the analysis)",
                   Levels={"0": "trial", "1": "practice"}),
    "repetition": _d("repetition of the condition, from 0"),
    "image": _d("stimulus id (stimuli/stimuli.json)"),
    "blur_rate": _d("foveation blur-rate; in a validation trial the adjusted value",
                    "arcmin/deg"),
    "method": _d("rendering method", Levels={"foveated": "foveated rendering alone",
                                             "contrast": "contrast enhancement (Patney 2016)",
                                             "ours": "noise-based enhancement"}),
    "adjusted_parameter": _d("the parameter the participant adjusted with the wheel"),
    "f_e": _d("contrast enhancement factor in effect", "1"),
    "s_k": _d("noise amplitude scale in effect", "1"),
    "s_f": _d("noise frequency scale in effect", "1"),
    "start_value": _d("the adjusted parameter's value at the trial's start"),
    "final_value": _d("the adjusted parameter's value on screen when Enter went down"),
    "response_time_s": _d("first stimulus frame's flip to the press of Enter", "s"),
    "wheel_events": _d("wheel notches turned"),
    "blanked_fraction": _d("fraction of the trial's time the screen was black by the gaze "
                           "check", "1"),
    "dropped_frames": _d("frames whose interval exceeded 1.5 refresh periods"),
    "tracker": _d("gaze source", Levels={
        "tobii": "a Tobii Pro eye tracker", "iohub": "an eye tracker through ioHub",
        "simulated": "dry run: a simulated participant, not a person",
        "mouse": "pilot: mouse gaze, no eye tracker"}),
    "seed": _d("noise and order seed"),
    "software_version": _d("fovexp version that ran the trial"),
    "timestamp": _d("ISO 8601 time of the trial's end (shifted with --shift-dates)"),
    # gaze-<session>.csv
    "attempt": _d("the trial's attempt (0, then 1, 2 ... when restarted); n/a between trials"),
    "device_time_us": _d("the tracker's own time stamp", "us"),
    "system_time_us": _d("the sample's time on the tracker's system clock (the clock of the "
                         "frame log)", "us"),
    "left_x": _d("left eye's gaze, fraction of the screen's width from its left edge", "1"),
    "left_y": _d("left eye's gaze, fraction of the screen's height from its top edge", "1"),
    "left_valid": _d("1 when the left eye's gaze is valid"),
    "right_x": _d("right eye's gaze, fraction of the screen's width from its left edge", "1"),
    "right_y": _d("right eye's gaze, fraction of the screen's height from its top edge", "1"),
    "right_valid": _d("1 when the right eye's gaze is valid"),
    "x": _d("binocular gaze point (mean of the valid eyes), fraction of the screen's width",
            "1"),
    "y": _d("binocular gaze point, fraction of the screen's height from its top edge", "1"),
    "valid": _d("1 when the binocular point is valid"),
    "eccentricity_deg": _d("binocular point's angle from the fixation cross", "deg"),
    **{f"{eye}_origin_{axis}_mm": _d(
        f"{eye} eye's position (gaze origin), {axis}, in the frame of the session record's "
        "display_area", "mm") for eye in ("left", "right") for axis in "xyz"},
    "received_system_time_us": _d("when the runner had the sample, on the system clock", "us"),
    "true_ecc_deg": _d("a simulated eye's true angle from the cross (dry runs only)", "deg"),
    # frames-<session>.csv
    "frame": _d("frame number within the attempt"),
    "flip_time_s": _d("flip time on the runner's monotonic clock", "s"),
    "interval_s": _d("time since the attempt's previous frame", "s"),
    "dropped": _d("1 when the interval exceeded 1.5 refresh periods"),
    "blanked": _d("1 when the frame was black (gaze check)"),
    "value": _d("the adjusted value of the render shown in this frame"),
    "gaze_system_time_us": _d("the gaze sample the frame's blanking decision used", "us"),
    "gaze_ecc_deg": _d("that sample's angle from the cross", "deg"),
    "flip_system_time_us": _d("the flip on the tracker's system clock", "us"),
    "decide_system_time_us": _d("when the frame's blanking decision was made", "us"),
    "attempt_start_system_time_us": _d("when the attempt began", "us"),
    # blanking-<session>.csv
    "start_s": _d("episode's start from the attempt's first frame", "s"),
    "end_s": _d("episode's end from the attempt's first frame", "s"),
    "frames": _d("black frames in the episode"),
    "reason": _d("why the screen was black", Levels={
        "outside": "gaze more than the blanking radius from the cross",
        "invalid": "no eye valid", "lost": "no sample newer than the gaze timeout"}),
    # the forced-choice task's columns after the documented ones (fovexp.results.choices)
    "task": _d("the task: 2afc for a forced choice (the adjustment task writes no such "
               "column)"),
    "degraded_side": _d("the screen half that showed the method", Levels={
        "left": "left half", "right": "right half"}),
    "answer": _d("the half the participant chose", Levels={
        "left": "left half", "right": "right half"}),
    "correct": _d("1 when the chosen half was the degraded one"),
    "presentation_s": _d("the stimulus' time on screen", "s"),
    "procedure": _d("how the blur-rate was chosen (questplus or constant)"),
    "grid_index": _d("the blur-rate's index on the procedure's grid"),
    # added by the export
    "log_row": _d("the row's place in its log (frames-<session>.csv or "
                  "blanking-<session>.csv), from 0"),
}
