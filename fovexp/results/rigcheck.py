"""The rig check's reports on disk (``fovexp rig check``, docs/EXPERIMENT.md "The rig check"):
where they are, how they are named, and the newest one, which ``fovexp run`` records in the
session file (its name and sha256) and warns about (none from the session's day, or a failed
one). Written by :mod:`fovexp.rig`; read here, below both the runner and the rig check.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

#: the reports' folder under the results root
RIG_FOLDER = "rig"
#: ``rig-YYYYmmdd-HHMMSS.json`` (and ``.md`` beside it)
REPORT_PREFIX = "rig-"
#: the JSON report's format version
REPORT_VERSION = 2  # 2: percent units, tracker.clock_jitter, the protocol section (issue 32)


def report_folder(results_root: str | Path) -> Path:
    return Path(results_root) / RIG_FOLDER


def report_stem(when: _dt.datetime) -> str:
    return f"{REPORT_PREFIX}{when.strftime('%Y%m%d-%H%M%S')}"


@dataclass(frozen=True)
class ReportRef:
    """A rig report as a session records it."""

    path: Path
    sha256: str
    created: str
    passed: bool | None
    dry_run: bool
    failed_checks: tuple[str, ...]

    @property
    def day(self) -> str:
        return self.created[:10]

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.path.name, "path": str(self.path), "sha256": self.sha256,
                "created": self.created, "passed": self.passed, "dry_run": self.dry_run,
                "failed_checks": list(self.failed_checks)}


def newest_report(results_root: str | Path) -> ReportRef | None:
    """The newest readable report under ``results_root/rig`` (by its name: the time it was
    made), or None."""
    for path in sorted(report_folder(results_root).glob(f"{REPORT_PREFIX}*.json"),
                       reverse=True):
        try:
            data = path.read_bytes()
            rep = json.loads(data)
        except (OSError, ValueError):
            continue
        if not isinstance(rep, dict) or "checks" not in rep:
            continue
        failed = tuple(c.get("id", "?") for c in rep.get("checks", [])
                       if c.get("passed") is False)
        return ReportRef(path, hashlib.sha256(data).hexdigest(), str(rep.get("created", "")),
                         rep.get("passed"), bool(rep.get("dry_run")), failed)
    return None


def session_rig_record(results_root: str | Path, today: str,
                       dry_run: bool) -> tuple[dict[str, Any], str | None]:
    """What a session records of the newest rig report (``rig_check``), and a warning for the
    operator when there is none from ``today`` (``YYYY-mm-dd``), it failed, or it was a dry
    run's (a participant's session on a rig checked only under a virtual display)."""
    ref = newest_report(results_root)
    if ref is None:
        return ({"report": None},
                "no rig check under this results root: run fovexp rig check before the first "
                "participant")
    rec = {"report": ref.to_dict()}
    if ref.passed is False:
        return rec, (f"the newest rig check ({ref.path.name}) failed "
                     f"({', '.join(ref.failed_checks)}): see {ref.path.with_suffix('.md')}")
    if ref.day != today:
        return rec, (f"no rig check today (the newest is {ref.path.name}, {ref.day}): run "
                     "fovexp rig check at the start of each study day")
    if ref.dry_run and not dry_run:
        return rec, (f"the newest rig check ({ref.path.name}) was a dry run under a virtual "
                     "display: run fovexp rig check on this rig")
    return rec, None


__all__ = ["REPORT_PREFIX", "REPORT_VERSION", "RIG_FOLDER", "ReportRef", "newest_report",
           "report_folder", "report_stem", "session_rig_record"]
