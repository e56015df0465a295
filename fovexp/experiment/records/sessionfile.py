"""The session file (``session-<id>.json``, docs/LOGS.md): the session's record, kept in memory
and rewritten whole and atomically on every change, so that it is valid JSON whenever a crash
comes.

Until a run starts its writer thread, every change is written at once on the calling thread;
from then on :meth:`SessionFile.event` (the frame loop's) only asks the writer thread for a
write and never waits on the disk, while :meth:`SessionFile.update` (state that must be on disk
before anything else happens) writes on the calling thread.
"""

from __future__ import annotations

import os
import platform
import sys
import threading
from pathlib import Path
from typing import Any

from fovexp.results.format import now_iso

from .logs import JsonWriter, json_text, write_json_atomic


def software_version() -> str:
    try:
        from importlib.metadata import version

        return version("fovexp")
    except Exception:
        import fovexp

        return str(getattr(fovexp, "__version__", "unknown"))


def versions() -> dict[str, str]:
    """The versions of Python, fovexp and the libraries a session's results depend on."""
    out = {"python": platform.python_version(), "fovexp": software_version(),
           "platform": platform.platform()}
    for mod in ("numpy", "scipy", "pydantic", "psychopy", "pyglet", "tobii_research"):
        m = sys.modules.get(mod)
        if m is None:
            try:
                m = __import__(mod)
            except Exception:
                continue
        # pyglet keeps its version in ``version``
        out[mod] = str(getattr(m, "__version__", getattr(m, "version", "?")))
    return out


class SessionFile:
    """``info`` (the record, a dict) and its file ``path``; changes go through :meth:`update`,
    :meth:`event` or :meth:`edit` (all under one lock: the frame loop's thread adds events
    while the session's changes others)."""

    def __init__(self, path: Path, info: dict[str, Any] | None = None) -> None:
        self.path = Path(path)
        self.info: dict[str, Any] = info if info is not None else {}
        self.lock = threading.Lock()
        self._writer: JsonWriter | None = None

    def text(self) -> str:
        with self.lock:
            return json_text(self.info)

    def update(self, **update: Any) -> None:
        """Set ``update``'s keys and write the file now (after any write the writer thread has
        under way). Not for the frame loop: :meth:`event` is."""
        with self.lock:
            self.info.update(update)
        self.write()

    def write(self) -> None:
        if self._writer is not None:
            self._writer.write_now()
        else:
            write_json_atomic(self.path, self.text())

    def event(self, kind: str, **detail: Any) -> None:
        """An event (with the time), written by the writer thread (the frame loop calls this:
        it never waits on the disk); before the writer exists, at once."""
        with self.lock:
            self.info.setdefault("events", []).append(
                {"time": now_iso(), "event": kind, **detail})
        if self._writer is not None:
            self._writer.request()
        else:
            self.write()

    def set_in_run(self, key: str, value: Any, write: bool = True) -> None:
        """``runs[-1][key] = value`` (this run's entry); written now unless ``write`` is
        False (then with the next write)."""
        with self.lock:
            self.info["runs"][-1][key] = value
        if write:
            self.write()

    def start_writer(self) -> None:
        self._writer = JsonWriter(self.path, self.text)

    def stop_writer(self) -> None:
        """Stop the writer thread (what it had still to write goes into the next write, which
        is on the calling thread)."""
        writer, self._writer = self._writer, None
        if writer is None:
            return
        try:
            writer.close()
        except Exception:  # the final write follows; closing must not hide the run's error
            pass


def new_record(*, session_id: str, participant: str, protocol: Any, display: Any, seed: int,
               limit_trials: int | None, practice_trials: int | None, n_trials: int,
               started: str) -> dict[str, Any]:
    """A new session's record (``protocol`` is a ``LoadedProtocol``, ``display`` its profile)."""
    return {
        "session": session_id,
        "participant": participant,
        "experiment": protocol.experiment,
        "protocol_path": str(protocol.path),
        "protocol_sha256": protocol.sha256,
        "protocol": protocol.text,
        "dependencies": protocol.dependency_folders,
        "derived": protocol.derived,
        "display": display.model_dump(),
        "seed": seed,
        "plan": {"limit_trials": limit_trials, "practice_trials": practice_trials,
                 "n_trials": n_trials},
        "software_version": software_version(),
        "started": started,
        "ended": None,
        "state": "running",
        "completed": False,
        "runs": [],
        "tracker_quality": [],
        "events": [],
    }


def run_entry(*, dry_run: bool, tracker: str, remaining_trials: int, screen: int,
              started: str | None = None) -> dict[str, Any]:
    """This run's entry of the record's ``runs`` (one per start or resume)."""
    return {"started": started or now_iso(), "dry_run": dry_run, "tracker": tracker,
            "pid": os.getpid(), "remaining_trials": remaining_trials, "screen": screen}


def participant_entry(form: dict[str, Any] | None, note: str | None, dry_run: bool,
                      time: str) -> dict[str, Any]:
    """The participant form's answers with the time they were given, or why it was not asked
    (recorded at the first start; a resumed session keeps it)."""
    if form is not None:
        return {**form, "time": time}
    return {"skipped": note or ("dry run" if dry_run else "not asked")}


def start_run(file: SessionFile, *, new: dict[str, Any], run: dict[str, Any],
              form: dict[str, Any] | None, form_note: str | None, dry_run: bool,
              stimuli: dict[str, Any], simulated: dict[str, Any] | None) -> None:
    """This run's entry in the session file: a new session's record first (``new``: the
    keywords of :func:`new_record` but ``started``), the participant form at the first start
    (a resumed session keeps it), the run (:func:`run_entry`), the stimuli and the software's
    versions, the simulated participant of a dry run; the state "running"."""
    info = file.info
    if not info:
        info.update(new_record(**new, started=run["started"]))
    if "participant_info" not in info:
        info["participant_info"] = participant_entry(form, form_note, dry_run, run["started"])
    info["runs"].append(run)
    info["stimuli"] = stimuli
    info["versions"] = versions()
    if simulated is not None:
        info["simulated_participant"] = simulated
    file.update(state="running", completed=False)


def end_run(file: SessionFile, *, state: str, complete: bool, n_completed: int,
            failure: str | None, measured: Any, log_error: OSError | None) -> None:
    """The run's end in the session file, its writer thread stopped first (the events it had
    still to write go into this final write): the state ("incomplete" for a run that ended
    normally with trials left), the failure, the tracker's measured sampling rate, the log a
    full disk kept from being written."""
    extra: dict[str, Any] = {"failure": failure} if failure is not None else {}
    if measured is not None and "tracker" in file.info:
        extra["tracker"] = {**file.info["tracker"], "measured": measured}
    if log_error is not None:
        extra["log_error"] = f"{log_error.filename}: {log_error.strerror}"
    file.stop_writer()
    file.update(state=state if not (state == "completed" and not complete) else "incomplete",
                completed=complete, ended=now_iso(), n_completed=n_completed,
                events=file.info.get("events", []), **extra)


__all__ = ["SessionFile", "end_run", "new_record", "participant_entry", "run_entry",
           "software_version", "start_run", "versions"]
