"""``fovexp export bids RESULTS OUT``: a results folder as a BIDS 1.11 dataset (docs/SHARING.md).

Where each log goes is defined once, in :mod:`fovexp.results.bids`, which also reads the dataset
back for ``fovexp analyze``. What this module adds: choosing the sessions (dry runs and pilots
left out unless asked; a session that cannot be exported left out with one line saying why,
also written into the dataset's README), the sidecars (the display profile as the events'
``StimulusPresentation``, the tracker and its calibration in the physio sidecars), the
participants' table from the forms, the stimuli, the analysis under ``derivatives/fovexp/``,
and the same bytes for the same results (sorted everywhere, gzip without a time stamp, the
report's generation time left out).
"""

from __future__ import annotations

import argparse
import csv
import datetime as dt
import json
import re
import shutil
import subprocess
import sys
import tempfile
import warnings
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from fovexp import FovexpError, __version__
from fovexp.results.bids import (
    BIDS_VERSION,
    BLANKING_EVENT,
    CHECKSUMS,
    COLUMN_DESCRIPTIONS,
    EVENT_COLUMNS,
    EYE_COLUMNS,
    FRAME_EVENT,
    GENERATOR,
    NA,
    PHYSIOEVENT_COLUMNS,
    SOURCE_FOLDER,
    eye_columns,
    gaze_text,
    gaze_to_tsv,
    label,
    read_bids,
    read_log,
    sha256_file,
    to_tsv,
    tsv_field,
    write_gzip,
)
from fovexp.results.format import (
    PILOT_TRACKER,
    SIMULATED_TRACKER,
    frame_log_version,
    read_trials_file,
)

#: The paper the dataset's experiments reproduce (dataset_description.json).
PAPER = ("Tariq T, Tursun C, Didyk P (2022). Noise-based enhancement for foveated rendering. "
         "ACM Transactions on Graphics 41(4):143. doi:10.1145/3528223.3530101")
PAPER_DOI = "doi:10.1145/3528223.3530101"
#: The words the analysis report uses for the data that are not a person's measurements.
DRY_RUN_WORDS = "dry run: a simulated participant, not a person"
PILOT_WORDS = "pilot: mouse gaze, no eye tracker"
VALIDATOR = "bids-validator-deno"
_SESSION_ID = re.compile(r"(?<!\d)(\d{8})-(\d{6})(?!\d)")
_ISO_DATE = re.compile(r"(?<!\d)\d{4}-\d{2}-\d{2}(?!\d)")


@dataclass
class ExportReport:
    """What an export wrote and left out."""

    out: Path
    sessions: int = 0
    participants: list[str] = field(default_factory=list)
    #: one line per session or participant left out, with the reason
    left_out: list[str] = field(default_factory=list)
    #: the analysis' Table 2 and tests under derivatives/fovexp/ (or why not)
    analysis: str = ""


@dataclass
class _Session:
    experiment: str
    participant: str
    session: str
    folder: Path
    header: list[str]
    rows: list[list[str]]  # trials.csv fields as written
    tracker: str
    info: dict[str, Any] = field(default_factory=dict)
    prefix: str = ""


# ------------------------------------------------------------------------------- the choice
def _raw_rows(path: Path, lines: Sequence[int]) -> list[list[str]]:
    """The fields, as written, of the rows at ``lines`` (the strict reader's line numbers)."""
    raw = path.read_bytes().split(b"\n")
    return [next(csv.reader([raw[i - 1].decode("utf-8").rstrip("\r")])) for i in lines]


def _torn_session(path: Path, header: Sequence[str], line: int | None,
                  rows: Sequence[dict[str, Any]]) -> str | None:
    """The session of a torn last row: its own session field where the write got that far
    (a resumed session's first row), else the session of the row before it."""
    raw = path.read_bytes().split(b"\n")
    if line is not None and "session" in header:
        fields = next(csv.reader([raw[line - 1].decode("utf-8", "replace")]), [])
        k = list(header).index("session")
        if len(fields) > k + 1 and fields[k]:  # the field is complete: another follows it
            return fields[k]
    return rows[-1]["session"] if rows else None


def _sessions(results: Path, experiments: set[str], participants: set[str],
              include_dry_runs: bool, include_pilots: bool,
              left_out: list[str]) -> list[_Session]:
    files = sorted(results.rglob("trials.csv"))
    if not files:
        raise FovexpError(f"{results}: no trials.csv found (expected "
                          "<experiment>/<participant>/trials.csv)")
    out: list[_Session] = []
    for path in files:
        where = path.parent.relative_to(results).as_posix() if path.parent != results else "."
        try:
            with warnings.catch_warnings():  # a torn last row: said below, in the left-out line
                warnings.simplefilter("ignore")
                tf = read_trials_file(path)
        except FovexpError as exc:
            left_out.append(f"{where}: {exc} (the file is damaged)")
            continue
        if tf.missing:
            left_out.append(f"{where}: trials.csv lacks {', '.join(tf.missing)} (an older "
                            "log version)")
            continue
        if not tf.rows:
            left_out.append(f"{where}: participant with no completed trial")
            continue
        rows = _raw_rows(path, tf.lines)
        by_session: dict[str, list[int]] = {}
        for k, r in enumerate(tf.rows):
            by_session.setdefault(r["session"], []).append(k)
        torn = _torn_session(path, tf.header, tf.torn_line, tf.rows) if tf.torn else None
        for sid, idx in by_session.items():
            first = tf.rows[idx[0]]
            exp, pid, tracker = first["experiment"], first["participant"], first["tracker"]
            if experiments and exp not in experiments or participants and pid not in participants:
                continue
            if tracker == SIMULATED_TRACKER and not include_dry_runs:
                continue
            if tracker == PILOT_TRACKER and not include_pilots:
                continue
            name = f"{exp}/{pid} session {sid}"
            if sid == torn:
                left_out.append(f"{name}: torn session (line {tf.torn_line} of trials.csv is an "
                                "interrupted write)")
                continue
            out.append(_Session(exp, pid, sid, path.parent, list(tf.header),
                                [rows[k] for k in idx], tracker))
    return out


# ------------------------------------------------------------------------------- privacy
def _shift_text(text: str, days: int) -> str:
    """``text`` with every date in it moved ``days`` back: ISO dates (``2026-11-27``, the time
    stamps) and session IDs (``20261127-163738``, also inside a file name)."""
    if not days:
        return text

    def session(m: re.Match[str]) -> str:
        try:
            d = dt.datetime.strptime(m.group(1), "%Y%m%d") - dt.timedelta(days=days)
        except ValueError:
            return m.group(0)
        return f"{d:%Y%m%d}-{m.group(2)}"

    def iso(m: re.Match[str]) -> str:
        try:
            d = dt.date.fromisoformat(m.group(0)) - dt.timedelta(days=days)
        except ValueError:
            return m.group(0)
        return d.isoformat()

    return _ISO_DATE.sub(iso, _SESSION_ID.sub(session, text))


def _clean(value: Any, days: int) -> Any:
    """A session record without local paths (a user name in a path) and with shifted dates."""
    if isinstance(value, dict):
        return {k: _clean(v, days) for k, v in value.items()}
    if isinstance(value, list):
        return [_clean(v, days) for v in value]
    if isinstance(value, str):
        if value.startswith("/") or re.match(r"\A[A-Za-z]:[\\/]", value):
            return re.split(r"[\\/]", value)[-1]
        return _shift_text(value, days)
    return value


# ------------------------------------------------------------------------------- writing
def _json(path: Path, data: Any) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=2, ensure_ascii=False) + "\n")


def _tsv(rows: Iterable[Sequence[str]]) -> str:
    return "".join("\t".join(r) + "\n" for r in rows)


def _us(value: str | float) -> int:
    return int(round(float(value)))


def _seconds(us: float) -> str:
    return f"{us / 1e6:.6f}"


def _describe(columns: Sequence[str]) -> dict[str, Any]:
    return {c: COLUMN_DESCRIPTIONS[c] for c in columns if c in COLUMN_DESCRIPTIONS}


def _stimulus_presentation(info: dict[str, Any]) -> dict[str, Any]:
    d = info.get("display") or {}
    out = {
        "OperatingSystem": str((info.get("versions") or {}).get("platform", NA)),
        "SoftwareName": "fovexp (PsychoPy)",
        "SoftwareVersion": str(info.get("software_version", __version__)),
        "ScreenDistance": float(d["distance_cm"]) / 100,
        "ScreenOrigin": ["top", "left"],
        "ScreenResolution": [int(d["width_px"]), int(d["height_px"])],
        "ScreenSize": [float(d["width_cm"]) / 100, float(d["height_cm"]) / 100],
        "HeadStabilization": "none recorded",
    }
    if d.get("refresh_hz"):
        out["ScreenRefreshRate"] = float(d["refresh_hz"])
    return out


def _calibration(info: dict[str, Any]) -> dict[str, Any]:
    """BEP020's calibration keys from the session's tracker quality records (accuracy in deg,
    the worse eye's)."""
    quality = [q for q in info.get("tracker_quality") or [] if isinstance(q, dict)]
    out: dict[str, Any] = {"CalibrationCount": len(quality)}
    accepted = [q for q in quality if q.get("accepted")] or quality
    if accepted:
        last = accepted[-1]
        val = last.get("validation") or {}
        eyes: list[dict[str, Any]] = [val[e] for e in ("left", "right")
                                      if isinstance(val.get(e), dict)]
        acc = [float(e["accuracy_deg"]) for e in eyes if "accuracy_deg" in e]
        worst = [float(t["accuracy_deg"]) for e in eyes for t in e.get("targets") or []
                 if "accuracy_deg" in t]
        targets = {tuple(t.get("target", ())) for e in eyes for t in e.get("targets") or []}
        if targets:
            out["CalibrationType"] = f"{len(targets)}-point"
        if acc:
            out["AverageCalibrationError"] = max(acc)
        if worst:
            out["MaximalCalibrationError"] = max(worst)
        status = (last.get("calibration") or {}).get("status")
        if status:
            out["CalibrationList"] = [[status]]
    return out


def _tracker(info: dict[str, Any]) -> dict[str, Any]:
    t = info.get("tracker") or {}
    name = str(t.get("name", NA))
    out: dict[str, Any] = {
        "Manufacturer": str(t.get("manufacturer") or {"tobii": "Tobii", "simulated": "fovexp",
                                                      "mouse": "none"}.get(name, NA)),
        "ManufacturersModelName": str(t.get("model") or {"simulated": "simulated eye (dry run)",
                                                          "mouse": "mouse gaze (pilot)"}
                                      .get(name, name)),
    }
    if t.get("serial_number"):
        out["DeviceSerialNumber"] = str(t["serial_number"])
    versions = [f"{k} {t[k]}" for k in ("firmware_version", "runtime_version") if t.get(k)]
    if versions:
        out["SoftwareVersions"] = "; ".join(versions)
    return out


def _write_session(s: _Session, out: Path, days: int, left_out: list[str]) -> bool:
    """One session's files; False (and a line in ``left_out``) where it cannot be exported."""
    name = f"{s.experiment}/{s.participant} session {s.session}"
    paths = {k: s.folder / f"{k}-{s.session}.{ext}" for k, ext in
             (("session", "json"), ("gaze", "csv"), ("frames", "csv"), ("blanking", "csv"))}
    try:
        info = json.loads(paths["session"].read_text())
        if not isinstance(info, dict):
            raise ValueError("not an object")
    except FileNotFoundError:
        left_out.append(f"{name}: no session-{s.session}.json (a torn session)")
        return False
    except (OSError, ValueError) as exc:
        left_out.append(f"{name}: session-{s.session}.json cannot be read ({exc}; a torn "
                        "session)")
        return False
    if not paths["gaze"].is_file():
        left_out.append(f"{name}: no gaze file (gaze-{s.session}.csv)")
        return False
    if not paths["frames"].is_file():
        left_out.append(f"{name}: no frame log (frames-{s.session}.csv)")
        return False
    try:
        gaze_head, gaze = gaze_text(paths["gaze"])
        frames = read_log(paths["frames"])
        blanks = (read_log(paths["blanking"]) if paths["blanking"].is_file()
                  else pd.DataFrame(columns=[], dtype=str))
    except (FovexpError, UnicodeDecodeError, ValueError) as exc:
        left_out.append(f"{name}: a log cannot be read ({exc})")
        return False
    version = frame_log_version(list(frames.columns))
    if version is None or version < 1:
        left_out.append(f"{name}: frame log of an older version ({version}; the export needs "
                        "the tracker-clock columns of version 1, issue 9)")
        return False
    k = gaze_head.index("system_time_us") if "system_time_us" in gaze_head else -1
    times = ([int(round(float(t))) for t in (ln.split(",")[k] for ln in gaze) if t != NA]
             if k >= 0 else [])
    if not times or len(times) < len(gaze):
        left_out.append(f"{name}: the gaze file has samples without their time on the "
                        "tracker's clock")
        return False
    display = info.get("display") or {}
    if not all(k in display for k in ("distance_cm", "width_px", "height_px", "width_cm",
                                      "height_cm")):
        left_out.append(f"{name}: the session record has no display profile (screen size and "
                        "distance)")
        return False
    # Time zero of the run: its first gaze sample or first flip, whichever came first.
    timed = frames[frames["flip_system_time_us"].notna()]
    flips = timed["flip_system_time_us"].astype(float).round().astype("int64")
    t0 = int(min(times[0], flips.min() if len(flips) else times[0]))
    first_flip: dict[tuple[str, str], int] = {}
    last_flip: dict[tuple[str, str], int] = {}
    for ti, at, t in zip(timed["trial_index"], timed["attempt"], flips, strict=True):
        first_flip.setdefault((ti, at), int(t))
        last_flip[(ti, at)] = int(t)
    attempts: dict[str, int] = {}
    for ti, at in first_flip:
        attempts[ti] = max(attempts.get(ti, -1), int(at))
    # The events: one row per trial, from its last attempt's first flip.
    hi = {c: k for k, c in enumerate(s.header)}
    events = []
    for r in s.rows:
        ti = r[hi["trial_index"]]
        if ti not in attempts:
            left_out.append(f"{name}: trial {ti} has no frame in the frame log")
            return False
        key = (ti, str(attempts[ti]))
        onset = first_flip[key] - t0
        rt = r[hi["response_time_s"]]
        duration = rt if rt else _seconds(last_flip[key] - first_flip[key])
        trial_type = "practice" if r[hi["practice"]] in ("1", "True", "true") else "trial"
        fields = [_shift_text(v, days) if c in ("session", "timestamp") else v
                  for c, v in zip(s.header, r, strict=True)]
        try:
            events.append([_seconds(onset), duration, trial_type, *map(tsv_field, fields)])
        except FovexpError as exc:
            left_out.append(f"{name}: trial {ti}: {exc}")
            return False
    # In the order trials.csv holds them (the order the trials ended, so their onsets are in
    # order too): the analysis reads the rows back in the order, and at the lines, it wrote.
    beh = out / f"sub-{label(s.participant)}" / "beh"
    beh.mkdir(parents=True, exist_ok=True)
    (beh / f"{s.prefix}_events.tsv").write_text(
        _tsv([[*EVENT_COLUMNS, *s.header], *events]))
    _json(beh / f"{s.prefix}_events.json", {
        "onset": {"Description": "the trial's first stimulus frame (its last attempt), from "
                                 "the run's first gaze sample or flip", "Units": "s"},
        "duration": {"Description": "to the press of Enter (response_time_s)", "Units": "s"},
        "trial_type": {"Description": "practice or trial",
                       "Levels": {"practice": "practice trial (left out of the analysis)",
                                  "trial": "trial"}},
        **_describe(s.header),
        "StimulusPresentation": _stimulus_presentation(info),
    })
    # The gaze, one physio file per eye.
    rate = float((info.get("tracker") or {}).get("rate_hz") or 0)
    span = (times[-1] - times[0]) / 1e6 if len(times) > 1 else 0
    measured = (len(times) - 1) / span if span > 0 else rate
    common = {
        "PhysioType": "eyetrack",
        "TaskName": s.experiment,
        "SamplingFrequency": rate or round(measured, 3),
        "SamplingFrequencyEffective": round(measured, 3),
        "StartTime": round((times[0] - t0) / 1e6, 6),
        "SampleCoordinateSystem": "gaze-on-screen",
        "EnvironmentCoordinates": "top-left",
        "SampleCoordinateUnits": "a.u.",
        "ScreenAOIDefinition": ["circle", [0.5, 0.5, float(
            (info.get("blanking_rule") or {}).get("radius_deg", 1.25))]],
        "EyeTrackingMethod": "video-based (the tracker's own)" if s.tracker != "mouse"
        else "none (mouse)",
        "RecordingType": "continuous",
        **_tracker(info), **_calibration(info),
    }
    for eye, side in (("eye1", "left"), ("eye2", "right")):
        cols = eye_columns(eye, gaze_head)
        std = list(EYE_COLUMNS[eye])
        names = std + cols[len(std):]
        write_gzip(beh / f"{s.prefix}_recording-{eye}_physio.tsv.gz",
                   gaze_to_tsv(gaze_head, gaze, cols))
        sidecar = {
            **common, "RecordedEye": side, "Columns": names,
            "Description": f"the {side} eye's gaze samples"
            + (" and the columns both eyes share" if eye == "eye1" else ""),
            "timestamp": {"Description": "sample time on the tracker's system clock "
                                         "(system_time_us)", "Units": "us"},
            "x_coordinate": {**COLUMN_DESCRIPTIONS[f"{side}_x"], "Units": "a.u."},
            "y_coordinate": {**COLUMN_DESCRIPTIONS[f"{side}_y"], "Units": "a.u."},
            **_describe(names[len(std):]),
        }
        if eye == "eye1":
            sidecar["fovexp"] = {"log_columns": gaze_head}
        _json(beh / f"{s.prefix}_recording-{eye}_physio.json", sidecar)
    # The frame log and the blanking episodes as the left eye's physioevents.
    extra = [*frames.columns, *[c for c in blanks.columns if c not in frames], "log_row"]
    ev_cols = [*PHYSIOEVENT_COLUMNS, *extra]
    fr = frames.assign(onset=frames["flip_system_time_us"], trial_type=FRAME_EVENT,
                       log_row=[str(k) for k in range(len(frames))])
    found = [first_flip.get((ti, at)) for ti, at in zip(blanks.get("trial_index", []),
                                                         blanks.get("attempt", []), strict=True)]
    starts = [t for t in found if t is not None]
    if len(starts) < len(found) or fr["onset"].isna().any():
        left_out.append(f"{name}: a frame or blanking episode without its time on the tracker's "
                        "clock")
        return False
    bl = blanks.assign(
        onset=[str(_us(t + float(v) * 1e6)) for t, v in zip(starts, blanks.get(
            "start_s", []), strict=True)],
        duration=[f"{float(b) - float(a):.6f}" for a, b in zip(
            blanks.get("start_s", []), blanks.get("end_s", []), strict=True)],
        trial_type=BLANKING_EVENT, message=blanks.get("reason", ""),
        log_row=[str(k) for k in range(len(blanks))])
    rows = pd.concat([fr, bl], ignore_index=True).reindex(columns=ev_cols)
    rows = rows.iloc[rows["onset"].astype(float).argsort(kind="stable")]
    write_gzip(beh / f"{s.prefix}_recording-eye1_physioevents.tsv.gz", to_tsv(rows))
    _json(beh / f"{s.prefix}_recording-eye1_physioevents.json", {
        "Description": "every stimulus frame (the frame log) and blanking episode (the "
                       "blanking log) of the session, on the gaze samples' clock",
        "OnsetSource": "timestamp",
        "Columns": ev_cols,
        "onset": {"Description": "the frame's flip, or the blanking episode's start, on the "
                                 "tracker's system clock (the physio files' timestamp)",
                  "Units": "us"},
        "duration": {"Description": "a blanking episode's length", "Units": "s"},
        "TaskName": s.experiment,
        "trial_type": {"Description": "what the row is", "Levels": {
            FRAME_EVENT: "a stimulus frame (the frame log)",
            BLANKING_EVENT: "a blanking episode (the blanking log)"}},
        "message": {"Description": "a blanking episode's reason"},
        **_describe(extra),
        "fovexp": {"frames_columns": list(frames.columns),
                   "blanking_columns": list(blanks.columns) if paths["blanking"].is_file()
                   else None},
    })
    # The session record, without the form's answers (participants.tsv), paths or dates.
    record = _clean(info, days)
    form = info.get("participant_info") or {}
    record["participant_info"] = ({"skipped": form["skipped"]} if "skipped" in form
                                  else {"exported": "participants.tsv"})
    _json(out / SOURCE_FOLDER / f"sub-{label(s.participant)}" / f"{s.prefix}_session.json",
          record)
    s.info = info
    return True


def _participants(out: Path, sessions: list[_Session]) -> None:
    form_fields = ("age", "sex", "vision_correction")
    rows: dict[str, dict[str, str]] = {}
    for s in sessions:
        row = rows.setdefault(label(s.participant), {"participant_id": f"sub-"
                                                     f"{label(s.participant)}"})
        form = s.info.get("participant_info") or {}
        for k in form_fields:
            if form.get(k) not in (None, "") and k not in row:
                row[k] = str(form[k])
        kind = {SIMULATED_TRACKER: DRY_RUN_WORDS, PILOT_TRACKER: PILOT_WORDS}.get(
            s.tracker, "a person, with an eye tracker")
        row.setdefault("data", kind)
    cols = ["participant_id", *form_fields, "data"]
    (out / "participants.tsv").write_text(_tsv([cols, *[[rows[p].get(c, NA) for c in cols]
                                                      for p in sorted(rows)]]))
    _json(out / "participants.json", {
        "participant_id": {"Description": "the runner's participant ID without its '_' and '-'"},
        "age": {"Description": "age from the participant form", "Units": "year"},
        "sex": {"Description": "sex from the participant form"},
        "vision_correction": {"Description": "vision correction from the participant form"},
        "data": {"Description": "whose data these are (the analysis report's words)",
                 "Levels": {DRY_RUN_WORDS: "dry run", PILOT_WORDS: "pilot",
                            "a person, with an eye tracker": "participant"}},
    })


def _scans(out: Path, sessions: list[_Session], days: int) -> None:
    by_sub: dict[str, list[list[str]]] = {}
    for s in sessions:
        started = _shift_text(str(s.info.get("started", "")), days)
        try:
            when = dt.datetime.fromisoformat(started).astimezone(dt.timezone.utc)
            acq = when.strftime("%Y-%m-%dT%H:%M:%S")
        except ValueError:
            acq = NA
        by_sub.setdefault(label(s.participant), []).append(
            [f"beh/{s.prefix}_recording-eye1_physio.tsv.gz", acq])
        by_sub[label(s.participant)].append([f"beh/{s.prefix}_recording-eye2_physio.tsv.gz", acq])
    for sub, rows in by_sub.items():
        (out / f"sub-{sub}" / f"sub-{sub}_scans.tsv").write_text(
            _tsv([["filename", "acq_time"], *sorted(rows)]))
        _json(out / f"sub-{sub}" / f"sub-{sub}_scans.json", {
            "acq_time": {"Description": "the session's start, UTC"
                         + (" (dates shifted for privacy)" if days else "")}})


def _stimuli(out: Path, sessions: list[_Session], left_out: list[str]) -> None:
    index: dict[str, dict[str, Any]] = {}
    for s in sessions:
        images = (s.info.get("stimuli") or {}).get("images") or {}
        for sid, img in sorted(images.items()):
            if sid in index or not isinstance(img, dict):
                continue
            entry = {k: img[k] for k in ("kind", "sha256", "size") if k in img}
            src = Path(str(img.get("path", "")))
            if img.get("kind") == "scene":
                w, h = (img.get("size") or [0, 0])[:2]
                entry["recipe"] = (f"fovexp stimuli generate --size {w}x{h} (fovexp "
                                   f"{s.info.get('software_version', __version__)}; "
                                   "scenes.yaml pins its sha256)")
            if src.is_file() and sha256_file(src) == img.get("sha256"):
                (out / "stimuli").mkdir(exist_ok=True)
                shutil.copyfile(src, out / "stimuli" / f"{sid}{src.suffix}")
                entry["file"] = f"{sid}{src.suffix}"
            else:
                left_out.append(f"stimulus {sid}: not found with its sha256 at its recorded "
                                "path; listed in stimuli/stimuli.json without its file")
            index[sid] = entry
    if index:
        _json(out / "stimuli" / "stimuli.json", dict(sorted(index.items())))


def _task_sidecars(out: Path, sessions: list[_Session], institution: dict[str, str]) -> None:
    """One sidecar per task at the top, which every run's events file inherits."""
    for exp in sorted({s.experiment for s in sessions}):
        _json(out / f"task-{label(exp)}_events.json", {
            "TaskName": exp,
            "TaskDescription": "adjust one parameter of the foveated rendering with a wheel "
                               "while fixating a cross (Tariq et al. 2022, sections 5.2, 6.1)",
            "Instructions": "the protocol's text, in the session records under sourcedata/",
            **institution,
        })


def _analysis(out: Path, stage: Path) -> str:
    """The analysis of the exported dataset (read back, as ``fovexp analyze`` reads it) under
    ``derivatives/fovexp/``; its text without the machine's paths or the time it ran."""
    from fovexp.analysis.report import run_analysis

    deriv = out / "derivatives" / "fovexp"
    with tempfile.TemporaryDirectory(prefix="fovexp-export-") as tmp:
        source = read_bids(stage, Path(tmp) / "results")
        try:
            ana = run_analysis(source.results, Path(tmp) / "report", figures=False,
                               include_pilots=True)
        except FovexpError as exc:
            return f"no analysis: {exc}"
        for path in sorted((Path(tmp) / "report").rglob("*")):
            if not path.is_file():
                continue
            dest = deriv / path.relative_to(Path(tmp) / "report")
            dest.parent.mkdir(parents=True, exist_ok=True)
            text = path.read_text()
            text = text.replace(str(source.results) + "/", "").replace(str(source.results), ".")
            text = re.sub(r" Generated \d{4}-\d{2}-\d{2} \d{2}:\d{2} UTC\.", "", text)
            dest.write_text(text)
        n = len(ana.data.trials)
    _json(deriv / "dataset_description.json", {
        "Name": "fovexp analysis (Table 2, t-tests, report)",
        "BIDSVersion": BIDS_VERSION, "DatasetType": "derivative",
        "GeneratedBy": [{"Name": GENERATOR, "Version": __version__,
                         "Description": "fovexp analyze, run on this dataset read back"}],
    })
    return f"{n} trials analysed into derivatives/fovexp/"


def _readme(out: Path, name: str, report: ExportReport, sessions: list[_Session]) -> None:
    sim = sum(s.tracker == SIMULATED_TRACKER for s in sessions)
    pilots = sum(s.tracker == PILOT_TRACKER for s in sessions)
    lines = [f"# {name}", ""]
    if sim:
        lines += [f"**{'All' if sim == len(sessions) else f'{sim} of {len(sessions)}'} "
                  "sessions come from dry runs: simulated participants, not people.** Nothing "
                  "here is a measurement of vision; it shows that the pipeline runs.", ""]
    if pilots:
        lines += [f"**{pilots} of {len(sessions)} sessions come from mouse-gaze pilot "
                  "sessions** (no eye tracker).", ""]
    lines += [
        f"Written by `fovexp export bids` (fovexp {__version__}) from the logs of "
        "fovexp's experiment runner: a reproduction of Tariq, Tursun and Didyk 2022, "
        f"\"Noise-based enhancement for foveated rendering\" ({PAPER_DOI}).", "",
        "## Layout", "",
        "- `sub-<participant>/beh/sub-<participant>_task-<experiment>[_run-<n>]_events.tsv`: "
        "one row per trial, every column of the runner's trials.csv (described in the "
        "`_events.json`, with the screen as `StimulusPresentation`);",
        "- `..._recording-eye1_physio.tsv.gz` (left eye, and the columns both eyes share) and "
        "`..._recording-eye2_physio.tsv.gz` (right eye): every gaze sample (BEP020);",
        "- `..._recording-eye1_physioevents.tsv.gz`: every stimulus frame and blanking "
        "episode;",
        f"- `{SOURCE_FOLDER}/`: each session's record (protocol, display, tracker, "
        "calibration, software versions), which BIDS has no place for, and the sha256 of "
        "every file (`fovexp analyze` reports a file changed since the export);",
        "- `stimuli/`: the images and, for generated scenes, their recipe;",
        "- `derivatives/fovexp/`: the analysis (Table 2, t-tests, report).", "",
        "`fovexp analyze DATASET` reads this dataset as it reads a results folder.", "",
        "## Left out", "",
    ]
    lines += [f"- {x}" for x in report.left_out] or ["Nothing."]
    lines += ["", "## Analysis", "", report.analysis or "not run", ""]
    (out / "README.md").write_text("\n".join(lines))


def _checksums(out: Path) -> None:
    files = sorted(p for p in out.rglob("*") if p.is_file()
                   and p.relative_to(out).as_posix() != CHECKSUMS)
    (out / CHECKSUMS).write_text("".join(f"{sha256_file(p)}  {p.relative_to(out).as_posix()}\n"
                                         for p in files))


def export_bids(results: str | Path, out: str | Path, *,
                experiments: Iterable[str] = (), participants: Iterable[str] = (),
                include_dry_runs: bool = False, include_pilots: bool = False,
                replace: bool = False, shift_dates_days: int = 0, name: str | None = None,
                authors: Sequence[str] = (), licence: str | None = None,
                institution: dict[str, str] | None = None,
                analysis: bool = True) -> ExportReport:
    """Write the sessions under ``results`` as a BIDS dataset at ``out`` (docs/SHARING.md).

    Dry runs and mouse-gaze pilots are left out unless asked; a session that cannot be
    exported is left out with one line in :attr:`ExportReport.left_out` (and the dataset's
    README). ``shift_dates_days`` moves every date (session IDs, time stamps) that many days
    back. ``institution``: BIDS's ``InstitutionName``, ``InstitutionAddress`` and
    ``InstitutionalDepartmentName``, where given. Raises :class:`FovexpError` when ``out``
    exists and ``replace`` is not set, or when nothing is left to export.
    """
    results, out = Path(results), Path(out)
    if not results.is_dir():
        raise FovexpError(f"{results}: no such folder")
    if out.exists() and not replace:
        raise FovexpError(f"{out}: exists; --replace replaces it")
    if shift_dates_days < 0:
        raise FovexpError(f"--shift-dates {shift_dates_days}: give a number of days >= 0")
    report = ExportReport(out=out)
    chosen = _sessions(results, set(experiments), set(participants), include_dry_runs,
                       include_pilots, report.left_out)
    stage = out.parent / f".{out.name}.partial"
    if stage.exists():
        shutil.rmtree(stage)
    stage.mkdir(parents=True)
    try:
        written: list[_Session] = []
        labels: dict[str, str] = {}
        for s in chosen:
            lab = label(s.participant)
            if labels.setdefault(lab, s.participant) != s.participant:
                report.left_out.append(f"{s.experiment}/{s.participant} session {s.session}: "
                                       f"its BIDS label sub-{lab} is {labels[lab]}'s too")
                continue
            same = [x for x in chosen if x.participant == s.participant
                    and x.experiment == s.experiment]
            run = f"_run-{same.index(s) + 1}" if len(same) > 1 else ""
            s.prefix = f"sub-{lab}_task-{label(s.experiment)}{run}"
            if _write_session(s, stage, shift_dates_days, report.left_out):
                written.append(s)
        if not written:
            why = f" ({report.left_out[0]})" if report.left_out else ""
            hint = ("" if include_dry_runs else "; dry runs are left out unless "
                    "--include-dry-runs")
            raise FovexpError(f"{results}: no session to export{why}{hint}")
        report.sessions = len(written)
        report.participants = sorted({s.participant for s in written})
        _participants(stage, written)
        _scans(stage, written, shift_dates_days)
        _stimuli(stage, written, report.left_out)
        _task_sidecars(stage, written, {k: v for k, v in (institution or {}).items() if v})
        title = name or f"fovexp study {results.resolve().name}"
        _json(stage / "dataset_description.json", {
            "Name": title, "BIDSVersion": BIDS_VERSION, "DatasetType": "raw",
            "GeneratedBy": [{"Name": GENERATOR, "Version": __version__,
                             "Description": "fovexp export bids, from the runner's logs"}],
            "ReferencesAndLinks": [PAPER],
            "HowToAcknowledge": f"Cite {PAPER}",
            **({"Authors": list(authors)} if authors else {}),
            **({"License": licence} if licence else {}),
        })
        _readme(stage, title, report, written)  # the analysis reads the dataset as written
        _checksums(stage)
        if analysis:
            report.analysis = _analysis(stage, stage)
        _readme(stage, title, report, written)
        _checksums(stage)
        if out.exists():
            shutil.rmtree(out)
        stage.rename(out)
    finally:
        if stage.exists():
            shutil.rmtree(stage)
    return report


# ------------------------------------------------------------------------------- validator
@dataclass
class ValidatorReport:
    """The official validator's verdict: its issues as (severity, code, key, file) rows (the
    key: the sidecar key an issue is about, where it is about one)."""

    issues: list[tuple[str, str, str, str]]

    @property
    def errors(self) -> list[tuple[str, str, str, str]]:
        return [i for i in self.issues if i[0] == "error"]

    @property
    def warnings(self) -> list[tuple[str, str, str, str]]:
        return [i for i in self.issues if i[0] == "warning"]


def validator_path() -> str | None:
    """The ``bids-validator-deno`` command (``fovexp[bids]``), beside this Python or on PATH."""
    beside = Path(sys.executable).parent / VALIDATOR
    return str(beside) if beside.is_file() else shutil.which(VALIDATOR)


def validate(dataset: str | Path, timeout_s: float = 300) -> ValidatorReport:
    """Run the official BIDS validator on ``dataset`` (every TSV row checked). Raises
    :class:`FovexpError` when it is not installed (saying how to install it) or fails."""
    exe = validator_path()
    if exe is None:
        raise FovexpError(f"{VALIDATOR} is not installed: pip install 'fovexp[bids]'")
    proc = subprocess.run([exe, str(dataset), "--format", "json", "--max-rows", "-1"],
                          capture_output=True, text=True, timeout=timeout_s)
    try:
        data = json.loads(proc.stdout)
    except ValueError:
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or ["no output"]
        raise FovexpError(f"{VALIDATOR} failed (exit {proc.returncode}): {tail[0]}") from None
    issues = [(str(i.get("severity")), str(i.get("code")), str(i.get("subCode") or ""),
               str(i.get("location") or "")) for i in (data.get("issues") or {}).get("issues")
              or []]
    return ValidatorReport(issues=issues)


# ------------------------------------------------------------------------------- CLI
def add_export_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """``fovexp export bids RESULTS OUT``."""
    p = subparsers.add_parser(
        "export", help="share a study: a results folder as a BIDS dataset",
        description="Write a results folder as a BIDS 1.11 dataset (docs/SHARING.md).")
    sub = p.add_subparsers(dest="format", required=True)
    b = sub.add_parser("bids", help="a BIDS 1.11 dataset (eye tracking as BEP020)",
                       description="Write RESULTS as a BIDS dataset at OUT: the trials as "
                                   "events, the gaze as eye-tracking physio, the analysis "
                                   "under derivatives/fovexp/ (docs/SHARING.md).")
    b.add_argument("results", type=Path, help="results folder (<experiment>/<participant>/)")
    b.add_argument("out", type=Path, help="the dataset's folder (must not exist)")
    b.add_argument("--experiment", action="append", default=[],
                   help="export only this experiment (repeatable)")
    b.add_argument("--participant", action="append", default=[],
                   help="export only this participant (repeatable)")
    b.add_argument("--include-dry-runs", action="store_true",
                   help="export dry runs too (simulated participants, marked as such)")
    b.add_argument("--include-pilots", action="store_true",
                   help="export mouse-gaze pilot sessions too (marked as such)")
    b.add_argument("--shift-dates", type=int, default=0, metavar="DAYS",
                   help="move every date (session IDs, time stamps, acq_time) DAYS back")
    b.add_argument("--name", default=None, help="the dataset's name (dataset_description)")
    b.add_argument("--author", action="append", default=[],
                   help="an author of the dataset, in the order of citation (repeatable)")
    b.add_argument("--license", default=None,
                   help="the dataset's licence, e.g. CC0 or CC-BY-4.0 (dataset_description)")
    b.add_argument("--institution", default=None,
                   help="the lab's institution (InstitutionName of the task sidecars)")
    b.add_argument("--institution-address", default=None,
                   help="its address (InstitutionAddress)")
    b.add_argument("--department", default=None,
                   help="the lab's department (InstitutionalDepartmentName)")
    b.add_argument("--replace", action="store_true", help="replace OUT if it exists")
    b.add_argument("--no-analysis", action="store_true",
                   help="leave out derivatives/fovexp/ (the analysis)")
    b.add_argument("--validate", action="store_true",
                   help=f"run the official validator ({VALIDATOR}, pip install "
                        "'fovexp[bids]') on the dataset")
    b.set_defaults(func=export_command)
    return p


def export_command(args: argparse.Namespace) -> int:
    report = export_bids(args.results, args.out, experiments=args.experiment,
                         participants=args.participant, include_dry_runs=args.include_dry_runs,
                         include_pilots=args.include_pilots, replace=args.replace,
                         shift_dates_days=args.shift_dates, name=args.name,
                         authors=args.author, licence=args.license,
                         institution={"InstitutionName": args.institution,
                                      "InstitutionAddress": args.institution_address,
                                      "InstitutionalDepartmentName": args.department},
                         analysis=not args.no_analysis)
    for line in report.left_out:
        print(f"fovexp export: left out: {line}", file=sys.stderr)
    print(f"fovexp export: {report.sessions} session(s) of {len(report.participants)} "
          f"participant(s) written to {report.out}; {report.analysis or 'no analysis'}")
    if not args.validate:
        return 0
    try:
        verdict = validate(report.out)
    except FovexpError as exc:
        raise FovexpError(f"{report.out} written, not validated: {exc}") from None
    for severity, code, key, where in verdict.issues:
        print(f"{VALIDATOR}: {severity}: {code} {key} {where}".rstrip(), file=sys.stderr)
    print(f"{VALIDATOR}: {len(verdict.errors)} errors, {len(verdict.warnings)} warnings")
    return 1 if verdict.errors else 0
