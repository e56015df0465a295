"""Synthetic trial logs in the exact docs/LOGS.md format, from known ground truth.

Simulated participants answer ground truth + a per-participant offset + per-trial noise, clipped to
the experiment's wheel range (paper section 5.2). Used by the analysis tests; nothing here touches
results/.
"""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass, field
from datetime import datetime, timedelta
from pathlib import Path

import numpy as np

from fovexp.results.format import format_value
from fovexp.results.loading import COLUMNS, EXPERIMENT_PARAMETER

BLUR_RATES = (0.11, 0.34, 0.57)
SK_SF_LEVELS = (1.0, 1.9, 3.61, 6.81)  # paper section 5.2
IMAGES = tuple(f"cal{i}" for i in range(5))
SCENES = tuple(f"scene{i:02d}" for i in range(10))
SHA = "a" * 64


@dataclass(frozen=True)
class Truth:
    """Ground truth of one simulated study: a Table 2 plus the s_k lines and validation means.

    Deliberately far from the paper's Table 2 (``fovexp.PAPER_TABLE2``, the enhancer's and the
    runner's default): every entry differs from it by more than twice the recovery tolerance
    of tests/results/test_calibration.py, so an analysis that returned the defaults instead of
    what the logs say fails the recovery tests (issue 19; guarded by
    ``test_the_fixture_truth_is_far_from_the_paper``). Not monotone in blur-rate either, so a
    mix-up of the levels shows."""

    f_e: dict[float, float] = field(default_factory=lambda: {0.11: 0.08, 0.34: 0.31, 0.57: 0.20})
    #: slope of s_k against s_f; the intercept puts the line through (s_f, s_k) below
    slope: dict[float, float] = field(default_factory=lambda: {0.11: -2.0, 0.34: -2.5, 0.57: -2.2})
    s_k: dict[float, float] = field(default_factory=lambda: {0.11: 16.0, 0.34: 30.0, 0.57: 26.0})
    s_f: dict[float, float] = field(default_factory=lambda: {0.11: 4.5, 0.34: 1.6, 0.57: 2.9})
    #: validation: contrast blur-rate per scene, and ours = contrast * (1 + gain)
    contrast: dict[str, float] = field(
        default_factory=lambda: {s: 0.30 + 0.02 * i for i, s in enumerate(SCENES)})
    gain: float = 0.25

    def intercept(self, br: float) -> float:
        return self.s_k[br] - self.slope[br] * self.s_f[br]

    def line(self, br: float, s_f: float) -> float:
        return self.slope[br] * s_f + self.intercept(br)


@dataclass(frozen=True)
class Noise:
    """Standard deviations of the simulated answers (participant offset, trial noise)."""

    f_e: tuple[float, float] = (0.01, 0.02)
    s_k: tuple[float, float] = (0.8, 1.5)
    s_f: tuple[float, float] = (0.10, 0.20)
    blur_rate: tuple[float, float] = (0.02, 0.03)


RANGES = {"f_e": (0.0, 0.4), "s_k": (0.0, 45.0), "s_f": (0.5, 10.0), "blur_rate": (0.0, 2.0)}


def session_id(k: int) -> str:
    return (datetime(2024, 5, 1, 9, 0, 0) + timedelta(hours=k)).strftime("%Y%m%d-%H%M%S")


def conditions(experiment: str, truth: Truth) -> list[dict]:
    """One dict per trial condition of ``experiment`` (one repetition)."""
    if experiment == "calibration-fe":
        return [{"image": im, "blur_rate": br, "method": "contrast"}
                for br in BLUR_RATES for im in IMAGES]
    if experiment == "calibration-sk":
        return [{"image": im, "blur_rate": br, "method": "ours", "s_f": sf}
                for br in BLUR_RATES for sf in SK_SF_LEVELS for im in IMAGES]
    if experiment == "calibration-sf":
        return [{"image": im, "blur_rate": br, "method": "ours"}
                for br in BLUR_RATES for im in IMAGES]
    if experiment == "validation":
        return [{"image": sc, "method": m} for sc in SCENES for m in ("contrast", "ours")]
    raise ValueError(experiment)


def _truth_value(experiment: str, cond: dict, truth: Truth) -> float:
    if experiment == "calibration-fe":
        return truth.f_e[cond["blur_rate"]]
    if experiment == "calibration-sk":
        return truth.line(cond["blur_rate"], cond["s_f"])
    if experiment == "calibration-sf":
        return truth.s_f[cond["blur_rate"]]
    base = truth.contrast[cond["image"]]
    return base * (1 + truth.gain) if cond["method"] == "ours" else base


def simulate_rows(experiment: str, participant: str, session: str, rng: np.random.Generator,
                  truth: Truth, noise: Noise, repetitions: int = 1, practice: int = 2,
                  sha: str = SHA) -> list[dict]:
    """The trials.csv rows of one simulated session (practice trials first)."""
    param = EXPERIMENT_PARAMETER[experiment]
    sd_part, sd_trial = getattr(noise, param)
    lo, hi = RANGES[param]
    offset = rng.normal(0.0, sd_part)
    conds = [dict(c, repetition=r) for r in range(repetitions) for c in conditions(experiment,
                                                                                    truth)]
    order = rng.permutation(len(conds))
    plan = [(True, conds[i]) for i in order[:practice]] + [(False, conds[i]) for i in order]
    t0 = datetime.strptime(session, "%Y%m%d-%H%M%S")
    rows = []
    for idx, (is_practice, cond) in enumerate(plan):
        value = _truth_value(experiment, cond, truth) + offset + rng.normal(0.0, sd_trial)
        if is_practice:
            value = value * 3 + 1  # practice answers are wild: they must not reach the results
        value = float(np.clip(value, lo, hi))
        br = cond.get("blur_rate", value)
        f_e = s_k = s_f = None
        if experiment == "calibration-fe":
            f_e = value
        elif experiment == "calibration-sk":
            f_e, s_k, s_f = truth.f_e[br], value, cond["s_f"]
        elif experiment == "calibration-sf":
            f_e, s_f, s_k = truth.f_e[br], value, truth.line(br, value)
        elif cond["method"] == "contrast":
            f_e = 0.2
        else:
            f_e, s_k, s_f = 0.2, 20.0, 2.2
        start = {"f_e": 0.0, "s_k": 0.0, "s_f": 1.0, "blur_rate": 0.0}[param]
        rows.append({
            "participant": participant, "session": session, "experiment": experiment,
            "protocol_sha256": sha, "trial_index": idx, "practice": int(is_practice),
            "repetition": cond["repetition"], "image": cond["image"], "blur_rate": br,
            "method": cond["method"], "adjusted_parameter": param, "f_e": f_e, "s_k": s_k,
            "s_f": s_f, "start_value": start, "final_value": value,
            "response_time_s": round(float(rng.uniform(3, 20)), 3),
            "wheel_events": int(rng.integers(1, 40)), "blanked_fraction": 0.0,
            "dropped_frames": 0, "tracker": "simulated", "seed": 7,
            "software_version": "0.1.0",
            "timestamp": (t0 + timedelta(seconds=15 * (idx + 1))).isoformat(),
        })
    return rows


def write_trials(folder: Path, rows: list[dict], *, completed: bool | None = True,
                 append: bool = False, columns: tuple[str, ...] = COLUMNS) -> Path:
    """Append ``rows`` to ``folder/trials.csv`` (header first if new) and write the session JSON
    (``completed=None``: no session JSON)."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "trials.csv"
    new = not (append and path.exists())
    with path.open("w" if new else "a", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        if new:
            w.writerow(columns)
        for r in rows:
            w.writerow([format_value(r.get(c)) for c in columns])
    if completed is not None and rows:
        sess = rows[0]["session"]
        (folder / f"session-{sess}.json").write_text(json.dumps(
            {"session": sess, "completed": completed, "protocol_sha256": rows[0]["protocol_sha256"]}
        ))
    return path


def write_study(root: Path, n_participants: int = 10, seed: int = 0, truth: Truth | None = None,
                noise: Noise | None = None, repetitions: int = 1,
                experiments: tuple[str, ...] = tuple(EXPERIMENT_PARAMETER),
                tracker: str = "simulated", prefix: str = "P") -> Path:
    """Write results/<experiment>/<participant>/trials.csv for every experiment and participant
    (participants ``<prefix>01``...; ``tracker``: the gaze source the rows record)."""
    truth = truth or Truth()
    noise = noise or Noise()
    rng = np.random.default_rng(seed)
    for k, exp in enumerate(experiments):
        for p in range(n_participants):
            pid = f"{prefix}{p + 1:02d}"
            rows = simulate_rows(exp, pid, session_id(10 * k + p), rng, truth, noise,
                                 repetitions=repetitions)
            write_trials(root / exp / pid, [dict(r, tracker=tracker) for r in rows])
    return root
