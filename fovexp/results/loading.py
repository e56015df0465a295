"""Load and validate the runner's trial logs (docs/LOGS.md) for paper sections 5.3 and 6.1.

Every row that does not reach the statistics is accounted for: it is either an error
(:class:`~fovexp.FovexpError` naming the file, line and problem) or an :class:`Exclusion`
with the rule that removed it. The rules, applied in this order (docs/ANALYSIS.md):

R1 torn last row
    The last row of a ``trials.csv`` without its final newline, with the wrong field count or
    with an unparsable value is an interrupted write (the runner writes each row in one fsync'ed
    write ending in a newline): it is dropped, with a warning naming the file and line.
R2 corrupt row
    Any other row with the wrong field count, an unparsable or out-of-range value, or an empty
    required value is an error: the file is damaged and nothing is guessed.
R3 missing columns
    A file whose header lacks a documented column is excluded as a whole (reported).
R4 practice
    Practice trials (``practice == 1``) are excluded.
R5 duplicated trials
    Rows with the same (experiment, participant, session, trial_index): identical copies are
    merged into one; conflicting copies keep the last one written and exclude the others.
R6 wrong parameter
    In the paper's four experiments, rows whose ``adjusted_parameter`` is not the one the
    experiment adjusts are excluded.
R7 pilot sessions
    Trials with mouse gaze (tracker ``mouse``: a person, but no eye tracker) are pilots:
    excluded unless ``include_pilots`` (``--include-pilots``).
R8 simulated sessions
    Where an experiment has trials with a participant's own gaze (tracker ``tobii``, or
    ``mouse`` with ``include_pilots``) in a session not recorded as incomplete, its trials with
    simulated gaze (dry runs, demos) are excluded: a dry run left in the lab's results folder
    never enters its calibration. A folder of simulated sessions alone (CI, demos) is analysed
    as it is, and the report says so at its top.
R9 mixed protocol versions
    Per experiment, the protocol version (``protocol_sha256``) run by the most participants is
    kept (ties: more trials, then the later last trial); rows of other versions are excluded.
R10 incomplete sessions
    A session whose ``session-<id>.json`` records it as not completed is excluded; without a
    readable completion state, a session with fewer trials than the largest session of the same
    experiment and protocol version is excluded.
R11 blanking, R12 dropped frames, R13 latency
    A participant's trial (not a dry run's: its frame timing is the machine's that ran it) is
    excluded when the stimulus was blanked for more than :attr:`TrialLimits.max_blanked_fraction`
    of its frames (the participant mostly looked away from the cross), when more than
    :attr:`TrialLimits.max_dropped_fraction` of its frames were dropped, or when the 95th
    percentile of its frames' gaze-to-flip latency exceeds
    :attr:`TrialLimits.max_latency_p95_ms`. R12 and R13 read the session's frame log
    (``frames-<session>.csv``, :func:`fovexp.results.frames.trial_quality`); a session without
    one is noted and not judged by them.
"""

from __future__ import annotations

import functools
import json
import warnings
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from fovexp import FovexpError, parse_yaml

from .bids import is_fovexp_bids, read_bids
from .choices import FORCED_CHOICE_COLUMNS
from .format import (
    FLOAT_COLUMNS,
    INT_COLUMNS,
    PILOT_TRACKER,
    SIMULATED_TRACKER,
    TRIAL_COLUMNS,
)
from .format import read_trials_file as _read_file
from .frames import read_frame_log, trial_quality
from .limits import R11, R12, R13, TrialLimits

#: ``trials.csv`` columns in their documented order (docs/LOGS.md); the format is defined once,
#: in :mod:`fovexp.results.format`.
COLUMNS: tuple[str, ...] = TRIAL_COLUMNS
#: The parameter each of the paper's experiments adjusts (sections 5.2, 6.1).
EXPERIMENT_PARAMETER: dict[str, str] = {
    "calibration-fe": "f_e",
    "calibration-sk": "s_k",
    "calibration-sf": "s_f",
    "validation": "blur_rate",
}
_COMPLETE_WORDS = frozenset({"complete", "completed", "finished", "done"})
_INCOMPLETE_WORDS = frozenset({
    "incomplete", "aborted", "interrupted", "running", "in_progress", "in-progress", "started",
    "crashed", "failed",
})

RULES: dict[str, str] = {
    "R1 torn last row": "last row of a file without its final newline, with the wrong field "
    "count or with an unparsable value (an interrupted write): dropped with a warning",
    "R2 corrupt row": "any other malformed row: an error naming the file, line and column",
    "R3 missing columns": "a file whose header lacks a documented column: whole file excluded",
    "R4 practice": "practice trials (practice = 1): excluded",
    "R5 duplicated trial": "same experiment, participant, session and trial_index more than once: "
    "identical copies merged, conflicting copies keep the last one written",
    "R6 wrong parameter": "a row of calibration-fe/-sk/-sf or validation whose "
    "adjusted_parameter is not the experiment's (f_e/s_k/s_f/blur_rate): excluded",
    "R7 pilot sessions": "trials with mouse gaze (pilots: a person, no eye tracker): excluded "
    "unless --include-pilots",
    "R8 simulated sessions": "trials with simulated gaze (dry runs) of an experiment that also "
    "has trials with a participant's own gaze (tobii; mouse with --include-pilots): excluded",
    "R9 mixed protocol versions": "per experiment, only the protocol version run by the most "
    "participants (ties: more trials, then the later last trial) is kept",
    "R10 incomplete session": "a session recorded as not completed in session-<id>.json (or, "
    "without one, with fewer trials than the largest session of its experiment and protocol "
    "version): excluded",
}


def rules(limits: TrialLimits | None = None) -> dict[str, str]:
    """Every exclusion rule in the order applied (R1-R13), with the thresholds of ``limits``."""
    return {**RULES, **(limits or TrialLimits()).rules()}


@dataclass(frozen=True)
class Exclusion:
    """Trials removed from the analysis by one rule (or a warning that removed nothing)."""

    rule: str
    file: str
    detail: str
    n_trials: int = 0
    experiment: str = ""
    participant: str = ""
    session: str = ""


@dataclass
class Dataset:
    """The included trials of any number of participants and sessions, and what was removed.

    ``trials`` holds one row per included trial with the documented columns (typed) plus
    ``file`` and ``line`` (where it came from).
    """

    root: Path
    trials: pd.DataFrame
    files: list[Path]
    exclusions: list[Exclusion] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def experiment(self, name: str) -> pd.DataFrame:
        """The included trials of experiment ``name`` (may be empty)."""
        return self.trials[self.trials["experiment"] == name]

    @property
    def experiments(self) -> list[str]:
        return sorted(self.trials["experiment"].unique())


def read_trials_file(path: Path) -> tuple[pd.DataFrame, list[Exclusion]]:
    """Read one ``trials.csv``: rules R1 (torn last row), R2 (corrupt row), R3 (missing columns).

    Returns the parsed rows (all of them, practice included) and the exclusions/warnings.
    Raises :class:`FovexpError` on a corrupt row other than the last one.
    """
    path = Path(path)
    tf = _read_file(path)
    empty = pd.DataFrame(columns=[*COLUMNS, "file", "line"])
    if not tf.header:
        return empty, [Exclusion("R3 missing columns", str(path), "empty file (no header)")]
    if tf.missing:
        n_rows = sum(1 for ln in path.read_bytes().splitlines()[1:] if ln.strip())
        return empty, [Exclusion(
            "R3 missing columns", str(path), f"header lacks {', '.join(tf.missing)}",
            n_trials=n_rows,
        )]
    exclusions: list[Exclusion] = []
    if tf.extra and tf.extra != list(FORCED_CHOICE_COLUMNS):  # answers: read by .choices
        exclusions.append(
            Exclusion("note", str(path), f"extra columns ignored: {', '.join(tf.extra)}")
        )
    if tf.torn is not None:
        msg = f"line {tf.torn_line}: torn last row dropped ({tf.torn})"
        exclusions.append(Exclusion("R1 torn last row", str(path), msg, n_trials=1))
    parsed = [dict(r, file=str(path), line=ln) for r, ln in zip(tf.rows, tf.lines, strict=True)]
    frame = pd.DataFrame(parsed, columns=[*COLUMNS, "file", "line"]) if parsed else empty
    if not parsed:
        exclusions.append(Exclusion("note", str(path), "no trials"))
    return frame, exclusions


def find_trial_files(root: Path) -> list[Path]:
    """All ``trials.csv`` under ``root`` (a results folder, an experiment or a participant)."""
    root = Path(root)
    if not root.exists():
        raise FovexpError(f"{root}: no such folder")
    if root.is_file():
        return [root]
    files = sorted(root.rglob("trials.csv"))
    if not files:
        raise FovexpError(
            f"{root}: no trials.csv found (expected <experiment>/<participant>/trials.csv)"
        )
    return files


def _session_state(folder: Path, session: str) -> bool | None:
    """Completion state from ``session-<id>.json``: True, False, or None when not recorded."""
    path = folder / f"session-{session}.json"
    if not path.is_file():
        return None
    try:
        info = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(info, Mapping):
        return None
    # The runner's key is not fixed in LOGS.md; accept the plausible spellings.
    for key in ("completed", "complete", "is_complete", "finished"):
        if isinstance(info.get(key), bool):
            return bool(info[key])
    for key in ("completion", "completion_state", "state", "status"):
        value = info.get(key)
        if isinstance(value, Mapping):
            for sub in ("completed", "complete"):
                if isinstance(value.get(sub), bool):
                    return bool(value[sub])
            value = value.get("state", value.get("status"))
        if isinstance(value, str):
            low = value.strip().lower()
            if low in _COMPLETE_WORDS:
                return True
            if low in _INCOMPLETE_WORDS:
                return False
    return None


def _exclude(frame: pd.DataFrame, mask: pd.Series, rule: str, detail: str,
             out: list[Exclusion]) -> pd.DataFrame:
    """Drop ``mask`` rows, one Exclusion per (file, session)."""
    gone = frame[mask]
    for (file, exp, part, sess), grp in gone.groupby(
        ["file", "experiment", "participant", "session"], sort=True
    ):
        out.append(Exclusion(rule, str(file), detail, len(grp), str(exp), str(part), str(sess)))
    return frame[~mask]


def load_results(
    root: str | Path,
    *,
    include_incomplete: bool = False,
    include_pilots: bool = False,
    protocol: Mapping[str, str] | None = None,
    limits: TrialLimits | None = None,
) -> Dataset:
    """Load every ``trials.csv`` under ``root`` and apply rules R1-R13 (see module docstring).

    ``root`` may also be a BIDS dataset written by ``fovexp export bids``
    (:mod:`fovexp.results.bids`): its logs are read back into a temporary results folder
    (then ``Dataset.root``), and files changed since the export are listed in the notes.

    ``include_incomplete`` keeps incomplete sessions (R10 then only reports them);
    ``include_pilots`` keeps mouse-gaze sessions (R7); ``protocol`` maps an experiment to the
    ``protocol_sha256`` (or a prefix) to keep instead of the majority version (R9); ``limits``
    the thresholds of R11-R13. Raises :class:`FovexpError` for an empty or missing folder, a
    corrupt row, or when no trial is left.
    """
    limits = limits or TrialLimits()
    root = Path(root)
    notes: list[str] = []
    if is_fovexp_bids(root):
        # A dataset of fovexp export bids: its logs written back into a results folder of the
        # usual layout, read below as any other (the analysis never knows the difference).
        source = read_bids(root)
        root = source.results
        notes += [f"{source.dataset}: {line}" for line in source.changed]
        if source.changed:
            warnings.warn(f"{source.dataset}: {len(source.changed)} file(s) changed since "
                          f"fovexp exported it, e.g. {source.changed[0]} (the report's notes "
                          "list them)", stacklevel=2)
    files = find_trial_files(root)
    session_state = functools.cache(_session_state)  # R7 and R9 ask about the same sessions
    frames: list[pd.DataFrame] = []
    exclusions: list[Exclusion] = []
    for path in files:
        frame, excl = read_trials_file(path)
        exclusions.extend(excl)
        if len(frame):
            frames.append(frame)
            names = set(frame["participant"])
            if path.parent.name not in names:
                notes.append(f"{path}: folder name {path.parent.name!r} is not the participant "
                             f"column ({', '.join(sorted(names))}); the column is used")
    if not frames:
        raise FovexpError(f"{root}: no usable trials in {len(files)} trials.csv file(s)"
                          + _first_reason(exclusions))
    # all-empty columns (e.g. s_f in calibration-fe) carry no dtype; they are typed just below
    columns = frames[0].columns
    trials = pd.concat([f.dropna(axis=1, how="all") for f in frames], ignore_index=True)
    trials = _typed(trials.reindex(columns=columns))

    # R4 practice.
    trials = _exclude(trials, trials["practice"], "R4 practice", "practice trial", exclusions)

    # R5 duplicated trials.
    key = ["experiment", "participant", "session", "trial_index"]
    dup = trials.duplicated(key, keep=False)
    if dup.any():
        content = [c for c in COLUMNS if c not in ("timestamp",)]
        drop = pd.Series(False, index=trials.index)
        for k, grp in trials[dup].groupby(key, sort=True):
            keep_idx = grp.index[-1]  # file order: the last one written
            identical = len(grp[content].astype(str).drop_duplicates()) == 1
            detail = (f"trial_index {k[3]} appears {len(grp)} times "
                      + ("(identical copies merged)" if identical
                         else f"with different values; kept {grp.loc[keep_idx, 'file']} line "
                              f"{grp.loc[keep_idx, 'line']}"))
            drop[grp.index[:-1]] = True
            exclusions.append(Exclusion("R5 duplicated trial", str(grp["file"].iloc[0]), detail,
                                        len(grp) - 1, k[0], k[1], k[2]))
        trials = trials[~drop]

    # R6 wrong parameter for the paper's experiments.
    expected = trials["experiment"].map(EXPERIMENT_PARAMETER)
    wrong = expected.notna() & (expected != trials["adjusted_parameter"])
    if wrong.any():
        trials = _exclude(trials, wrong, "R6 wrong parameter",
                          "adjusted_parameter is not the experiment's", exclusions)

    # R7 pilot sessions.
    pilot = trials["tracker"] == PILOT_TRACKER
    if pilot.any() and not include_pilots:
        trials = _exclude(trials, pilot, "R7 pilot sessions",
                          "mouse gaze: a pilot session (--include-pilots keeps it)", exclusions)

    # R8 simulated sessions (before R9: dry runs must not outvote the real participants).
    simulated = trials["tracker"] == SIMULATED_TRACKER
    for exp, grp in list(trials.groupby("experiment", sort=True)):
        sim = simulated & (trials["experiment"] == exp)
        # a real session recorded as not completed (R9 drops it) does not push the dry runs out
        real = grp[~simulated[grp.index]]
        has_real = any(include_incomplete or session_state(Path(f).parent, str(sess)) is not False
                       for f, sess in real[["file", "session"]].drop_duplicates().itertuples(
                           index=False))
        if sim.any() and has_real:
            trials = _exclude(trials, sim, "R8 simulated sessions",
                              "simulated gaze (a dry run) beside real participants' sessions",
                              exclusions)
            simulated = simulated[trials.index]
        elif sim.any():
            notes.append(f"experiment {exp}: every trial comes from simulated gaze (dry runs), "
                         "not from real participants")

    # R9 mixed protocol versions.
    protocol = dict(protocol or {})
    for exp, grp in list(trials.groupby("experiment", sort=True)):
        versions = grp.groupby("protocol_sha256").agg(
            participants=("participant", "nunique"), n=("trial_index", "size"),
            last=("timestamp", lambda s: max((str(v) for v in s if v), default="")),
        )
        if exp in protocol:
            matches = [v for v in versions.index if str(v).startswith(protocol[exp])]
            if len(matches) != 1:
                raise FovexpError(f"experiment {exp}: protocol {protocol[exp]!r} matches "
                                  f"{len(matches)} of the logged versions "
                                  f"({', '.join(v[:12] for v in versions.index)})")
            keep = matches[0]
        elif len(versions) > 1:
            keep = versions.sort_values(["participants", "n", "last"], ascending=False).index[0]
        else:
            continue
        other = (trials["experiment"] == exp) & (trials["protocol_sha256"] != keep)
        if other.any():
            trials = _exclude(trials, other, "R9 mixed protocol versions",
                              f"protocol {_short(trials.loc[other, 'protocol_sha256'])} "
                              f"differs from the kept {keep[:12]}", exclusions)

    # R10 incomplete sessions.
    sess_key = ["experiment", "protocol_sha256", "participant", "session"]
    sizes = trials.groupby(sess_key, sort=True).agg(n=("trial_index", "size"),
                                                    file=("file", "first"))
    largest = sizes.groupby(level=["experiment", "protocol_sha256"])["n"].transform("max")
    for (exp, sha, part, sess), row in sizes.iterrows():
        state = session_state(Path(row["file"]).parent, str(sess))
        if state is True:
            continue
        if state is False:
            reason = f"session-{sess}.json records it as not completed ({row['n']} trials)"
        elif row["n"] < largest[(exp, sha, part, sess)]:
            reason = (f"{row['n']} trials, fewer than the {largest[(exp, sha, part, sess)]} of "
                      f"the largest session (no completion state in session-{sess}.json)")
        else:
            continue
        mask = ((trials["experiment"] == exp) & (trials["participant"] == part)
                & (trials["session"] == sess) & (trials["protocol_sha256"] == sha))
        if include_incomplete:
            exclusions.append(Exclusion("R10 incomplete session", str(row["file"]),
                                        reason + "; kept (--include-incomplete)", 0,
                                        str(exp), str(part), str(sess)))
        else:
            trials = _exclude(trials, mask, "R10 incomplete session", reason, exclusions)

    trials = _trial_quality_rules(trials, limits, exclusions, notes)

    if trials.empty:
        hint = (" (mouse-gaze pilot sessions were left out: --include-pilots keeps them)"
                if any(e.rule == "R7 pilot sessions" for e in exclusions) else "")
        raise FovexpError(f"{root}: no trials left after the exclusion rules"
                          + _first_reason(exclusions) + hint)
    return Dataset(root=root, trials=trials.reset_index(drop=True), files=files,
                   exclusions=exclusions, notes=notes)


def _trial_quality_rules(trials: pd.DataFrame, limits: TrialLimits,
                         exclusions: list[Exclusion], notes: list[str]) -> pd.DataFrame:
    """R11 blanking, R12 dropped frames, R13 latency: a participant's trials only (a dry run's
    frame timing is the machine's that ran it, not a participant's)."""
    person = trials["tracker"] != SIMULATED_TRACKER
    if not person.any():
        return trials
    blanked = person & limits.blanked_excluded(trials["blanked_fraction"])
    if blanked.any():
        trials = _exclude(trials, blanked, R11,
                          f"blanked for more than {limits.max_blanked_fraction:.0%} of the "
                          "trial's frames", exclusions)
    dropped = pd.Series(False, index=trials.index)
    late = pd.Series(False, index=trials.index)
    person = trials["tracker"] != SIMULATED_TRACKER
    for (file, sess), grp in trials[person].groupby(["file", "session"], sort=True):
        path = Path(str(file)).parent / f"frames-{sess}.csv"
        if not path.is_file():
            notes.append(f"{path.parent}: session {sess} has no frame log: rules R12 and R13 "
                         "not applied to it")
            continue
        quality = trial_quality(read_frame_log(path)).set_index("trial_index")
        q = quality.reindex(grp["trial_index"].astype(int).to_numpy())
        dropped[grp.index] = limits.dropped_excluded(q["dropped_fraction"]).to_numpy()
        late[grp.index] = limits.latency_excluded(q["latency_p95_ms"]).to_numpy()
    if dropped.any():
        trials = _exclude(trials, dropped, R12,
                          f"more than {limits.max_dropped_fraction:.0%} of the trial's frames "
                          "dropped", exclusions)
    late = late[trials.index]
    if late.any():
        trials = _exclude(trials, late, R13,
                          "the 95th percentile of the gaze-to-flip latency above "
                          f"{limits.max_latency_p95_ms:g} ms", exclusions)
    return trials


def _short(values: Iterable[str]) -> str:
    return ", ".join(sorted({str(v)[:12] for v in values}))


def _first_reason(exclusions: list[Exclusion]) -> str:
    real = [e for e in exclusions if e.rule != "note"] or exclusions
    return f" (e.g. {real[0].file}: {real[0].detail})" if real else ""


def _typed(frame: pd.DataFrame) -> pd.DataFrame:
    frame = frame.copy()
    for col in FLOAT_COLUMNS:
        frame[col] = pd.to_numeric(frame[col], errors="coerce").astype(float)
    for col in INT_COLUMNS:
        frame[col] = pd.array(frame[col], dtype="Int64")
    frame["practice"] = frame["practice"].astype(bool)
    frame["line"] = frame["line"].astype(int)
    return frame


#: A protocol's impulse count when it does not name one (fovexp.experiment.protocol.spec's default).
DEFAULT_IMPULSES = 64


def impulse_count(results: Path, experiment: str) -> int | None:
    """The ``impulses`` of the protocol the sessions of ``experiment`` ran (the newest
    session's copy of the protocol in its ``session-*.json``, docs/LOGS.md; 64 where the
    protocol names none), or None when no session file records the protocol."""
    folder = results / experiment
    if not folder.is_dir():
        folder = results if results.name == experiment else folder
    best: tuple[str, int] | None = None
    for path in sorted(folder.rglob("session-*.json")):
        try:
            info = json.loads(path.read_text())
            text = info.get("protocol") if isinstance(info, dict) else None
            if not isinstance(text, str):
                continue
            spec = parse_yaml(text, str(path))
        except (OSError, ValueError, FovexpError):
            continue
        if not isinstance(spec, dict):
            continue
        n = int(spec.get("impulses", DEFAULT_IMPULSES))
        if best is None or path.name > best[0]:
            best = (path.name, n)
    return None if best is None else best[1]
