"""The report's 12-against-64-impulses section (paper section 6.3): both validations in one
results folder (simulated logs whose session files carry the shipped protocols' text, as the
runner's do), ours against contrast at each count, the test of whether the advantage differs,
and the sampling-rate reduction per scene at each count."""

from __future__ import annotations

import csv
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from fovexp.analysis.report import run_analysis
from fovexp.results.loading import impulse_count

from analysis_fixtures import Noise, Truth, session_id, simulate_rows, write_trials

REPO = Path(__file__).resolve().parents[2]


def _write(root: Path, experiment: str, protocol: str, truth: Truth, seed: int,
           participants: int = 8, offset: int = 0) -> None:
    rng = np.random.default_rng(seed)
    text = (REPO / "protocols" / f"{protocol}.yaml").read_text()
    for p in range(participants):
        pid = f"P{p + 1:02d}"
        sess = session_id(100 * seed + p + offset)
        rows = [dict(r, experiment=experiment)
                for r in simulate_rows("validation", pid, sess, rng, truth, Noise())]
        folder = root / experiment / pid
        write_trials(folder, rows)
        info_path = folder / f"session-{sess}.json"
        info = json.loads(info_path.read_text())
        info["protocol"] = text
        info_path.write_text(json.dumps(info))


@pytest.fixture(scope="module")
def same_gain(tmp_path_factory) -> Path:
    """The paper's finding: the advantage is the same at 12 and 64 (gain 0.25 both)."""
    root = tmp_path_factory.mktemp("same")
    _write(root, "validation", "validation", Truth(), seed=1)
    _write(root, "validation-12", "validation-12", Truth(), seed=2, offset=50)
    return root


def _csv(path: Path) -> list[dict[str, str]]:
    return list(csv.DictReader(path.open()))


def test_the_impulse_count_comes_from_the_recorded_protocol(same_gain):
    assert impulse_count(same_gain, "validation") == 64
    assert impulse_count(same_gain, "validation-12") == 12
    assert impulse_count(same_gain, "no-such") is None


def test_the_section_reports_both_counts_and_an_unchanged_advantage(same_gain, tmp_path):
    ana = run_analysis(same_gain, tmp_path / "r")
    md = (tmp_path / "r" / "report.md").read_text()
    assert "## Impulses per kernel: 12 against 64 (section 6.3)" in md
    per = {int(r["impulses"]): r for r in _csv(tmp_path / "r" / "tables" /
                                                "impulses-per-count.csv")}
    assert set(per) == {12, 64}
    for r in per.values():  # ours beats contrast at each count
        assert float(r["mean_diff"]) > 0 and float(r["p"]) < 0.001
    (diff,) = _csv(tmp_path / "r" / "tables" / "impulses-difference.csv")
    assert diff["test"] == "paired (participant x scene)"  # the same participants and scenes
    assert float(diff["p"]) > 0.05  # the same truth: no difference found
    assert float(diff["ci_low"]) < 0 < float(diff["ci_high"])
    sampling = _csv(tmp_path / "r" / "tables" / "impulses-sampling.csv")
    assert {(r["experiment"], r["impulses"]) for r in sampling} == {("validation", "64"),
                                                                     ("validation-12", "12")}
    assert all(float(r["reduction_pct"]) > 0 for r in sampling)
    assert (tmp_path / "r" / "figures" / "impulses-sampling.png").stat().st_size > 0
    assert len(ana.validations) == 2


def test_a_smaller_advantage_at_12_is_detected(tmp_path):
    root = tmp_path / "results"
    _write(root, "validation", "validation", Truth(), seed=3)
    _write(root, "validation-12", "validation-12", replace(Truth(), gain=0.05), seed=4,
           offset=50)
    run_analysis(root, tmp_path / "r", figures=False)
    (diff,) = _csv(tmp_path / "r" / "tables" / "impulses-difference.csv")
    assert (diff["a"], diff["b"]) == ("validation-12", "validation")  # fewer impulses first
    assert float(diff["mean_diff"]) < 0 and float(diff["p"]) < 0.001


def test_different_participants_get_welch(tmp_path):
    root = tmp_path / "results"
    _write(root, "validation", "validation", Truth(), seed=5, participants=6)
    _write(root, "validation-12", "validation-12", Truth(), seed=6, participants=5)
    for folder in (root / "validation-12").iterdir():  # other people
        for f in folder.iterdir():
            if f.name == "trials.csv":
                f.write_text(f.read_text().replace(f"{folder.name},", f"Q{folder.name[1:]},"))
        folder.rename(folder.with_name(f"Q{folder.name[1:]}"))
    run_analysis(root, tmp_path / "r", figures=False)
    (diff,) = _csv(tmp_path / "r" / "tables" / "impulses-difference.csv")
    assert diff["test"] == "Welch (participant means)" and diff["n"] == "5+6"  # 12 first
    assert 0 <= float(diff["p"]) <= 1


def test_one_impulse_count_has_no_section(tmp_path):
    root = tmp_path / "results"
    _write(root, "validation", "validation", Truth(), seed=7, participants=4)
    run_analysis(root, tmp_path / "r", figures=False)
    assert "Impulses per kernel" not in (tmp_path / "r" / "report.md").read_text()
    assert not (tmp_path / "r" / "tables" / "impulses-difference.csv").exists()
