"""The rig check's report: JSON (the record a session names by its sha256) and Markdown (for
the lab), written atomically under ``<results>/rig/`` (``fovexp.results.rigcheck`` names and
finds them), with the photodiode log beside them when asked."""

from __future__ import annotations

import csv
import datetime as _dt
import io
import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from fovexp import write_bytes_atomic
from fovexp.results.rigcheck import REPORT_VERSION, report_folder, report_stem

from .checks import VIRTUAL, Check

#: the photodiode log's columns: frame, patch state, flip time (PsychoPy's clock, s) and the
#: same flip on the tracker's clock (us), as the frame log puts flips
PHOTODIODE_COLUMNS = ("frame", "patch_white", "flip_time_s", "flip_system_time_us")


def _clean(x: Any) -> Any:
    """JSON without NaN (null instead), rounded floats."""
    if isinstance(x, float):
        return None if not math.isfinite(x) else round(x, 6)
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    return x


def build_report(checks: list[Check], sections: dict[str, Any], *, dry_run: bool,
                 command: str, created: _dt.datetime, versions: dict[str, str],
                 duration_s: float) -> dict[str, Any]:
    judged = [c for c in checks if c.passed is not None]
    return _clean({
        "format": REPORT_VERSION, "created": created.isoformat(timespec="seconds"),
        "command": command, "dry_run": dry_run,
        "virtual_display": VIRTUAL if dry_run else None,
        "duration_s": duration_s,
        "passed": all(c.passed for c in judged) if judged else None,
        "checks": [c.to_dict() for c in checks],
        **sections, "versions": versions,
    })


#: a check's verdict in words (the Markdown bolds a failure)
RESULT = {True: "pass", False: "FAIL", None: "not judged"}


def _fmt(v: Any) -> str:
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def value_text(check: Mapping[str, Any]) -> str:
    """A check's measured value with its unit, which is the unit its threshold states (a
    share as a percentage against a limit in percent): the Markdown's and the console's one
    rendering of it."""
    if check["value"] is None:
        return "-"
    return f"{_fmt(check['value'])} {check['unit']}" if check["unit"] else _fmt(check["value"])


def check_line(check: Mapping[str, Any]) -> str:
    """One check as the console says it: its title, value, threshold and verdict (the
    Markdown table's row, in the same words)."""
    return (f"{check['title']}: {value_text(check)}; threshold: {check['threshold']}; "
            f"{RESULT[check['passed']]}")


def protocol_text(protocol: Mapping[str, Any]) -> str:
    """Which protocol a report measured with, and why that one (the study folder's own,
    ``--protocol``, or the default)."""
    return f"{protocol.get('experiment')} ({protocol.get('path')}; {protocol.get('chosen')})"


def markdown(report: dict[str, Any]) -> str:
    """The report for the lab: the verdict, every check with its threshold and what to change,
    then the figures."""
    verdict = {True: "PASSED", False: "FAILED", None: "NOT JUDGED"}[report["passed"]]
    lines = [f"# Rig check {report['created']}: {verdict}", ""]
    if report["dry_run"]:
        lines += [f"**Dry run: every figure was {report['virtual_display']}.**", ""]
    lines += [f"`{report['command']}`", ""]
    if isinstance(report.get("protocol"), Mapping):
        lines += [f"Protocol: {protocol_text(report['protocol'])}", ""]
    lines += ["| check | value | threshold | result |", "|---|---|---|---|"]
    for c in report["checks"]:
        res = "**FAIL**" if c["passed"] is False else RESULT[c["passed"]]
        cells = (c["title"], value_text(c), c["threshold"], res)
        lines.append("| " + " | ".join(str(x).replace("|", "\\|") for x in cells) + " |")
    failed = [c for c in report["checks"] if c["passed"] is False]
    if failed:
        lines += ["", "## What to change", ""]
        lines += [f"- **{c['title']}**: {c['advice']}" for c in failed]
    notes = [c for c in report["checks"] if c["note"]]
    if notes:
        lines += ["", "## Notes", ""]
        lines += [f"- {c['title']}: {c['note']}" for c in notes]
    for part in ("protocol", "display", "gpu", "tracker", "photodiode", "machine"):
        if part in report:
            lines += ["", f"## {part}", "", "```json",
                      json.dumps(report[part], indent=1, sort_keys=True)[:6000], "```"]
    return "\n".join(lines) + "\n"


def write_report(results_root: str | Path, report: dict[str, Any], created: _dt.datetime,
                 photodiode_rows: list[tuple[Any, ...]] | None = None) -> Path:
    """``rig-<time>.json``, ``.md`` (and ``-photodiode.csv``) under ``results_root/rig``; the
    JSON's path."""
    folder = report_folder(results_root)
    folder.mkdir(parents=True, exist_ok=True)
    stem = report_stem(created)
    if photodiode_rows:
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(PHOTODIODE_COLUMNS)
        w.writerows(photodiode_rows)
        pd_path = folder / f"{stem}-photodiode.csv"
        write_bytes_atomic(pd_path, buf.getvalue().encode())
        report.setdefault("photodiode", {})["log"] = pd_path.name
    report = _clean(report)
    write_bytes_atomic(folder / f"{stem}.md", markdown(report).encode())
    path = folder / f"{stem}.json"
    write_bytes_atomic(path, (json.dumps(report, indent=1, allow_nan=False) + "\n").encode())
    return path


__all__ = ["PHOTODIODE_COLUMNS", "RESULT", "build_report", "check_line", "markdown",
           "protocol_text", "value_text", "write_report"]
