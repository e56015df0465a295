"""The test session's dry-run study, made once and shared (tests/conftest.py registers the
fixtures): the paper's chain of calibration experiments and both validations, each run by
``fovexp run --dry-run`` under Xvfb. The analysis' recovery tests
(tests/analysis/test_recovery_dryrun.py), the impulse-count comparison
(tests/experiment/test_dryrun_impulses.py) and the BIDS export (tests/export/) read them;
dry runs are the suite's most expensive setup, so nobody runs their own copy.

The calibration design (``TRUTH``, ``IMAGES``, ``TRIALS``, why these sizes): the recovery
test's docstring.
"""

from __future__ import annotations

import csv
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest
import yaml

from fovexp import ParameterTable

# The runner's modules are imported where used: tests/conftest.py imports this module, and
# most tests never touch the runner.

TRUTH = ParameterTable(source="recovery test ground truth", rows=[
    {"blur_rate": 0.11, "f_e": 0.10, "s_k": 30.0, "s_f": 1.6},
    {"blur_rate": 0.34, "f_e": 0.18, "s_k": 24.0, "s_f": 2.8},
    {"blur_rate": 0.57, "f_e": 0.32, "s_k": 12.0, "s_f": 4.5},
])
SK_SLOPE = -2.0
#: The runner's default per-trial noise sd (SimTruth), written out so the test does not drift.
NOISE = {"f_e": 0.02, "s_k": 1.5, "s_f": 0.25, "blur_rate": 0.04}
PARTICIPANTS = ["R01", "R02", "R03", "R04"]
#: images per protocol copy (fewer than the shipped protocols, to keep the test short)
IMAGES = {"calibration-fe": ["scene-00", "scene-01", "scene-02"],
          "calibration-sk": ["scene-02", "scene-03"],
          "calibration-sf": ["scene-02", "scene-03", "scene-04"],
          "validation": ["scene-00", "scene-03", "scene-06", "scene-09"]}
TRIALS = {"calibration-fe": 9, "calibration-sk": 24, "calibration-sf": 9, "validation": 8}
DRY = ["--dry-run", "--practice", "0", "--window", "160x90", "--sim-speed", "12"]
#: the validations' truth: the highest invisible blur-rate per method
VALIDATIONS_TRUTH = "validation_blur_rate: {contrast: 0.3, ours: 0.5}\n"


def shrink(ws: Path, experiment: str) -> None:
    """Keep fewer images in the workspace's copy of a protocol (everything else as shipped)."""
    path = ws / "protocols" / f"{experiment}.yaml"
    spec = yaml.safe_load(path.read_text())
    spec["images"] = IMAGES[experiment]
    path.write_text(yaml.safe_dump(spec, sort_keys=False))


def run_all(ws: Path, experiment: str, pids: list[str], truth: Path) -> None:
    """Dry-run one protocol for every participant, two sessions at a time."""
    from fovexp.experiment.records.logs import read_trials

    from experiment_helpers import run_cli

    def one(pid: str):
        return pid, run_cli(["run", f"protocols/{experiment}.yaml", "--participant", pid, *DRY,
                             "--sim-truth", str(truth)], cwd=ws, timeout=300)

    with ThreadPoolExecutor(max_workers=2) as pool:
        for pid, r in pool.map(one, pids):
            assert r.returncode == 0, f"{experiment} {pid}:\n{r.stderr[-3000:]}"
            rows, _ = read_trials(ws / "results" / experiment / pid / "trials.csv")
            assert len(rows) == TRIALS[experiment] and not any(r["practice"] for r in rows)


def read_csv(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def analyze_all(ws: Path, out: Path) -> None:
    from fovexp.cli import main as fovexp_main

    code = fovexp_main(["analyze", str(ws / "results"), "--out", str(out), "--no-figures"])
    assert code == 0
    # Every dry-run trial reaches the statistics: complete sessions, no practice, one protocol.
    assert read_csv(out / "tables" / "exclusions.csv") == []


@pytest.fixture(scope="session")
def dry_run_calibration(tmp_path_factory, xvfb_display) -> Path:
    """The three calibration experiments dry-run in order (4 participants), then
    ``fovexp analyze`` into ``report/``: the workspace (``results/``, ``report/``)."""
    from experiment_helpers import make_workspace

    ws = make_workspace(tmp_path_factory.mktemp("recovery") / "project")
    truth = ws / "truth.yaml"
    truth.write_text(yaml.safe_dump({
        "table": TRUTH.model_dump(), "sk_slope": SK_SLOPE, "noise_sd": NOISE}, sort_keys=False))
    for exp in ("calibration-fe", "calibration-sk", "calibration-sf"):
        shrink(ws, exp)
        run_all(ws, exp, PARTICIPANTS, truth)
    analyze_all(ws, ws / "report")
    return ws


@pytest.fixture(scope="session")
def dry_run_validations(tmp_path_factory, xvfb_display) -> Path:
    """``validation`` (64 impulses per kernel) and ``validation-12`` dry-run with one
    participant (S01) on two scenes each, both methods on each scene, without the simulated
    participant's noise, then ``fovexp analyze`` into ``report/``: the workspace
    (``results/``, ``report/``)."""
    from experiment_helpers import make_workspace, run_cli

    ws = make_workspace(tmp_path_factory.mktemp("validations") / "project")
    for protocol in ("validation", "validation-12"):
        path = ws / "protocols" / f"{protocol}.yaml"
        text = path.read_text()
        start = text.index("images: [")
        end = text.index("]", start) + 1
        path.write_text(text[:start] + "images: [scene-05, scene-06]" + text[end:])
    truth = ws / "truth.yaml"
    truth.write_text(VALIDATIONS_TRUTH)
    for protocol in ("validation", "validation-12"):
        r = run_cli(["run", f"protocols/{protocol}.yaml", "--participant", "S01", "--dry-run",
                     "--sim-speed", "12", "--practice", "0",
                     "--sim-truth", str(truth), "--sim-noise-scale", "0"], cwd=ws, timeout=600)
        assert r.returncode == 0, r.stderr[-3000:]
    analyze_all(ws, ws / "report")
    return ws
