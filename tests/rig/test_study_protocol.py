"""``fovexp rig check`` inside a study folder (issue 32): without ``--protocol`` it measures
the study's own protocol (its display, stimuli and tracker), found as every command finds the
study (``find_study``, from the folder or below it), and says which in its report; outside a
study it keeps the shipped validation; ``--protocol`` still chooses. The study is made by the
real ``fovexp init`` code, and names a lab frame instead of the generated scenes: the shipped
validation would fail on their absence there (the issue)."""

from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path

import pytest
import yaml

from fovexp import FovexpError
from fovexp.experiment.protocol.study import init_study
from fovexp.rig import checks as C
from fovexp.rig.cli import DEFAULT_PROTOCOL, rig_protocol, study_protocol
from fovexp.stimuli.folder import DRY_RUN_SIZE, STUDY_FILE

from experiment_helpers import cli, pattern, run_cli, write_png, xvfb_display  # noqa: F401

#: the lab's tracker rate in the study's protocol: not the shipped validation's 600 Hz
STUDY_RATE_HZ = 250


def lab_study(root: Path, name: str = "lab-study", sources: list[str] | None = None) -> Path:
    """``fovexp init`` of ``root/name``, its validation naming one lab frame (``lab-01``, at
    the dry run's size, in the study's ``stimuli/``) and a 250 Hz tracker."""
    init_study(root / name, sources)
    study = root / name
    frame = write_png(study / "stimuli" / "frames" / "lab-01.png",
                      pattern(DRY_RUN_SIZE[1], DRY_RUN_SIZE[0], 7))
    (study / "stimuli" / "manifest.yaml").write_text(yaml.safe_dump({"images": [{
        "id": "lab-01", "path": "frames/lab-01.png", "source": "test", "licence": "CC0-1.0",
        "sha256": hashlib.sha256(frame.read_bytes()).hexdigest()}]}))
    proto = study / "protocols" / f"{name}.yaml"
    text = re.sub(r"^images: \[[^\]]*\]", "images: [lab-01]", proto.read_text(),
                  flags=re.MULTILINE)
    text = text.replace("tracker: {sampling_hz: 600,", f"tracker: {{sampling_hz: {STUDY_RATE_HZ},")
    assert "images: [lab-01]" in text and f"sampling_hz: {STUDY_RATE_HZ}" in text
    proto.write_text(text)
    return study


def test_inside_a_study_its_own_protocol_is_chosen(tmp_path: Path, monkeypatch) -> None:
    study = lab_study(tmp_path)
    own = study / "protocols" / "lab-study.yaml"
    for where in (study, study / "results", study / "stimuli" / "frames"):  # or below it
        monkeypatch.chdir(where)
        path, chosen = rig_protocol(None)
        assert path.resolve() == own.resolve()
        assert chosen == f"the study folder {study.resolve()}'s own"
    # --protocol still chooses (as fovexp run finds it: ./protocols, then the shipped ones)
    monkeypatch.chdir(study)
    path, chosen = rig_protocol("validation")
    assert path.name == "validation.yaml" and chosen == "--protocol validation"
    # outside a study: the shipped validation, as before
    monkeypatch.chdir(tmp_path)
    path, chosen = rig_protocol(None)
    assert path.name == f"{DEFAULT_PROTOCOL}.yaml" and "outside a study" in chosen


def test_the_studys_validation_among_several(tmp_path: Path) -> None:
    """A study of the calibrations and the validation: the one adjusting the blur-rate (the
    study's validation, named after it), as the shipped validation is chosen outside."""
    init_study(tmp_path / "c", ["calibration-fe", "calibration-sk", "validation"], "chain")
    assert study_protocol(tmp_path / "c") == tmp_path / "c" / "protocols" / "chain.yaml"
    init_study(tmp_path / "k", ["calibration-sk", "calibration-fe"], "k")
    assert study_protocol(tmp_path / "k").name == "calibration-sk.yaml"  # else the first
    marker = tmp_path / "k" / STUDY_FILE
    marker.write_text(marker.read_text().replace("protocols/", "gone/"))
    with pytest.raises(FovexpError, match=r"lists no protocol file that exists .*--protocol"):
        study_protocol(tmp_path / "k")


def test_the_rig_check_in_a_study_loads_and_reports_its_protocol(tmp_path: Path, capsys,
                                                                 monkeypatch) -> None:
    """The command, the measurements replaced by the protocol's loading alone (the window's
    part is the slow test's): the study's display, stimulus folder and tracker rate, and the
    report and console naming the protocol and why."""
    import fovexp.rig.measure as measure

    study = lab_study(tmp_path)
    seen: dict = {}

    def measured(opts: measure.RigOptions) -> measure.Measured:
        protocol, about = measure.load_rig_protocol(opts)
        protocol.prepare_images(DRY_RUN_SIZE, opts.dry_run)  # lab-01 is there
        seen.update(protocol=protocol, opts=opts)
        return measure.Measured(checks=[C.dropped_check({"dropped_fraction": 0.0}, True)],
                                sections={"protocol": about})

    monkeypatch.setattr(measure, "run_measurements", measured)
    monkeypatch.chdir(study / "stimuli")
    r = cli(capsys, ["rig", "check", "--dry-run", "--duration", "1"])
    assert r.returncode == 0, r.stderr
    lp = seen["protocol"]
    assert lp.experiment == "lab-study" and lp.display.name == "lg-oled55cx"
    assert lp.stimuli.folder == (study / "stimuli").resolve()
    assert lp.spec.tracker.sampling_hz == STUDY_RATE_HZ
    (path,) = (study / "stimuli" / "results" / "rig").glob("rig-*.json")  # --results: ./results
    rep = json.loads(path.read_text())
    own = study / "protocols" / "lab-study.yaml"
    assert rep["protocol"]["experiment"] == "lab-study"
    assert Path(rep["protocol"]["path"]).resolve() == own.resolve()
    assert rep["protocol"]["sha256"] == hashlib.sha256(own.read_bytes()).hexdigest()
    md = path.with_suffix(".md").read_text()
    assert (f"Protocol: lab-study ({rep['protocol']['path']}; the study folder "
            f"{study.resolve()}'s own)") in md.splitlines()


@pytest.mark.gui
@pytest.mark.slow
def test_a_dry_run_rig_check_in_a_study_folder(tmp_path: Path, xvfb_display) -> None:  # noqa: F811
    """The whole dry run from the study folder: the study's frame and its 250 Hz tracker
    are measured (the shipped validation's scenes are not in the study's stimuli)."""
    study = lab_study(tmp_path)
    r = run_cli(["rig", "check", "--dry-run", "--duration", "2"], cwd=study, timeout=600)
    assert r.returncode in (0, 1), r.stderr[-3000:]
    lines = r.stderr.strip().splitlines()
    assert any(line.startswith("fovexp rig check: protocol lab-study (") and
               "the study folder" in line for line in lines), lines
    (path,) = (study / "results" / "rig").glob("rig-*.json")
    rep = json.loads(path.read_text())
    assert rep["protocol"]["experiment"] == "lab-study"
    assert rep["tracker"]["nominal_rate_hz"] == STUDY_RATE_HZ
    # every check on the console, its value in its threshold's unit; the verdict last
    dropped = next(c for c in rep["checks"] if c["id"] == "display.dropped")
    assert dropped["unit"] == "%" and "%" in dropped["threshold"]
    assert sum(line.startswith("fovexp rig check: dropped frames under the session's load: ")
               and line.endswith("%; threshold: at most 1 % of the frames; "
                                 + {True: "pass", False: "FAIL", None: "not judged"}[
                                     dropped["passed"]])
               for line in lines) == 1
    assert lines[-1].startswith("fovexp rig check: ")
    assert "| tracker found | simulated |" in path.with_suffix(".md").read_text()
