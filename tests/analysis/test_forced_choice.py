"""The forced-choice analysis (issue 30, section 3): the fits of :mod:`fovexp.analysis.fits`
on answers from a known function, the posterior of a difference, the section on a results
folder written in the log format (forced-choice rows beside an adjustment validation), and its
figures' layout. Window-free: the answers come from the simulated observer directly."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from fovexp import FovexpError
from fovexp.analysis import figures
from fovexp.analysis.fits import fit_ml, fit_psignifit, posterior_difference
from fovexp.analysis.report import run_analysis
from fovexp.analysis.sections.forced_choice import (
    adjustment_plot,
    compare_methods,
    fit_thresholds,
    psychometric_plot,
    threshold_plot,
)
from fovexp.analysis.stats import paired_ttest
from fovexp.experiment.tasks.procedures import QuestPlusArrays, geometric_grid
from fovexp.experiment.tasks.simulated_observer import SimulatedObserver, simulate_answers
from fovexp.experiment.tasks.simulated_participant import SimTruth
from fovexp.results.choices import FORCED_CHOICE_COLUMNS, with_choices
from fovexp.results.loading import COLUMNS

from analysis_fixtures import SHA, write_study, write_trials

GRID = geometric_grid(0.05, 2.0, 25)
TRUTH = {"foveated": 0.25, "contrast": 0.4, "ours": 0.6}


def _constant_stimuli(threshold: float, n_per_level: int, seed: int
                      ) -> tuple[np.ndarray, np.ndarray]:
    obs = SimulatedObserver(SimTruth(validation_blur_rate={"m": threshold}), seed)
    levels = np.repeat(GRID[6:22], n_per_level)
    correct = np.array([obs.answer("m", float(b), "left") == "left" for b in levels])
    return levels, correct


def test_the_ml_fit_finds_a_known_threshold_and_its_interval_holds_it() -> None:
    b, c = _constant_stimuli(0.4, 100, seed=1)
    f = fit_ml(b, c, n_boot=300, seed=2)
    assert f.threshold_arcmin_per_deg == pytest.approx(0.4, rel=0.08)
    assert f.ci_low_arcmin_per_deg < 0.4 < f.ci_high_arcmin_per_deg
    assert f.ci_high_arcmin_per_deg / f.ci_low_arcmin_per_deg < 1.5
    assert 1.5 < f.slope < 6 and f.lapse == 0.02 and f.n_trials == b.size
    free = fit_ml(b, c, lapse=None, n_boot=100)
    assert 0.0 <= free.lapse <= 0.06
    assert free.threshold_arcmin_per_deg == pytest.approx(0.4, rel=0.1)


def test_a_fit_needs_two_blur_rates() -> None:
    with pytest.raises(FovexpError, match="two blur-rates or more, got 1"):
        fit_ml([0.3, 0.3, 0.3], [True, False, True])


@pytest.mark.slow
def test_psignifit_agrees_with_the_ml_fit_on_many_trials() -> None:
    pytest.importorskip("psignifit", reason="psignifit comes with the [psignifit] extra")
    b, c = _constant_stimuli(0.4, 40, seed=1)
    ml = fit_ml(b, c, n_boot=100)
    ps = fit_psignifit(b, c, grid_arcmin_per_deg=(GRID[0], GRID[-1]))
    assert ps.fit == "psignifit"
    assert ps.threshold_arcmin_per_deg == pytest.approx(ml.threshold_arcmin_per_deg, rel=0.05)
    assert ps.ci_low_arcmin_per_deg < 0.4 < ps.ci_high_arcmin_per_deg


def test_the_posterior_of_a_difference_is_the_t_interval_under_its_prior() -> None:
    """Under p(mu, sigma) ~ 1/sigma the 95 % credible interval of the mean is the paired
    t-test's confidence interval (Gelman et al., BDA3, section 3.2)."""
    d = np.array([0.1, 0.25, 0.05, 0.3, 0.18])
    post = posterior_difference(d)
    tt = paired_ttest(d, np.zeros_like(d))
    assert (post.ci_low, post.ci_high) == pytest.approx((tt.ci_low, tt.ci_high))
    assert post.p_positive == pytest.approx(1 - tt.p / 2)
    assert math.isnan(posterior_difference([0.1]).ci_low)


def _fc_rows(participant: str, seed: int, n: int, session: str) -> list[dict]:
    truth = SimTruth(validation_blur_rate=TRUTH)
    procs = {m: QuestPlusArrays(GRID, (1.0, 2.0, 3.0, 5.0), (0.02,)) for m in TRUTH}
    rows = []
    for i, r in enumerate(simulate_answers(truth, procs, n, seed)):
        rows.append({
            "participant": participant, "session": session, "experiment": "validation-2afc",
            "protocol_sha256": SHA, "trial_index": i, "practice": 0, "repetition": 0,
            "image": "scene-05", "blur_rate": r["blur_rate"], "method": r["method"],
            "adjusted_parameter": "blur_rate", "final_value": r["blur_rate"],
            "response_time_s": 0.5, "blanked_fraction": 0.0, "dropped_frames": 0,
            "tracker": "simulated", "seed": 7, "software_version": "0.1.0",
            "timestamp": f"2026-11-27T10:{i // 60:02d}:{i % 60:02d}",
            "task": "2afc", "degraded_side": r["degraded_side"], "answer": r["answer"],
            "correct": int(r["correct"]), "presentation_s": 1.5, "procedure": "questplus",
            "grid_index": GRID.index(r["blur_rate"])})
    return rows


@pytest.mark.slow
def test_the_section_reports_thresholds_methods_and_the_adjustment(tmp_path: Path) -> None:
    """A results folder with an adjustment validation and a forced-choice experiment for the
    same participants: the validation section keeps to its experiment, the forced-choice one
    fits, compares and sets the two tasks side by side."""
    root = write_study(tmp_path / "results", n_participants=2, experiments=("validation",))
    for k in range(2):
        pid = f"P{k + 1:02d}"
        write_trials(root / "validation-2afc" / pid,
                     _fc_rows(pid, k, 30, f"20261127-10{k:02d}00"),
                     columns=(*COLUMNS, *FORCED_CHOICE_COLUMNS))
    # the figures are the next test's (the report's writing of them: every section's)
    ana = run_analysis(root, tmp_path / "report", figures=False)
    report = ana.report.read_text()
    assert "## Forced choice: validation-2afc" in report
    assert "measured by this task, not by adjustment" in report
    assert "Validation: validation-2afc" not in report  # not an adjustment validation
    assert "### Beside the adjustment task" in report
    assert "extra columns ignored" not in report  # the answers are read, not ignored
    assert "not analysed" not in report
    assert "Task: adjustment" in report  # which task measured what
    for name in ("thresholds", "methods", "adjustment"):
        assert (ana.tables / f"validation-2afc-{name}.csv").is_file()
    choices = with_choices(ana.data.trials)
    assert len(choices) == 2 * 3 * 30 and choices["correct"].dtype == bool
    thr = pd.read_csv(ana.tables / "validation-2afc-thresholds.csv")
    assert set(thr["method"]) == set(TRUTH) and (thr["ci_low"] < thr["ci_high"]).all()


@pytest.mark.slow
def test_the_figures_keep_their_texts_apart() -> None:
    rows = [r for k in range(5) for r in _fc_rows(f"P{k:02d}", k, 20, "20261127-100000")]
    choices = with_choices_frame(rows)
    thr = fit_thresholds(choices, n_boot=50, psignifit=False)
    assert len(compare_methods(thr)) == 3
    both = pd.DataFrame({"participant": ["P00", "P01", "P02"], "method": ["ours"] * 3,
                         "adjusted": [0.5, 0.6, 0.7], "forced_choice": [0.4, 0.65, 0.8]})
    for fig in (psychometric_plot(choices, thr, "validation-2afc"),
                threshold_plot(thr, "validation-2afc"),
                adjustment_plot(both, 0.9, "validation-2afc")):
        assert figures.text_problems(fig) == []


def with_choices_frame(rows: list[dict]) -> pd.DataFrame:
    frame = pd.DataFrame(rows)
    frame["correct"] = frame["correct"].astype(bool)
    frame["practice"] = frame["practice"].astype(bool)
    return frame


def test_without_psignifit_the_fit_names_its_extra_and_the_report_goes_on(monkeypatch) -> None:
    import sys

    from fovexp.analysis.fits import psignifit_available

    monkeypatch.setitem(sys.modules, "psignifit", None)  # import fails as if not installed
    assert not psignifit_available()
    b, c = _constant_stimuli(0.4, 5, seed=3)
    with pytest.raises(FovexpError, match=r"pip install 'fovexp\[psignifit\]'"):
        fit_psignifit(b, c)
    rows = with_choices_frame(_fc_rows("P01", 0, 15, "20261127-100000"))
    assert set(fit_thresholds(rows, n_boot=20)["fit"]) == {"ml-bootstrap"}


def test_without_questplus_the_task_names_the_experiment_extra(monkeypatch) -> None:
    import sys

    from fovexp.experiment.tasks.procedures import QuestPlus

    monkeypatch.setitem(sys.modules, "questplus", None)
    with pytest.raises(FovexpError, match=r"pip install 'fovexp\[experiment\]'"):
        QuestPlus(GRID, (1.0, 2.0), (0.02,))
