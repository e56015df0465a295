"""Protocol validation (issue 3, item 1 and "Bad input"): the shipped protocols load, and bad
ones fail with an error naming the file and the key, before any window opens."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from fovexp import FovexpError
from fovexp.experiment.protocol.spec import load_protocol
from fovexp.experiment.records.participant_id import check_participant

from analysis_fixtures import Truth, write_study
from experiment_helpers import REPO, make_workspace, run_cli
from experiment_helpers import edit_protocol as edit


@pytest.fixture()
def ws(tmp_path: Path) -> Path:
    return make_workspace(tmp_path / "ws")


def test_shipped_protocols_state_the_paper_design() -> None:
    fe = load_protocol(REPO / "protocols" / "calibration-fe.yaml")
    assert fe.spec.adjust.parameter == "f_e" and fe.spec.adjust.range == (0.0, 0.4)
    assert fe.spec.methods == ["contrast"] and fe.spec.blur_rates == [0.11, 0.34, 0.57]
    assert len(fe.spec.images) == 5
    _, trials = fe.plan("P01", practice=0)
    assert len(trials) == 15
    val = load_protocol(REPO / "protocols" / "validation.yaml")
    assert val.spec.adjust.parameter == "blur_rate" and val.spec.adjust.start == 0.0
    assert sorted(val.spec.methods) == ["contrast", "ours"] and len(val.spec.images) == 10
    _, trials = val.plan("P01", practice=0)
    assert len(trials) == 20
    t = next(t for t in trials if t.method == "ours")
    # Table 2 interpolated by blur-rate: halfway between 0.11 and 0.34.
    v = val.parameter_values(t, 0.225)
    assert v["f_e"] == pytest.approx(0.19) and v["s_k"] == pytest.approx(21.71)
    assert v["s_f"] == pytest.approx(2.83) and v["blur_rate"] == 0.225
    for name in ("calibration-sk", "calibration-sf"):
        spec = yaml.safe_load((REPO / "protocols" / f"{name}.yaml").read_text())
        assert spec["parameters"]["f_e"] == {"fe_results": "calibration-fe"}
    sk = yaml.safe_load((REPO / "protocols" / "calibration-sk.yaml").read_text())
    assert sk["s_f_values"] == [1.0, 1.9, 3.61, 6.81] and sk["adjust"]["range"] == [0.0, 45.0]
    sf = yaml.safe_load((REPO / "protocols" / "calibration-sf.yaml").read_text())
    assert sf["adjust"]["range"] == [min(sk["s_f_values"]), max(sk["s_f_values"])]
    # Validation scenes are not the calibration images; practice is on another method.
    assert not set(val.spec.images) & set(fe.spec.images)
    _, trials = val.plan("P01")
    practice = [t for t in trials if t.practice]
    assert len(practice) == 2 and {t.method for t in practice} == {"foveated"}
    assert {t.method for t in trials if not t.practice} == {"contrast", "ours"}


def test_practice_methods_must_use_the_adjusted_parameter(ws: Path) -> None:
    with pytest.raises(FovexpError, match=r"practice_methods: foveated does not use the "
                                          r"adjusted f_e"):
        load_protocol(edit(ws, "calibration-fe", practice_methods=["foveated"]))


def test_plan_is_seeded_per_participant_and_stable() -> None:
    fe = load_protocol(REPO / "protocols" / "calibration-fe.yaml")
    s1, a = fe.plan("P01")
    s2, b = fe.plan("P01")
    _, c = fe.plan("P02")
    assert s1 == s2 and a == b
    assert [(t.image, t.blur_rate) for t in a] != [(t.image, t.blur_rate) for t in c]
    assert [t.practice for t in a] == [True, True] + [False] * 15
    assert all(0.0 <= t.start_value <= 0.4 for t in a)
    # A limit keeps a prefix of the same order (resume regenerates the same plan).
    _, lim = fe.plan("P01", limit=4)
    assert lim == a[:6]
    main = [(t.image, t.blur_rate) for t in a if not t.practice]
    assert len(set(main)) == 15


@pytest.mark.parametrize(
    ("change", "needle"),
    [
        ({"colour": "red"}, "colour='red': Extra inputs"),
        ({"adjust.range": [0.0, 9.0]}, "adjust"),
        ({"adjust.start": 0.9}, "start 0.9 is outside"),
        ({"blur_rates": [0.11, 7.0]}, "blur_rates"),
        ({"adjust.stride": 2}, "adjust.stride=2: Extra inputs"),
        ({"images": ["scene-00", "no-such-image"]}, "images[1]: image 'no-such-image'"),
        ({"repetitions": 0}, "repetitions"),
        ({"display": "displays/none.yaml"}, "display"),
    ],
)
def test_bad_protocol_names_file_and_key(ws: Path, change: dict, needle: str) -> None:
    path = edit(ws, "calibration-fe", **change)
    with pytest.raises(FovexpError) as err:
        load_protocol(path)
    msg = str(err.value)
    assert str(path) in msg and needle in msg
    assert "\n" not in msg


def test_missing_dependency_folder(ws: Path) -> None:
    with pytest.raises(FovexpError) as err:
        load_protocol(ws / "protocols" / "calibration-sk.yaml", results_root=ws / "results")
    msg = str(err.value)
    assert "calibration-sk.yaml" in msg and "parameters.f_e.fe_results" in msg
    assert "does not exist" in msg and str(ws / "results" / "calibration-fe") in msg


def test_dependencies_come_from_the_results_root(ws: Path, tmp_path: Path) -> None:
    """A study kept elsewhere (--results /data/study) reads its own calibration-fe, not the
    results folder beside the protocols."""
    study = write_study(tmp_path / "study", n_participants=2, seed=3,
                        experiments=("calibration-fe",), tracker="tobii")
    write_study(ws / "results", n_participants=2, seed=4, experiments=("calibration-fe",),
                truth=Truth(f_e={0.11: 0.05, 0.34: 0.1, 0.57: 0.15}), tracker="tobii")
    here = load_protocol(ws / "protocols" / "calibration-sk.yaml", results_root=ws / "results")
    there = load_protocol(ws / "protocols" / "calibration-sk.yaml", results_root=study)
    assert there.dependency_folders["f_e"] == str(study / "calibration-fe")
    assert here.sources["f_e"](0.34, None) == pytest.approx(0.1, abs=0.03)
    assert there.sources["f_e"](0.34, None) != pytest.approx(here.sources["f_e"](0.34, None),
                                                             abs=0.03)


def test_results_paths_stay_in_the_results_root(ws: Path) -> None:
    path = edit(ws, "calibration-sk", **{"parameters.f_e": {"fe_results":
                                                            "../results/calibration-fe"}})
    with pytest.raises(FovexpError, match=r"parameters\.f_e\.fe_results: "
                                          r"'\.\./results/calibration-fe' leaves the results root"):
        load_protocol(path, results_root=ws / "results")


def test_participant_sessions_never_use_dry_runs(ws: Path) -> None:
    """Dependencies holding only dry runs serve dry runs, and stop a real session; beside real
    participants' results, dry runs are left out (analysis rule R8)."""
    root = ws / "results"
    write_study(root, n_participants=2, seed=5, experiments=("calibration-fe",),
                truth=Truth(f_e={0.11: 0.3, 0.34: 0.3, 0.57: 0.3}), prefix="SIM")
    sk = ws / "protocols" / "calibration-sk.yaml"
    assert load_protocol(sk, results_root=root).sources["f_e"](0.34, None) > 0.25
    with pytest.raises(FovexpError, match=r"parameters\.f_e\.fe_results: .* only simulated "
                                          r"sessions \(dry runs\)"):
        load_protocol(sk, results_root=root, real_only=True)
    write_study(root, n_participants=2, seed=6, experiments=("calibration-fe",),
                truth=Truth(f_e={0.11: 0.1, 0.34: 0.1, 0.57: 0.1}), tracker="tobii")
    for real_only in (False, True):
        f_e = load_protocol(sk, results_root=root, real_only=real_only).sources["f_e"]
        assert f_e(0.34, None) == pytest.approx(0.1, abs=0.03)  # the dry runs' 0.3 left out


def test_pilot_sessions_serve_the_chain_only_when_asked(ws: Path) -> None:
    """Mouse-gaze pilots (analysis rule R7) feed the next calibration step only with
    --include-pilots; without it the error names the option."""
    root = ws / "results"
    write_study(root, n_participants=2, seed=5, experiments=("calibration-fe",),
                truth=Truth(f_e={0.11: 0.3, 0.34: 0.3, 0.57: 0.3}), tracker="mouse")
    sk = ws / "protocols" / "calibration-sk.yaml"
    with pytest.raises(FovexpError, match=r"parameters\.f_e\.fe_results: .*--include-pilots"):
        load_protocol(sk, results_root=root, real_only=True)
    f_e = load_protocol(sk, results_root=root, real_only=True, include_pilots=True)
    assert f_e.sources["f_e"](0.34, None) == pytest.approx(0.3, abs=0.03)


def test_method_needs_its_parameters(ws: Path) -> None:
    path = edit(ws, "validation", **{"parameters.s_k": None})
    with pytest.raises(FovexpError, match=r"parameters\.s_k: required"):
        load_protocol(path)


def test_changed_image_is_detected(ws: Path, tmp_path: Path, dry_run_scenes: Path) -> None:
    """A lab's frame whose bytes differ from the sha256 its manifest records stops the session
    before its window (the protocol names the stimulus folder through its manifest)."""
    stim = tmp_path / "stim"
    (stim / "frames").mkdir(parents=True)
    src = dry_run_scenes / "generated" / "480x270" / "scene-00.png"
    (stim / "frames" / "mine.png").write_bytes(src.read_bytes() + b"\0")
    man = {"images": [{"id": "mine", "path": "frames/mine.png", "source": "test",
                       "licence": "CC0-1.0", "sha256": "0" * 64}]}
    (stim / "manifest.yaml").write_text(yaml.safe_dump(man))
    path = edit(ws, "calibration-fe", stimuli=str(stim / "manifest.yaml"), images=["mine"])
    lp = load_protocol(path)
    assert lp.stimuli.folder == stim and lp.stimuli.found_by == "the protocol's stimuli key"
    with pytest.raises(FovexpError, match=r"images\[0\]: image 'mine': .*mine\.png has sha256 "
                                          r".*records 000000000000\.\.\. \(file changed\?\)"):
        lp.prepare_images((480, 270), dry_run=True)


@pytest.mark.parametrize("pid", ["P01", "a_b-3", "X" * 32])
def test_participant_ok(pid: str) -> None:
    assert check_participant(pid) == pid


@pytest.mark.parametrize("pid", ["", "../x", "P 01", "P01/", "é", "X" * 33, "a.b", "P01\n",
                                 "con", "NUL", "Com1", "lpt0"])
def test_participant_rejected(pid: str) -> None:
    with pytest.raises(FovexpError, match="participant ID"):
        check_participant(pid)


def test_cli_bad_input_one_line_exit_2(ws: Path) -> None:
    path = edit(ws, "calibration-fe", colour="red")
    r = run_cli(["run", str(path), "--participant", "P01", "--dry-run"], cwd=ws)
    assert r.returncode == 2
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "colour='red': Extra inputs" in lines[0] and str(path) in lines[0]
    assert not any((ws / "results").iterdir())  # nothing written, no window
    r = run_cli(["run", "protocols/calibration-fe.yaml", "--participant", "../evil",
                 "--dry-run"], cwd=ws)
    assert r.returncode == 2 and "participant ID" in r.stderr


def test_ranges_come_from_the_enhancer(ws: Path) -> None:
    """Protocol bounds are the enhancer's PARAMETER_RANGES (s_f open at 0): a protocol that
    validates gives parameters the enhancer accepts."""
    from fovexp import PARAMETER_RANGES

    hi = PARAMETER_RANGES["f_e"][1]
    load_protocol(edit(ws, "calibration-fe", **{"adjust.range": [0.0, hi]}))
    with pytest.raises(FovexpError,
                       match=rf"adjust.*outside what f_e allows: must be a finite number in "
                             rf"\[0, {hi:g}\]"):
        load_protocol(edit(ws, "calibration-fe", **{"adjust.range": [0.0, hi + 0.1]}))
    with pytest.raises(FovexpError,
                       match=r"parameters\.s_f\.value: 0\.0 is outside what s_f allows: .* "
                             r"in \(0, "):
        load_protocol(edit(ws, "validation", **{"parameters.s_f": {"value": 0.0}}))
    lp = load_protocol(edit(ws, "validation", **{"parameters.s_f": {"value": 1e-3}}))
    assert lp.spec.parameters["s_f"].value == 1e-3


def test_preset_and_geometry_must_agree(ws: Path) -> None:
    with pytest.raises(FovexpError, match="geometry: 'exact' contradicts preset 'release'"):
        load_protocol(edit(ws, "calibration-fe", preset="release", geometry="exact"))
    lp = load_protocol(edit(ws, "calibration-fe", preset="release", geometry=None))
    assert lp.spec.geometry_model == "release"
    lp = load_protocol(edit(ws, "calibration-fe", geometry="linear"))
    assert (lp.spec.preset, lp.spec.geometry_model) == ("paper", "linear")


def test_misspelt_key_is_named_with_the_likely_one(ws: Path) -> None:
    """A misspelt required key is reported as the unknown key it is (not only as the key that
    is missing), with the likely intended one; also nested."""
    src = (ws / "protocols" / "calibration-fe.yaml").read_text()
    bad = ws / "protocols" / "typo.yaml"
    bad.write_text(src.replace("\nseed:", "\nseeed:"))
    with pytest.raises(FovexpError, match=r"typo.yaml: seeed=.*Extra inputs are not permitted "
                                          r"\(did you mean 'seed'\?\)"):
        load_protocol(bad)
    path = edit(ws, "calibration-fe", **{"adjust.step": None, "adjust.stepz": 0.02})
    with pytest.raises(FovexpError, match=r"adjust\.stepz=0\.02: .*did you mean 'step'"):
        load_protocol(path)


def test_duplicate_key_and_bad_yaml_are_one_line(ws: Path) -> None:
    src = (ws / "protocols" / "calibration-fe.yaml").read_text()
    dup = ws / "protocols" / "dup.yaml"
    dup.write_text(src + "\nseed: 7\n")  # PyYAML alone would keep the last seed silently
    with pytest.raises(FovexpError, match=r"dup.yaml \(line \d+, column 1\): key 'seed' is "
                                          r"given twice"):
        load_protocol(dup)
    broken = ws / "protocols" / "broken.yaml"
    broken.write_text("experiment: [\n")
    with pytest.raises(FovexpError) as err:
        load_protocol(broken)
    assert "broken.yaml is not valid YAML (line 2, column 1)" in str(err.value)
    assert "\n" not in str(err.value)


def test_cross_field_errors_name_their_keys_without_noise(ws: Path) -> None:
    with pytest.raises(FovexpError) as err:
        load_protocol(edit(ws, "calibration-fe", images=["scene-00", "scene-00"]))
    assert str(err.value).endswith("edited-calibration-fe.yaml: images: duplicate ids")


def test_bad_parameter_table_names_the_protocol_key(ws: Path) -> None:
    (ws / "protocols" / "bad-table.yaml").write_text("rows:\n  - {blur_rate: 0.3, f_e: 0.1}\n")
    path = edit(ws, "validation", **{"parameters.f_e": {"table": "bad-table.yaml"},
                                     "parameters.s_k": {"table": "bad-table.yaml"},
                                     "parameters.s_f": {"table": "bad-table.yaml"}})
    with pytest.raises(FovexpError) as err:
        load_protocol(path)
    msg = str(err.value)
    assert msg.startswith(f"protocol {path}: parameters.") and ".table: parameter table" in msg
    assert "bad-table.yaml" in msg and "Field required" in msg
