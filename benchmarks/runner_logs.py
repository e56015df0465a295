"""What a dry run writes, with its timings left out: a digest to compare two versions of the
runner (issue 27: the runner's modules moved, its logs must not change).

A dry run depends on the wall clock (how many frames each trial lasts, how many gaze samples
arrive, when the simulated eye follows a calibration target), so the digest keeps what a fixed
seed decides:

- every log's columns, in order, and the session file's key paths;
- trials.csv, every column but the session id, response time, dropped frames, blanked
  fraction and time stamp;
- the frame log: per trial and attempt, the sequence of values shown (each value once per
  run of frames that showed it);
- the gaze log: its first 300 samples without the system time (before the simulated eye
  first follows a calibration target, at a moment the wall clock sets);
- the session file: the plan, seed, display, state, the events' kinds in order, the stimuli's
  sha256 and the validation's targets.

    python benchmarks/runner_logs.py run OUT        # a dry run (calibration-fe, seed 5) into OUT
    python benchmarks/runner_logs.py digest OUT     # its digest as JSON
    python benchmarks/runner_logs.py compare A.json B.json

The before-and-after record of issue 27's move: benchmarks/RUNNER_LOGS.md.
"""

from __future__ import annotations

import csv
import itertools
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

TIMING = {"session", "response_time_s", "dropped_frames", "blanked_fraction", "timestamp"}
GAZE_PREFIX = 300


def run(out: Path) -> None:
    """The dry run the record uses: calibration-fe, 1 practice and 3 trials, seed 5."""
    fovexp = Path(sys.executable).parent / "fovexp"
    subprocess.run(["xvfb-run", "-a", "-s", "-screen 0 1280x720x24", str(fovexp), "run",
                    "calibration-fe", "--participant", "S01", "--dry-run", "--sim-speed", "12",
                    "--limit-trials", "3", "--practice", "1", "--sim-seed", "5",
                    "--results", str(out), "--stimuli", "stimuli"], check=True)


def _rows(path: Path) -> tuple[list[str], list[dict[str, str]]]:
    with path.open(newline="") as f:
        reader = csv.DictReader(f)
        return list(reader.fieldnames or []), list(reader)


def _paths(x: Any, prefix: str = "") -> set[str]:
    if isinstance(x, dict):
        return {prefix} | {p for k, v in x.items() for p in _paths(v, f"{prefix}.{k}")}
    if isinstance(x, list):
        return {prefix} | {p for v in x for p in _paths(v, f"{prefix}[]")}
    return {prefix}


def digest(out: Path) -> dict[str, Any]:
    folder = next(out.glob("*/*/"))
    d: dict[str, Any] = {"columns": {}}
    for path in sorted(folder.glob("*.csv")):
        name = path.name.split("-")[0].removesuffix(".csv")
        cols, rows = _rows(path)
        d["columns"][name] = cols
        if name == "trials":
            d["trials"] = [{k: v for k, v in r.items() if k not in TIMING} for r in rows]
        elif name == "frames":
            d["frames"] = {f"{t}/{a}": [v for v, _ in itertools.groupby(r["value"] for r in g)]
                           for (t, a), g in itertools.groupby(
                               rows, key=lambda r: (r["trial_index"], r["attempt"]))}
        elif name == "gaze":
            d["gaze"] = [{k: v for k, v in r.items() if k != "system_time_us"}
                         for r in rows[:GAZE_PREFIX]]
    info = json.loads(next(folder.glob("session-*.json")).read_text())
    d["session_paths"] = sorted(_paths(info))
    d["session"] = {
        **{k: info[k] for k in ("participant", "experiment", "protocol_sha256", "display",
                                "seed", "plan", "state", "completed")},
        "events": [e["event"] for e in info.get("events", [])],
        "stimuli": {k: v["sha256"] for k, v in info["stimuli"]["images"].items()},
        "validation_targets": [q["validation"]["targets"] for q in info["tracker_quality"]],
    }
    return d


def compare(a: dict[str, Any], b: dict[str, Any]) -> list[str]:
    """The parts of two digests that differ (empty: the same)."""
    return [k for k in sorted(set(a) | set(b)) if a.get(k) != b.get(k)]


def main(argv: list[str]) -> int:
    if argv[:1] == ["run"]:
        run(Path(argv[1]))
    elif argv[:1] == ["digest"]:
        print(json.dumps(digest(Path(argv[1])), indent=1, sort_keys=True))
    elif argv[:1] == ["compare"]:
        a, b = (json.loads(Path(p).read_text()) for p in argv[1:3])
        diff = compare(a, b)
        print("the same" if not diff else f"differ in: {', '.join(diff)}")
        return 1 if diff else 0
    else:
        print(__doc__)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
