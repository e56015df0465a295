"""``fovexp export bids`` (docs/SHARING.md) on the test session's dry-run study
(tests/dry_run_study.py: the three calibration experiments, ``validation`` and
``validation-12``): the official validator accepts the dataset with no error; ``fovexp
analyze`` reads it back into the same Table 2, t-tests and exclusions; the logs come back value
for value; the same results give the same bytes; an edited dataset is reported; bad input is
left out with one line each."""

from __future__ import annotations

import csv
import filecmp
import gzip
import json
import os
import shutil
from pathlib import Path

import pytest

from fovexp import FovexpError
from fovexp.cli import main as fovexp_main
from fovexp.export import bids as export
from fovexp.results.bids import read_bids
from fovexp.results.format import FRAME_COLUMNS
from fovexp.results.loading import load_results

from experiment_helpers import xvfb_display  # noqa: F401  (the dry-run study's)

#: The validator's warnings docs/SHARING.md explains ("What the validator still says"), each
#: by its code and the key it is about: everything else it could say is fixed.
EXPLAINED = {
    ("JSON_KEY_RECOMMENDED", "HEDVersion"),
    ("JSON_KEY_RECOMMENDED", "SourceDatasets"),
    ("SIDECAR_KEY_RECOMMENDED", "CogAtlasID"),
    ("SIDECAR_KEY_RECOMMENDED", "CogPOID"),
}
#: the analysis under derivatives/ is left out here (the small exports below have it): the
#: round trip analyses the dataset itself
STUDY_OPTIONS = ["--include-dry-runs", "--author", "A. Researcher", "--author",
                 "B. Researcher", "--license", "CC0", "--institution", "A University",
                 "--institution-address", "1 Example Street, A Town", "--department",
                 "Perception Lab", "--no-analysis"]


def _copy_results(src: Path, dest: Path, experiments: list[str] | None = None) -> None:
    for exp in sorted(src.iterdir()):
        if exp.is_dir() and (experiments is None or exp.name in experiments):
            shutil.copytree(exp, dest / exp.name,
                            ignore=shutil.ignore_patterns(".fovexp-run.lock", "live-*.json"))


@pytest.fixture(scope="module")
def study(tmp_path_factory, dry_run_calibration, dry_run_validations) -> Path:
    """One results folder with the dry runs of the four paper protocols and validation-12."""
    root = tmp_path_factory.mktemp("study") / "results"
    _copy_results(dry_run_calibration / "results", root)
    _copy_results(dry_run_validations / "results", root)
    assert sorted(p.name for p in root.iterdir()) == [
        "calibration-fe", "calibration-sf", "calibration-sk", "validation", "validation-12"]
    return root


@pytest.fixture(scope="module")
def dataset(study, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("bids") / "dataset"
    assert fovexp_main(["export", "bids", str(study), str(out), *STUDY_OPTIONS]) == 0
    return out


def _validator_or_skip() -> None:
    if export.validator_path() is None:
        why = f"{export.VALIDATOR} is not installed (pip install 'fovexp[bids]')"
        if os.environ.get("FOVEXP_REQUIRE_BIDS_VALIDATOR") == "1":
            pytest.fail(f"FOVEXP_REQUIRE_BIDS_VALIDATOR=1 but {why}")
        pytest.skip(why)


@pytest.mark.gui
@pytest.mark.slow
def test_the_validator_accepts_the_dry_run_study(dataset):
    _validator_or_skip()
    verdict = export.validate(dataset)
    assert verdict.errors == []
    unexplained = {(code, key) for _, code, key, _ in verdict.warnings} - EXPLAINED
    assert unexplained == set()
    print(f"{export.VALIDATOR}: {len(verdict.errors)} errors, {len(verdict.warnings)} "
          f"warnings ({sorted({(c, k) for _, c, k, _ in verdict.warnings})})")


def _rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.mark.gui
@pytest.mark.slow
def test_analyze_reads_the_dataset_into_the_same_results(dry_run_calibration,
                                                         dry_run_validations, dataset, tmp_path):
    """Table 2, the t-tests, every table and the exclusions, to the last digit: the dataset's
    analysis against the study's own (``fovexp analyze`` of the calibration's and of the
    validations' results folders, tests/dry_run_study.py)."""
    assert fovexp_main(["analyze", str(dataset), "--out", str(tmp_path / "b"),
                        "--no-figures"]) == 0
    got = tmp_path / "b" / "tables"
    originals = [ws / "report" / "tables" for ws in (dry_run_calibration, dry_run_validations)]
    names = sorted({p.name for t in originals for p in t.glob("*.csv")})
    assert names == sorted(p.name for p in got.glob("*.csv"))
    assert {"table2.csv", "validation-tests.csv", "validation-12-tests.csv",
            "impulses-difference.csv", "exclusions.csv"} <= set(names)
    for name in names:
        if name in ("latency.csv", "gating.csv", "exclusions.csv"):  # a row per session
            rows = sorted(map(str, _rows(got / name)))
            assert rows == sorted(str(r) for t in originals if (t / name).exists()
                                  for r in _rows(t / name)), name
        else:  # one study's own
            (original,) = [t / name for t in originals if (t / name).exists()]
            assert original.read_bytes() == (got / name).read_bytes(), name
    assert (dry_run_calibration / "report" / "table2.yaml").read_text().split("rows:")[1] == \
        (tmp_path / "b" / "table2.yaml").read_text().split("rows:")[1]


@pytest.mark.gui
@pytest.mark.slow
def test_the_logs_come_back_value_for_value(study, dataset, tmp_path):
    """trials.csv, the gaze samples, the frame log and the blanking episodes: byte for byte."""
    source = read_bids(dataset, tmp_path / "back")
    back = source.results
    assert source.changed == []
    originals = sorted(p.relative_to(study) for p in study.rglob("*.csv"))
    assert originals == sorted(p.relative_to(back) for p in back.rglob("*.csv"))
    for rel in originals:
        assert filecmp.cmp(study / rel, back / rel, shallow=False), rel
    # the events, on the gaze's clock: onsets in order, one row per trial
    events = next((dataset / "sub-R01" / "beh").glob("*task-calibrationfe_events.tsv"))
    head, *rows = [ln.split("\t") for ln in events.read_text().splitlines()]
    assert head[:3] == ["onset", "duration", "trial_type"]
    onsets = [float(r[0]) for r in rows]
    assert onsets == sorted(onsets) and onsets[0] >= 0 and len(rows) == 9
    sidecar = json.loads(events.with_suffix(".json").read_text())
    assert set(sidecar["StimulusPresentation"]) >= {"ScreenDistance", "ScreenOrigin",
                                                    "ScreenResolution", "ScreenSize"}
    assert sidecar["StimulusPresentation"]["ScreenDistance"] == pytest.approx(0.715)


@pytest.mark.gui
@pytest.mark.slow
def test_same_results_same_bytes_and_no_overwrite(study, tmp_path):
    args = ["export", "bids", str(study), "--participant", "R01", "--experiment",
            "calibration-fe", "--include-dry-runs"]
    assert fovexp_main([*args[:3], str(tmp_path / "one"), *args[3:]]) == 0
    assert fovexp_main([*args[:3], str(tmp_path / "two"), *args[3:]]) == 0
    one, two = tmp_path / "one", tmp_path / "two"
    files = sorted(p.relative_to(one) for p in one.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(two) for p in two.rglob("*") if p.is_file())
    assert all((one / f).read_bytes() == (two / f).read_bytes() for f in files)
    gz = next(one.rglob("*_physio.tsv.gz")).read_bytes()
    assert gz[4:8] == b"\0\0\0\0"  # gzip's MTIME field: no time stamp
    with pytest.raises(FovexpError, match="exists; --replace replaces it"):
        export.export_bids(study, one, participants=["R01"], include_dry_runs=True)
    # the dataset's analysis: the report without the machine's paths or the time it ran
    report = (one / "derivatives" / "fovexp" / "report.md").read_text()
    assert "calibration-fe" in report and "dry runs" in report
    assert "Generated" not in report and str(study) not in report
    assert fovexp_main([*args[:3], str(one), *args[3:], "--replace", "--no-analysis"]) == 0
    assert not (one / "derivatives").exists()


@pytest.mark.gui
@pytest.mark.slow
def test_an_edited_dataset_is_reported(study, tmp_path):
    copy = tmp_path / "edited"
    export.export_bids(study, copy, participants=["R02"], experiments=["calibration-sf"],
                       include_dry_runs=True, analysis=False)
    assert not [n for n in load_results(copy).notes if "since the export" in n]
    events = next((copy / "sub-R02" / "beh").glob("*calibrationsf_events.tsv"))
    events.write_text("".join(events.read_text().splitlines(keepends=True)[:-1]))
    physio = next((copy / "sub-R02" / "beh").glob("*calibrationsf_recording-eye2_physio.json"))
    meta = json.loads(physio.read_text())
    meta["SamplingFrequency"] = 300
    physio.write_text(json.dumps(meta))
    with pytest.warns(UserWarning, match="2 file\\(s\\) changed since fovexp exported it"):
        data = load_results(copy)
    changed = [n for n in data.notes if "changed since the export" in n]
    assert len(changed) == 2
    assert any(events.name in n for n in changed) and any(physio.name in n for n in changed)


@pytest.mark.gui
@pytest.mark.slow
def test_dates_shifted_and_no_local_paths(study, dry_run_scenes, tmp_path):
    out = tmp_path / "public"
    report = export.export_bids(study, out, participants=["R01"], experiments=["calibration-fe"],
                                include_dry_runs=True, shift_dates_days=40000, analysis=False)
    assert report.sessions == 1
    session = json.loads(next((out / "sourcedata").rglob("*_session.json")).read_text())
    original = session["session"]
    texts = []
    for path in out.rglob("*"):
        if path.suffix in (".json", ".tsv", ".md", ".txt"):
            texts.append(path.read_text())
        elif path.name.endswith(".tsv.gz"):
            texts.append(gzip.decompress(path.read_bytes()).decode())
    blob = "\n".join(texts)
    for real in (str(study.parent), str(dry_run_scenes), "2026-", "2025-"):
        assert real not in blob, real
    assert original.startswith("19") and session["started"].startswith("19")
    (scans,) = out.glob("sub-R01/*_scans.tsv")
    assert scans.read_text().splitlines()[1].split("\t")[1] < "1925"


@pytest.mark.gui
@pytest.mark.slow
def test_bad_input_is_left_out_with_one_line_each(dry_run_calibration, tmp_path, capsys):
    src = dry_run_calibration / "results" / "calibration-fe"
    root = tmp_path / "results" / "calibration-fe"
    for pid in ("R01", "R02", "R03", "R04"):
        shutil.copytree(src / pid, root / pid, ignore=shutil.ignore_patterns(".fovexp-run.lock"))
    (next((root / "R02").glob("gaze-*.csv"))).unlink()  # a missing gaze file
    frames = next((root / "R03").glob("frames-*.csv"))  # a frame log before version 1
    rows = list(csv.reader(frames.open()))
    with frames.open("w", newline="") as fh:
        csv.writer(fh, lineterminator="\n").writerows(r[:8] for r in rows)
    assert rows[0][:8] == list(FRAME_COLUMNS[:8])
    trials = root / "R04" / "trials.csv"  # a torn session: killed while writing its last row
    trials.write_bytes(trials.read_bytes()[:-20])
    (root / "R05").mkdir()  # a participant with no completed trial
    (root / "R05" / "trials.csv").write_text((root / "R01" / "trials.csv").read_text()
                                             .splitlines(keepends=True)[0])
    out = tmp_path / "dataset"
    code = fovexp_main(["export", "bids", str(tmp_path / "results"), str(out),
                        "--include-dry-runs", "--no-analysis"])
    assert code == 0
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 4 and all("left out" in ln for ln in lines), lines
    for pid, why in (("R02", "no gaze file"), ("R03", "frame log of an older version"),
                     ("R04", "torn session"), ("R05", "participant with no completed trial")):
        (line,) = [ln for ln in lines if f"/{pid}" in ln]
        assert why in line
        assert line.split("left out: ", 1)[1] in (out / "README.md").read_text()
    assert sorted(p.name for p in out.glob("sub-*")) == ["sub-R01"]


def test_dry_runs_are_left_out_unless_asked(tmp_path, capsys):
    """A folder of dry runs alone exports nothing by default, and says how to include them."""
    from analysis_fixtures import Truth, write_study

    write_study(tmp_path / "results", n_participants=1, truth=Truth())
    code = fovexp_main(["export", "bids", str(tmp_path / "results"), str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and "no session to export" in err and "--include-dry-runs" in err
    assert len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()


def test_without_the_validator_the_extra_is_named(monkeypatch, tmp_path):
    monkeypatch.setattr(export, "validator_path", lambda: None)
    with pytest.raises(FovexpError, match=r"pip install 'fovexp\[bids\]'"):
        export.validate(tmp_path)
