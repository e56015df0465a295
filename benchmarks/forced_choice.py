"""How many forced-choice trials per method are enough (issue 30, section 4): simulated
participants with known thresholds run QUEST+ sessions (the task's procedure, its NumPy twin
for speed), and the analysis' ML fit (fovexp.analysis.fits) recovers their thresholds.

Per number of trials per method: the coverage of the 95 % intervals, the median error of the
thresholds (log10 units and per cent), the interval's median width, and how often the methods'
order (foveated < contrast < ours, the truths' order) is recovered, per participant and from the
group's mean log thresholds. Writes benchmarks/FORCED_CHOICE.md and forced_choice.json.

    .venv/bin/python benchmarks/forced_choice.py [--participants 20] [--studies 10]
        [--trials 30,60,100,150]

tests/analysis/test_forced_choice_recovery.py runs :func:`recovery` once (20 participants).
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import time
from pathlib import Path

import numpy as np
import pandas as pd

from fovexp.analysis.sections.forced_choice import METHOD_ORDER, compare_methods, fit_thresholds
from fovexp.experiment.tasks.procedures import QuestPlusArrays, geometric_grid
from fovexp.experiment.tasks.simulated_observer import simulate_answers
from fovexp.experiment.tasks.simulated_participant import SimTruth

HERE = Path(__file__).resolve().parent
#: the shipped validation-2afc protocol's procedure (protocols/validation-2afc.yaml)
GRID = geometric_grid(0.05, 2.0, 25)
SLOPES = (1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0)
LAPSE = 0.02
#: the group's thresholds at 75 % correct (arcmin/deg): the simulated adjustment participants'
#: truth (SimTruth.validation_blur_rate), so both tasks' dry runs share one truth
GROUP = {"foveated": 0.25, "contrast": 0.4, "ours": 0.6}
#: between participants: each threshold times exp(N(0, sd)); slopes uniform in this range
PARTICIPANT_SD_LOG = 0.15
SLOPE_RANGE = (2.0, 4.0)


def participants(n: int, seed: int) -> list[SimTruth]:
    """``n`` simulated participants' truths around :data:`GROUP`."""
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        out.append(SimTruth(
            validation_blur_rate={m: float(v * math.exp(rng.normal(0, PARTICIPANT_SD_LOG)))
                                  for m, v in GROUP.items()},
            forced_choice_slope={m: float(rng.uniform(*SLOPE_RANGE)) for m in GROUP},
            forced_choice_lapse=dict.fromkeys(GROUP, LAPSE)))
    return out


def recovery(n_participants: int = 20, trials_per_method: int = 100, seed: int = 0,
             n_boot: int = 400) -> dict[str, float]:
    """One simulated study: coverage, median errors, interval width, order recovered."""
    truths = participants(n_participants, seed)
    rows = []
    for i, truth in enumerate(truths):
        procs = {m: QuestPlusArrays(GRID, SLOPES, (LAPSE,)) for m in GROUP}
        for r in simulate_answers(truth, procs, trials_per_method, seed * 1000 + i):
            rows.append({**r, "experiment": "validation-2afc", "participant": f"S{i:02d}",
                         "practice": False})
    thr = fit_thresholds(pd.DataFrame(rows), n_boot=n_boot, psignifit=False)
    true = np.array([truths[int(p[1:])].validation_blur_rate[m]
                     for p, m in zip(thr["participant"], thr["method"], strict=True)])
    err = np.log10(thr["threshold"].to_numpy() / true)
    inside = (thr["ci_low"].to_numpy() <= true) & (true <= thr["ci_high"].to_numpy())
    wide = thr.pivot(index="participant", columns="method", values="threshold")
    order = list(METHOD_ORDER)
    per_participant = float(np.mean([list(row.sort_values().index) == order
                                     for _, row in wide.iterrows()]))
    group = list(np.log10(wide).mean().sort_values().index) == order
    comp = compare_methods(thr)
    return {"participants": n_participants, "trials_per_method": trials_per_method,
            "intervals": int(inside.size), "coverage": float(inside.mean()),
            "median_abs_error_log10": float(np.median(np.abs(err))),
            "median_abs_error_pct": float(100 * (10 ** np.median(np.abs(err)) - 1)),
            "median_bias_log10": float(np.median(err)),
            "median_width_log10": float(np.median(np.log10(thr["ci_high"] / thr["ci_low"]))),
            "order_per_participant": per_participant, "order_group": bool(group),
            "max_p": float(comp["p"].max())}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--participants", type=int, default=20)
    ap.add_argument("--studies", type=int, default=10)
    ap.add_argument("--trials", default="30,60,100,150")
    args = ap.parse_args()
    results = []
    for n in (int(v) for v in args.trials.split(",")):
        t0 = time.monotonic()
        runs = [recovery(args.participants, n, seed=s) for s in range(args.studies)]
        keys = [k for k, v in runs[0].items() if isinstance(v, float | bool)]
        summary = {"trials_per_method": n, "studies": args.studies,
                   "intervals": sum(r["intervals"] for r in runs),
                   **{k: float(np.mean([r[k] for r in runs])) for k in keys},
                   "coverage_min": min(r["coverage"] for r in runs),
                   "coverage_max": max(r["coverage"] for r in runs),
                   "seconds": time.monotonic() - t0}
        results.append(summary)
        print(json.dumps(summary), flush=True)
    record = {"machine": platform.node(), "participants": args.participants,
              "grid": [GRID[0], GRID[-1], len(GRID)], "slopes": SLOPES, "lapse": LAPSE,
              "group": GROUP, "results": results}
    (HERE / "forced_choice.json").write_text(json.dumps(record, indent=1) + "\n")


if __name__ == "__main__":
    main()
