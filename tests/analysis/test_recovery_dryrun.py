"""Recovery through the real runner: dry-run sessions of simulated participants with a known
ground truth, chained calibration-fe -> calibration-sk -> calibration-sf (paper section 5.2) and
analysed with ``fovexp analyze``, give back that truth's Table 2 (section 5.3); a validation dry
run with a known ours-vs-contrast difference gives the t-test of section 6.1.

Unlike tests/test_analysis_calibration.py (trial logs written directly), every trial here is run
by ``fovexp run --dry-run`` (PsychoPy window under Xvfb, simulated gaze, simulated participant
turning the wheel towards ``--sim-truth``), so the chain between the protocols (f_e read from the
calibration-fe results, s_k from the calibration-sk line), the logs and the analysis are tested
together.

Design (kept small for CI; copies of the protocols with fewer images, no practice, a 160x90
window, two sessions at a time; a session's start-up costs more than its trials, so few
participants with several trials each): 4 participants; calibration-fe 3 images x 3 blur-rates
(9 trials each), calibration-sk 2 images x 3 blur-rates x the 4 s_f levels (24), calibration-sf
3 images x 3 blur-rates (9). The simulated participant has no personal offset, only per-trial
noise, so the precision depends on the trials per condition (12 for f_e and s_f, 8 per s_f level
for s_k), not on how they are split between participants.

Ground truth (:data:`TRUTH`): a Table 2 unlike the paper's (f_e 0.10/0.18/0.32, s_k 30/24/12,
s_f 1.6/2.8/4.5 at blur-rates 0.11/0.34/0.57), s_k falling with s_f at slope -2 in
calibration-sk, and the runner's default participant noise (per-trial sd 0.02 for f_e, 1.5 for
s_k, 0.25 for s_f, plus the stop within half a fine step).

Tolerance (docs/ANALYSIS.md, "Recovery through the runner"): every Table 2 entry within
|f_e error| <= 0.021, |s_k error| <= 1.25, |s_f error| <= 0.27, and the s_k slopes within 0.45.
For this design the expected (rms) errors per entry are 0.0058, 0.34 and 0.072 (slope 0.12); the
tolerances are the 99.9 % quantiles (rounded up) of the largest of the three blur-rates' errors
in a Monte Carlo of the same design and noise (20000 studies), i.e. about 3.6 standard errors, so
a correct chain fails on fewer than 1 in 1000 seeds. They are less than half the distance
between this truth and the paper's Table 2 in at least one entry per parameter, so a runner that
ignored ``--sim-truth`` (its default truth is the paper's table) fails
(:func:`test_truth_is_far_from_the_paper`).
"""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from fovexp import PAPER_TABLE2, ParameterTable
from fovexp.experiment.records.logs import read_trials

from dry_run_study import IMAGES, NOISE, PARTICIPANTS, SK_SLOPE, TRUTH
from dry_run_study import analyze_all as _analyze
from dry_run_study import read_csv as _csv
from dry_run_study import run_all as _run_all
from dry_run_study import shrink as _shrink
from experiment_helpers import make_workspace, xvfb_display  # noqa: F401

pytestmark = [pytest.mark.gui, pytest.mark.slow]

# The ground truth, the design and the runs: tests/dry_run_study.py (shared with the BIDS
# export's tests, made once per test session).
TOLERANCE = {"f_e": 0.021, "s_k": 1.25, "s_f": 0.27}
SLOPE_TOLERANCE = 0.45

#: validation truth: highest invisible blur-rate per method (ours 1.5 x contrast)
VALIDATION_TRUTH = {"contrast": 0.30, "ours": 0.45}
VALIDATION_PARTICIPANTS = ["V01", "V02", "V03"]


@pytest.fixture
def calibration(dry_run_calibration: Path) -> Path:
    """The three calibration experiments dry-run in order, then ``fovexp analyze``
    (tests/dry_run_study.py)."""
    return dry_run_calibration


def test_truth_is_far_from_the_paper() -> None:
    """Guard: recovering TRUTH within the tolerance is impossible from the paper's Table 2 (the
    simulated participant's default truth), so the recovery test can fail."""
    for k, key in enumerate(("f_e", "s_k", "s_f")):
        gaps = [abs(TRUTH.at(br)[k] - PAPER_TABLE2.at(br)[k]) for br in (0.11, 0.34, 0.57)]
        assert max(gaps) > 2 * TOLERANCE[key], key


def test_recovered_table2(calibration: Path) -> None:
    report = calibration / "report"
    table = ParameterTable.load(report / "table2.yaml")
    assert [r.blur_rate for r in table.rows] == [0.11, 0.34, 0.57]
    sem = {float(r["blur_rate"]): r for r in _csv(report / "tables" / "table2.csv")}
    errors: dict[str, float] = {}
    for row in table.rows:
        true = dict(zip(("f_e", "s_k", "s_f"), TRUTH.at(row.blur_rate), strict=True))
        for key in ("f_e", "s_k", "s_f"):
            got = getattr(row, key)
            err = got - true[key]
            errors[f"{key}@{row.blur_rate:g}"] = round(err, 4)
            assert abs(err) <= TOLERANCE[key], (key, row.blur_rate, got, true[key])
            # The CSV (full precision, with SEMs) agrees with the YAML the enhancer reads.
            assert float(sem[row.blur_rate][key]) == pytest.approx(got, rel=1e-5)
            assert float(sem[row.blur_rate][f"{key}_sem"]) > 0
    print("recovery errors (recovered - truth):", errors)


def test_recovered_sk_lines(calibration: Path) -> None:
    """calibration-sk's lines: slope SK_SLOPE, through the truth's (s_f, s_k) per blur-rate."""
    lines = _csv(calibration / "report" / "tables" / "calibration-sk-lines.csv")
    assert len(lines) == 3
    for ln in lines:
        br = float(ln["blur_rate"])
        _, s_k, s_f = TRUTH.at(br)
        assert float(ln["n_levels"]) == 4
        assert abs(float(ln["slope"]) - SK_SLOPE) <= SLOPE_TOLERANCE, ln
        line_at = float(ln["slope"]) * s_f + float(ln["intercept"])
        assert abs(line_at - s_k) <= TOLERANCE["s_k"], ln


def test_chain_used_earlier_results(calibration: Path) -> None:
    """The runner set calibration-sk's f_e and calibration-sf's s_k from the earlier dry runs'
    results, with the same numbers the analysis reports (the contract of section 5.2)."""
    report = calibration / "report" / "tables"
    fe = {float(r["blur_rate"]): float(r["mean"]) for r in _csv(report / "calibration-fe.csv")}
    lines = {float(r["blur_rate"]): (float(r["slope"]), float(r["intercept"]))
             for r in _csv(report / "calibration-sk-lines.csv")}
    for pid in PARTICIPANTS:
        rows, _ = read_trials(calibration / "results" / "calibration-sk" / pid / "trials.csv")
        for r in rows:
            assert r["f_e"] == pytest.approx(fe[r["blur_rate"]], rel=1e-5)
        rows, _ = read_trials(calibration / "results" / "calibration-sf" / pid / "trials.csv")
        for r in rows:
            slope, icpt = lines[r["blur_rate"]]
            assert r["f_e"] == pytest.approx(fe[r["blur_rate"]], rel=1e-5)
            assert r["s_k"] == pytest.approx(slope * r["s_f"] + icpt, rel=1e-5)


def test_validation_ttest(tmp_path_factory, xvfb_display) -> None:  # noqa: F811
    """Validation (section 6.1): simulated participants whose highest invisible blur-rate is 0.30
    with contrast and 0.45 with ours (sd 0.04 per trial). 3 participants x 4 scenes = 12 pairs:
    the expected SE of a method's mean is 0.012 and of the mean difference 0.016; tolerances 0.045
    (means) and 0.06 (difference), about 3.7 SE. The paired t-test must find ours > contrast
    (t about 9, p < 0.001); the sampling-rate reduction 1 - 0.30/0.45 = 33.3 % within 10
    percentage points (SE about 3)."""
    ws = make_workspace(tmp_path_factory.mktemp("recovery-val") / "project")
    truth = ws / "truth.yaml"
    truth.write_text(yaml.safe_dump({"validation_blur_rate": VALIDATION_TRUTH,
                                     "noise_sd": NOISE}))
    _shrink(ws, "validation")
    _run_all(ws, "validation", VALIDATION_PARTICIPANTS, truth)
    out = ws / "report"
    _analyze(ws, out)
    tables = out / "tables"
    overall = {r["method"]: r for r in _csv(tables / "validation-overall.csv")}
    for method, true in VALIDATION_TRUTH.items():
        assert abs(float(overall[method]["mean"]) - true) <= 0.045, overall[method]
        assert int(overall[method]["n"]) == len(VALIDATION_PARTICIPANTS)
    tests = {r["scope"]: r for r in _csv(tables / "validation-tests.csv")}
    main = tests["all scenes"]
    assert int(main["n"]) == 12 and int(main["df"]) == 11
    diff = VALIDATION_TRUTH["ours"] - VALIDATION_TRUTH["contrast"]
    assert abs(float(main["mean_diff"]) - diff) <= 0.06, main
    assert float(main["t"]) > 0 and float(main["p"]) < 1e-3, main
    assert float(main["ci_low"]) > 0
    assert int(tests["participant means"]["n"]) == len(VALIDATION_PARTICIPANTS)
    assert {s for s in tests if s.startswith("scene-")} == set(IMAGES["validation"])
    sampling = {r["scope"]: r for r in _csv(tables / "validation-sampling.csv")}
    true_pct = 100 * (1 - VALIDATION_TRUTH["contrast"] / VALIDATION_TRUTH["ours"])
    assert abs(float(sampling["all scenes"]["reduction_pct"]) - true_pct) <= 10.0
    print("validation:", {k: round(float(main[k]), 4) for k in ("mean_diff", "t", "p")},
          "reduction_pct", round(float(sampling["all scenes"]["reduction_pct"]), 2))
