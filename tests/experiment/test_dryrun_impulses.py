"""Dry runs of both validations (paper section 6.3): ``validation`` (64 impulses per kernel)
and ``validation-12`` (12, otherwise identical), then ``fovexp analyze`` on both, whose report
compares the advantage of ours over contrast at the two counts.

The simulated participants' truth does not depend on the impulse count (docs/EXPERIMENT.md,
"Dry runs"): the same truth file serves both, which models the paper's finding that 12
impulses keep the advantage."""

from __future__ import annotations

import csv
import json

import pytest

from experiment_helpers import xvfb_display  # noqa: F401

pytestmark = [pytest.mark.gui, pytest.mark.slow]


def test_both_validations_dry_run_and_the_report_compares_them(dry_run_validations):
    """One participant, two scenes each, the same truth, analysed by ``fovexp analyze``
    (tests/dry_run_study.py: the dry runs and their report are the test session's, shared with
    the BIDS export's tests)."""
    ws = dry_run_validations
    info = json.loads(next((ws / "results" / "validation-12" / "S01").glob(
        "session-*.json")).read_text())
    assert "impulses: 12" in info["protocol"]
    md = (ws / "report" / "report.md").read_text()
    assert "## Validation: validation-12" in md
    assert "## Impulses per kernel: 12 against 64" in md
    per = list(csv.DictReader((ws / "report" / "tables" / "impulses-per-count.csv").open()))
    assert sorted(int(r["impulses"]) for r in per) == [12, 64]
    assert all(float(r["mean_diff"]) > 0.15 for r in per)  # ours 0.5 against contrast 0.3
    (diff,) = csv.DictReader((ws / "report" / "tables" / "impulses-difference.csv").open())
    assert diff["test"] == "paired (participant x scene)" and diff["n"] == "2"
    assert abs(float(diff["mean_diff"])) < 0.02  # the same truth at both counts
