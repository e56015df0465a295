"""End to end: ``python -m analysis`` / ``fovexp analyze`` on simulated logs -> report folder;
clear errors (one line, exit status 2) for bad input."""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

import pytest

from fovexp import ParameterTable
from fovexp.analysis.cli import add_analyze_parser, analyze_command, main
from fovexp.analysis.report import run_analysis

from analysis_fixtures import Truth, write_study


@pytest.fixture(scope="module")
def results(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_study(tmp_path_factory.mktemp("results"), n_participants=6, seed=2)


def test_cli_writes_the_report(results: Path, tmp_path: Path,
                               capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "report"
    assert main([str(results), "--out", str(out), "--table-out", str(tmp_path / "t.yaml")]) == 0
    printed = capsys.readouterr().out
    assert "report:" in printed and "table2.yaml" in printed
    for name in ("report.md", "table2.yaml", "tables/table2.csv", "tables/table2.md",
                 "tables/table2.tex", "tables/calibration-sk-lines.csv",
                 "tables/validation-tests.csv", "tables/validation-sampling.csv",
                 "tables/exclusions.csv", "figures/calibration.png", "figures/calibration.pdf",
                 "figures/validation.png", "figures/validation.pdf",
                 "figures/validation-sampling.png"):
        assert (out / name).is_file(), name
        assert (out / name).stat().st_size > 0, name
    # Table 2 in the enhancer's format exists once (one source string).
    assert not (out / "tables" / "table2.yaml").exists()
    assert len(list(out.rglob("table2.yaml"))) == 1
    assert (tmp_path / "t.yaml").read_bytes() == (out / "table2.yaml").read_bytes()
    assert (out / "figures/calibration.png").read_bytes()[:4] == b"\x89PNG"
    assert (out / "figures/validation.pdf").read_bytes()[:4] == b"%PDF"
    report = (out / "report.md").read_text()
    for heading in ("## Calibration (section 5.3)", "### Table 2", "## Validation: validation",
                    "### Paired t-test, ours vs contrast", "sampling-rate reduction",
                    "## Exclusions", "R4 practice", "R9 incomplete session"):
        assert heading in report, heading
    # 2 practice trials per session, 6 participants x 4 experiments
    assert "| R4 practice | 48 |" in report
    # the lab's table replaces the paper's: the enhancer's loader reads it
    table = ParameterTable.load(tmp_path / "t.yaml")
    assert ParameterTable.load(out / "table2.yaml").rows == table.rows
    assert table.at(0.34)[0] == pytest.approx(Truth().f_e[0.34], abs=0.03)


def test_validation_only_and_partial_calibration(results: Path, tmp_path: Path) -> None:
    ana = run_analysis(results / "validation", tmp_path / "v", figures=False)
    assert ana.calibration is None and len(ana.validations) == 1
    tests = ana.validations[0].tests.set_index("scope")
    assert tests.loc["all scenes", "p"] < 1e-3 and tests.loc["all scenes", "mean_diff"] > 0
    # truth: ours = contrast x 1.25 -> sampling-rate reduction 20 %
    red = ana.validations[0].sampling.set_index("scope").loc["all scenes", "reduction_pct"]
    assert red == pytest.approx(20.0, abs=3.0)
    part = tmp_path / "part"
    shutil.copytree(results / "calibration-fe", part / "calibration-fe")
    ana = run_analysis(part, tmp_path / "p", figures=False)
    assert ana.calibration is None
    assert "missing: calibration-sk, calibration-sf" in ana.report.read_text()


@pytest.mark.parametrize("setup,message", [
    ("empty", "no trials.csv found"),
    ("corrupt", "line 3: column final_value: 'x' is not a number"),
])
def test_cli_errors_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                 setup: str, message: str) -> None:
    root = tmp_path / "results"
    root.mkdir()
    if setup == "corrupt":
        write_study(root, n_participants=1, experiments=("calibration-fe",))
        path = root / "calibration-fe" / "P01" / "trials.csv"
        lines = path.read_text().splitlines()
        lines[2] = ",".join(lines[2].split(",")[:15] + ["x"] + lines[2].split(",")[16:])
        path.write_text("\n".join(lines) + "\n")
    assert main([str(root), "--out", str(tmp_path / "out"), "--no-figures"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and message in err[0]
    if setup == "corrupt":
        assert "calibration-fe/P01/trials.csv" in err[0]


def test_bad_protocol_option(results: Path, tmp_path: Path,
                             capsys: pytest.CaptureFixture[str]) -> None:
    assert main([str(results), "--out", str(tmp_path), "--protocol", "nohash"]) == 2
    assert "EXPERIMENT=SHA256" in capsys.readouterr().err


def test_add_analyze_parser(results: Path, tmp_path: Path) -> None:
    parser = argparse.ArgumentParser(prog="fovexp")
    add_analyze_parser(parser.add_subparsers(dest="command"))
    args = parser.parse_args(["analyze", str(results / "validation"), "--out",
                              str(tmp_path / "r"), "--no-figures"])
    assert args.func is analyze_command
    assert args.func(args) == 0
    assert (tmp_path / "r" / "report.md").is_file()


def test_report_lists_exclusions(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    root = write_study(tmp_path / "results", n_participants=3, experiments=("validation",))
    p3 = root / "validation" / "P03"
    info = next(p3.glob("session-*.json"))
    info.write_text(info.read_text().replace('"completed": true', '"completed": false'))
    torn = root / "validation" / "P02" / "trials.csv"
    torn.write_text(torn.read_text()[:-30])
    out = tmp_path / "out"
    assert main([str(root), "--out", str(out), "--no-figures"]) == 0
    captured = capsys.readouterr()
    assert "warning:" in captured.err and "torn last row" in captured.err
    report = (out / "report.md").read_text()
    assert "| R1 torn last row | 1 |" in report and "| R9 incomplete session | 20 |" in report
    assert "validation/P03/trials.csv" in report  # the details name the file
    assert main([str(root), "--out", str(out), "--no-figures", "--include-incomplete"]) == 0
    report = (out / "report.md").read_text()
    assert "kept (--include-incomplete)" in report
    summary = (out / "tables" / "validation-summary.csv").read_text()
    assert ",3," in summary  # three participants again
