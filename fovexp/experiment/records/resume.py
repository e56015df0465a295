"""Which session a run continues, and where it stands: new or resumed, the trials already
logged, the attempts begun per trial (no window, no tracker).

A participant's folder holds one ``session-<id>.json`` per session. A run starts a new session
unless one is incomplete: then ``--resume`` continues it (refused when the protocol changed, or
when it would let a dry run finish a participant's session or one gaze source another's) and
``--new-session`` leaves it. A session that failed before its first trial (a tracker set-up, a
bad stimulus) has nothing to continue and blocks nothing.
"""

from __future__ import annotations

import csv
import datetime as _dt
import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fovexp import FovexpError
from fovexp.results.format import now_iso

from ..protocol.spec import LoadedProtocol
from .logs import read_trials


def new_session_id(folder: Path) -> str:
    """``YYYYmmdd-HHMMSS``; waits a second if that id is taken in ``folder``."""
    while True:
        sid = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
        if not (folder / f"session-{sid}.json").exists():
            return sid
        time.sleep(0.2)


def find_sessions(folder: Path) -> list[dict[str, Any]]:
    """The session files of ``folder`` in the order of their ids (unreadable ones left out),
    each with ``_path``."""
    out = []
    for p in sorted(Path(folder).glob("session-*.json")):
        try:
            info = json.loads(p.read_text())
        except (OSError, json.JSONDecodeError):
            continue
        info["_path"] = str(p)
        out.append(info)
    return out


def incomplete_sessions(sessions: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Those a run could continue: not completed, and not failed before a trial was done."""
    return [s for s in sessions if not s.get("completed")
            and not (s.get("state") == "failed" and not s.get("n_completed"))]


@dataclass
class SessionChoice:
    """The session a run works on: its id, its record so far (empty for a new one) and the
    plan's limits (a resumed session keeps those it started with)."""

    session_id: str
    info: dict[str, Any] = field(default_factory=dict)
    limit_trials: int | None = None
    practice_trials: int | None = None

    @property
    def resumed(self) -> bool:
        return bool(self.info)


def choose_session(folder: Path, protocol: LoadedProtocol, participant: str, *, resume: bool,
                   new_session: bool, dry_run: bool, tracker: str,
                   limit_trials: int | None, practice_trials: int | None) -> SessionChoice:
    """The session to continue (``resume``) or a new one; raises :class:`FovexpError` with
    what to do when neither is allowed. Resuming puts back the values the session derived from
    its dependencies (:func:`reuse_derived`)."""
    incomplete = incomplete_sessions(find_sessions(folder))
    if not resume:
        if incomplete and not new_session:
            sid = incomplete[-1].get("session")
            raise FovexpError(
                f"participant {participant} has an incomplete session {sid} of "
                f"{protocol.experiment} in {folder}: add --resume to continue it, or "
                "--new-session to start a new one")
        return SessionChoice(new_session_id(folder), {}, limit_trials, practice_trials)
    if not incomplete:
        raise FovexpError(
            f"--resume: no incomplete session of {protocol.experiment} for participant "
            f"{participant} in {folder}")
    info = incomplete[-1]
    info.pop("_path", None)
    if info.get("protocol_sha256") != protocol.sha256:
        raise FovexpError(
            f"--resume: protocol {protocol.path} changed since session {info['session']} "
            f"started (sha256 {protocol.sha256[:12]}... vs "
            f"{str(info.get('protocol_sha256'))[:12]}...); resuming would mix protocol "
            "versions")
    first = (info.get("runs") or [{}])[0]
    if (first.get("dry_run"), first.get("tracker")) not in ((None, None), (dry_run, tracker)):
        # a dry run must never finish a participant's session, nor a mouse a tracker's
        mode = "a dry run" if first.get("dry_run") else "a session"
        raise FovexpError(
            f"--resume: session {info['session']} started as {mode} with "
            f"--tracker {first.get('tracker')}; resume it the same way "
            f"({'--dry-run' if first.get('dry_run') else 'without --dry-run'}, "
            f"--tracker {first.get('tracker')}), or start a --new-session")
    reuse_derived(protocol, info)
    plan = info.get("plan", {})
    return SessionChoice(str(info["session"]), info, plan.get("limit_trials"),
                         plan.get("practice_trials"))


def reuse_derived(protocol: LoadedProtocol, info: dict[str, Any]) -> None:
    """Resume with the dependency values (f_e per blur-rate, s_k lines, tables) the session
    started with, even when the results they came from changed since (more participants):
    one session never mixes two sets. A change is recorded as an event in ``info``."""
    stored = info.get("derived")
    if stored is None:
        if protocol.derived:
            raise FovexpError(
                f"--resume: session {info['session']} did not record the values it derived "
                f"from {', '.join(sorted(protocol.dependency_folders.values()))}; resuming "
                "could mix two sets of them: start a --new-session")
        return
    if stored != protocol.derived:
        changed = sorted(k for k in set(stored) | set(protocol.derived)
                         if stored.get(k) != protocol.derived.get(k))
        info.setdefault("events", []).append({
            "time": now_iso(), "event": "derived_values_reused", "parameters": changed,
            "note": "the dependency results changed since the session started; the "
                    "session's own values are used"})
        protocol.use_derived(stored)


def done_trials(trials_csv: Path, session_id: str) -> set[int]:
    """The trial indices of ``session_id`` with a row in the trial log (its commit points)."""
    rows, _ = read_trials(trials_csv)
    return {int(r["trial_index"]) for r in rows if r["session"] == session_id}


def attempts_so_far(folder: Path, session_id: str, info: dict[str, Any]) -> dict[int, int]:
    """Attempts already begun per trial index: those the session file recorded at each
    attempt's start, or, for an attempt whose start a kill kept out of it, those in the
    frame and blanking logs. A resumed session numbers its attempts on from these."""
    out = {int(k): int(v) for k, v in (info.get("attempts") or {}).items()}
    for name in (f"frames-{session_id}.csv", f"blanking-{session_id}.csv"):
        path = Path(folder) / name
        if not path.exists():
            continue
        with open(path, encoding="utf-8", newline="") as fh:
            for row in csv.DictReader(fh):
                try:
                    i, a = int(row["trial_index"]), int(row["attempt"])
                except (KeyError, TypeError, ValueError):  # a torn last line
                    continue
                out[i] = max(out.get(i, 0), a + 1)
    return out


def resume_command(protocol_path: Path, participant: str, results_root: Path,
                   dry_run: bool) -> str:
    """The command that continues a session (told when the results disk fills)."""
    parts = ["fovexp run", str(protocol_path), "--participant", participant]
    if Path(results_root) != Path("results"):
        parts += ["--results", str(results_root)]
    if dry_run:
        parts.append("--dry-run")
    return " ".join(parts + ["--resume"])


__all__ = ["SessionChoice", "attempts_so_far", "choose_session", "done_trials",
           "find_sessions", "incomplete_sessions", "new_session_id", "resume_command",
           "reuse_derived"]
