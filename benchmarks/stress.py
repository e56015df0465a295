"""Run the stress tests (tests/stress) in the long hypothesis profile and record the result in
benchmarks/STRESS.md: examples per property, failures, time, machine and command.

    .venv/bin/python benchmarks/stress.py [--profile long|ci|dev] [--out benchmarks/STRESS.md]

(``./dev stress`` runs it.) The record's table is rewritten between its markers; the text
around them is kept.
"""

from __future__ import annotations

import argparse
import os
import platform
import re
import subprocess
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

from fovexp.bench import machine_cpu

ROOT = Path(__file__).resolve().parents[1]
BEGIN, END = "<!-- stress-run: begin -->", "<!-- stress-run: end -->"


def machine() -> str:
    cpu = machine_cpu()
    return f"{platform.node()}: {cpu}, {os.cpu_count()} cores, {platform.platform()}, " \
           f"Python {platform.python_version()}"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--profile", default="long")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "STRESS.md")
    args = ap.parse_args()
    cmd = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "tests/stress",
           f"--hypothesis-profile={args.profile}", "--hypothesis-show-statistics", "-rA"]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    wall_s = time.perf_counter() - t0
    text = proc.stdout + proc.stderr
    rows = []
    # "tests/stress/test_x.py::test_y:" then its phases' "N passing examples, M failing"
    for block in re.split(r"\n(?=tests/stress/\S+::\S+:\n)", text):
        m = re.match(r"(tests/stress/\S+)::(\S+):\n", block)
        if not m:
            continue
        passing = sum(int(n) for n in re.findall(r"(\d+) passing", block))
        failing = sum(int(n) for n in re.findall(r"(\d+) failing", block))
        secs = sum(float(s) for s in re.findall(r"phase \(([\d.]+) seconds\)", block))
        rows.append((Path(m.group(1)).name, m.group(2), passing, failing, secs))
    outcome = {name: state for state, name in re.findall(
        r"^(PASSED|FAILED|XFAIL|XPASS|ERROR|SKIPPED)\S* tests/stress/\S+::(\S+)", text, re.M)}
    summary = (re.findall(r"^=* ?(\d+ (?:passed|failed|error).*?) in [\d.]+s", text, re.M)
               or ["?"])[-1]
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT,
                            capture_output=True, text=True).stdout.strip()
    lines = [
        BEGIN,
        f"Run {datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC, commit {commit}, profile "
        f"`{args.profile}`: **{summary}** in {wall_s / 60:.1f} min wall.",
        "",
        f"Machine: {machine()}.",
        "",
        f"Command: `{' '.join(['python', *cmd[1:]])}` (what `./dev stress` runs).",
        "",
        "| file | property | examples passed | failing | hypothesis s | outcome |",
        "|---|---|---:|---:|---:|---|",
        *[f"| {f} | `{t}` | {p} | {n} | {s:.0f} | {outcome.get(t, '?')} |"
          for f, t, p, n, s in rows],
        f"| | **total** | {sum(r[2] for r in rows)} | {sum(r[3] for r in rows)} | "
        f"{sum(r[4] for r in rows):.0f} | |",
        END,
    ]
    record = "\n".join(lines)
    old = args.out.read_text() if args.out.exists() else f"# Stress tests\n\n{BEGIN}\n{END}\n"
    if BEGIN in old and END in old:
        new = old[:old.index(BEGIN)] + record + old[old.index(END) + len(END):]
    else:
        new = old.rstrip() + "\n\n" + record + "\n"
    args.out.write_text(new)
    print(record)
    if proc.returncode:
        print(text[-6000:], file=sys.stderr)
    return proc.returncode


if __name__ == "__main__":
    sys.exit(main())
