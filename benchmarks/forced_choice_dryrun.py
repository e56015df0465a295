"""Issue 30's "done when": dry runs of validation-2afc for 20 simulated participants (the real
runner under Xvfb: window, simulated gaze, blanking, QUEST+, logs), analysed by ``fovexp
analyze`` into thresholds with intervals and a comparison of methods, checked against the
participants' known truths (benchmarks/forced_choice.py's).

The protocol is the shipped one with a 0.3 s presentation (the simulated observer does not
look; 1.5 s would only make the run five times longer) and ``--limit-trials`` main trials
(interleaved: a third per method). Writes forced_choice_dryrun.json; the record is in
benchmarks/FORCED_CHOICE.md.

    xvfb-run -a .venv/bin/python benchmarks/forced_choice_dryrun.py [--participants 20]
        [--trials-per-method 30] [--out /tmp/fc-dryrun]
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

from fovexp.stimuli.folder import DRY_RUN_SIZE, StimulusSet, generate_scenes

sys.path.insert(0, str(Path(__file__).resolve().parent))
from forced_choice import participants  # noqa: E402

HERE = Path(__file__).resolve().parent
REPO = HERE.parent


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--participants", type=int, default=20)
    ap.add_argument("--trials-per-method", type=int, default=30)
    ap.add_argument("--out", default="/tmp/fc-dryrun")
    args = ap.parse_args()
    ws = Path(args.out)
    shutil.rmtree(ws, ignore_errors=True)
    (ws / "protocols").mkdir(parents=True)
    shutil.copytree(REPO / "protocols" / "displays", ws / "protocols" / "displays")
    proto = yaml.safe_load((REPO / "protocols" / "validation-2afc.yaml").read_text())
    proto["forced_choice"]["presentation_s"] = 0.3
    (ws / "protocols" / "validation-2afc.yaml").write_text(yaml.safe_dump(proto))
    generate_scenes(StimulusSet(ws / "stimuli"), DRY_RUN_SIZE)
    env = {**os.environ, "FOVEXP_STIMULI": str(ws / "stimuli"), "FOVEXP_PROGRESS": "0"}
    truths = participants(args.participants, seed=0)
    t0 = time.monotonic()
    for i, truth in enumerate(truths):
        path = ws / f"truth-S{i:02d}.yaml"
        path.write_text(yaml.safe_dump(truth.model_dump(mode="json")))
        r = subprocess.run(
            [sys.executable, "-m", "fovexp", "run", "protocols/validation-2afc.yaml",
             "--participant", f"S{i:02d}", "--dry-run", "--practice", "1", "--limit-trials",
             str(3 * args.trials_per_method), "--sim-speed", "12", "--sim-truth", str(path)],
            cwd=ws, env=env, capture_output=True, text=True)
        if r.returncode:
            raise SystemExit(f"S{i:02d}: {r.stderr[-2000:]}")
        print(f"S{i:02d} done, {time.monotonic() - t0:.0f} s", flush=True)
    run_s = time.monotonic() - t0
    r = subprocess.run([sys.executable, "-m", "fovexp", "analyze", "results", "--out", "report"],
                       cwd=ws, env=env, capture_output=True, text=True)
    if r.returncode:
        raise SystemExit(r.stderr[-2000:])
    thr = pd.read_csv(ws / "report" / "tables" / "validation-2afc-thresholds.csv")
    methods = pd.read_csv(ws / "report" / "tables" / "validation-2afc-methods.csv")
    out = {"participants": args.participants, "trials_per_method": args.trials_per_method,
           "run_s": run_s}
    for fit, grp in thr.groupby("fit"):
        true = np.array([truths[int(p[1:])].validation_blur_rate[m]
                         for p, m in zip(grp["participant"], grp["method"], strict=True)])
        err = np.log10(grp["threshold"].to_numpy() / true)
        inside = (grp["ci_low"].to_numpy() <= true) & (true <= grp["ci_high"].to_numpy())
        out[str(fit)] = {"intervals": int(inside.size), "coverage": float(inside.mean()),
                         "median_abs_error_pct": float(100 * (10 ** np.median(np.abs(err)) - 1))}
    out["methods"] = methods[["comparison", "n", "ratio", "p", "p_positive"]].to_dict("records")
    out = json.loads(json.dumps(out, default=lambda v: None if isinstance(v, float)
                                and math.isnan(v) else v))
    (HERE / "forced_choice_dryrun.json").write_text(json.dumps(out, indent=1) + "\n")
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
