"""Issue 21: a lab's own study folder (``fovexp init``), a dry run at the display's size that
refuses what the real session refuses, the closest ids for an unknown one, a window larger than
the X screen, and ``--limit-trials`` keeping a scene's methods together. The whole recipe with
the wheel in a clean environment: ``.ci/study-walk`` (run by ``.ci/wheel-smoke``)."""

from __future__ import annotations

import hashlib
import os
import re
from pathlib import Path

import pytest
import yaml

from fovexp import FovexpError
from fovexp.experiment.display.xscreen import check_window_fits, x_screen_size
from fovexp.experiment.protocol.spec import limit_order, load_protocol
from fovexp.experiment.protocol.study import init_study, study_name
from fovexp.stimuli.folder import STUDY_FILE, StimulusSet, find_folder

from experiment_helpers import REPO, cli, pattern, write_png, xvfb_display  # noqa: F401


def tiny_display(folder: Path, w: int, h: int) -> Path:
    """A display profile of ``w`` x ``h`` pixels (the paper's otherwise): small test frames."""
    data = yaml.safe_load((REPO / "protocols" / "displays" / "lg-oled55cx.yaml").read_text())
    data.update(name=f"tiny-{w}x{h}", width_px=w, height_px=h)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"tiny-{w}x{h}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _key(path: Path, key: str) -> str | None:
    m = re.search(rf"^{key}: ?(.*)$", path.read_text(), re.MULTILINE)
    return m.group(1) if m else None


# -- fovexp init ----------------------------------------------------------------------------------
def test_the_guides_recipe_is_what_init_prints(tmp_path: Path, capsys, monkeypatch) -> None:
    """docs/STUDY.md's recipe is ``fovexp init lab-study --name lab-validation``'s printed
    commands to the character (issue 32: .ci/study-walk runs them as printed)."""
    monkeypatch.chdir(tmp_path)
    r = cli(capsys, ["init", "lab-study", "--name", "lab-validation"])
    assert r.returncode == 0, r.stderr
    printed = r.stdout.split("next:\n", 1)[1].splitlines()
    guide = (REPO / "docs" / "STUDY.md").read_text().split(
        "<!-- recipe: fovexp init lab-study --name lab-validation", 1)[1]
    block = guide.split("\n\n", 1)[0].splitlines()[1:]
    assert [ln.removeprefix("    ") for ln in block] == [ln.removeprefix("  ") for ln in printed]


def test_init_makes_a_study_that_loads_where_it_lands(tmp_path: Path, capsys,
                                                      monkeypatch) -> None:
    monkeypatch.chdir(tmp_path)  # no ./protocols/displays of the clone to fall back on
    r = cli(capsys, ["init", "my-study", "--name", "Lab Validation"])
    assert r.returncode == 0, r.stderr
    study = tmp_path / "my-study"
    assert sorted(p.name for p in study.iterdir()) == [
        "README.md", STUDY_FILE, "protocols", "results", "stimuli"]
    proto = study / "protocols" / "lab-validation.yaml"
    assert [p.name for p in (study / "protocols").iterdir()] == [proto.name]
    assert _key(proto, "experiment") == "lab-validation"
    assert _key(proto, "display") == "lg-oled55cx"
    assert _key(proto, "stimuli") == "../stimuli"
    # the rest of the shipped text, comments included, is kept
    shipped = (REPO / "protocols" / "validation.yaml").read_text()
    kept = [ln for ln in shipped.splitlines()
            if not ln.startswith(("experiment:", "display:"))]
    assert [ln for ln in proto.read_text().splitlines()
            if not ln.startswith(("experiment:", "display:", "stimuli:"))] == kept
    # the copy loads from anywhere, with the study's stimulus folder
    monkeypatch.chdir(REPO.parent)
    lp = load_protocol(proto, results_root=tmp_path / "r")
    assert lp.experiment == "lab-validation" and lp.display.name == "lg-oled55cx"
    assert lp.stimuli.folder == (study / "stimuli").resolve()
    # the next commands: printed and in the README, with the rehearsal's --window
    # (issue 32) exactly two trials (no practice), into test-results/, not the study's results/
    rehearsal = ("fovexp run lab-validation --participant SIM01 --dry-run --window 3840x2160 "
                 "--limit-trials 2 --practice 0 --sim-truth quick --results test-results")
    assert rehearsal in r.stdout and rehearsal in (study / "README.md").read_text()
    # a free display number (-a): without it xvfb-run fails wherever :99 is taken (issue 32)
    assert "xvfb-run -a -s '-screen 0 3840x2160x24' " + rehearsal in r.stdout
    assert "xvfb-run -a -s '-screen 0 3840x2160x24' fovexp rig check --dry-run --results " \
           "test-results" in r.stdout
    assert "xvfb-run -s" not in r.stdout + (study / "README.md").read_text()
    for cmd in ("fovexp stimuli add", "fovexp stimuli check", "fovexp analyze test-results",
                "# on the rig:", "fovexp analyze results"):
        assert cmd in r.stdout
    marker = yaml.safe_load((study / STUDY_FILE).read_text())
    assert marker["study"] == "lab-validation" and marker["display"] == "lg-oled55cx"
    # a folder like any other the user makes (mkdtemp's would be private)
    umask = os.umask(0)
    os.umask(umask)
    assert study.stat().st_mode & 0o777 == 0o777 & ~umask


def test_init_never_overwrites(tmp_path: Path, capsys) -> None:
    study = tmp_path / "s"
    assert cli(capsys, ["init", str(study)]).returncode == 0
    (study / "protocols" / "s.yaml").write_text("edited: by the lab\n")
    before = {p: p.read_bytes() for p in study.rglob("*") if p.is_file()}
    r = cli(capsys, ["init", str(study), "--from", "calibration-fe"])
    assert r.returncode == 2 and "never overwrites" in r.stderr
    assert {p: p.read_bytes() for p in study.rglob("*") if p.is_file()} == before
    # an empty folder is fine; nothing is left behind by a failure
    (tmp_path / "empty").mkdir()
    assert cli(capsys, ["init", str(tmp_path / "empty")]).returncode == 0
    r = cli(capsys, ["init", str(tmp_path / "bad"), "--from", "validatoin"])
    assert r.returncode == 2 and "did you mean 'validation'?" in r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["empty", "s"]


def test_init_keeps_the_calibration_chain_and_copies_a_lab_profile(tmp_path: Path) -> None:
    """The calibration copies keep their experiments' names (the chain and Table 2 read them);
    the validation gets the study's; a protocol of the lab's own with a profile that is not
    shipped brings the profile along."""
    study = init_study(tmp_path / "c", ["calibration-fe", "calibration-sk", "calibration-sf",
                                        "validation"], "chain")
    assert study.protocols == {"protocols/calibration-fe.yaml": "calibration-fe",
                               "protocols/calibration-sk.yaml": "calibration-sk",
                               "protocols/calibration-sf.yaml": "calibration-sf",
                               "protocols/chain.yaml": "chain"}
    assert _key(tmp_path / "c/protocols/calibration-sk.yaml", "experiment") == "calibration-sk"
    assert "fe_results: calibration-fe" in (tmp_path / "c/protocols/calibration-sk.yaml"
                                            ).read_text()
    own = tmp_path / "lab" / "mine.yaml"
    tiny_display(tmp_path / "lab" / "screens", 64, 36)
    data = yaml.safe_load((REPO / "protocols" / "validation.yaml").read_text())
    data.update(display="screens/tiny-64x36.yaml", experiment="mine")
    own.write_text(yaml.safe_dump(data))
    study = init_study(tmp_path / "o", [str(own)], "own")
    copy = tmp_path / "o" / "protocols" / "own.yaml"
    assert _key(copy, "display") == "displays/tiny-64x36.yaml"
    assert (tmp_path / "o" / "protocols" / "displays" / "tiny-64x36.yaml").is_file()
    assert study.size == (64, 36) and "--window 64x36" in study.commands
    assert load_protocol(copy).native_size == (64, 36)


def test_a_profile_name_is_found_beside_the_protocol(tmp_path: Path, monkeypatch) -> None:
    """``display: NAME`` loads protocols/displays/NAME.yaml of the protocol's own folder,
    wherever it is run from."""
    init_study(tmp_path / "s")
    tiny_display(tmp_path / "s" / "protocols" / "displays", 64, 36)
    proto = tmp_path / "s" / "protocols" / "s.yaml"
    proto.write_text(proto.read_text().replace("display: lg-oled55cx", "display: tiny-64x36"))
    monkeypatch.chdir(tmp_path)
    assert load_protocol(proto).native_size == (64, 36)


def test_study_names() -> None:
    assert study_name("Lab Study 2") == "lab-study-2"
    with pytest.raises(FovexpError, match="--name '__': a study's name"):
        study_name("__")


def test_stimuli_add_inside_a_study_writes_to_its_stimuli(tmp_path: Path, capsys,
                                                          monkeypatch) -> None:
    """From the study folder or below it, before $FOVEXP_STIMULI (set for every test)."""
    assert os.environ.get("FOVEXP_STIMULI")
    init_study(tmp_path / "s")
    disp = tiny_display(tmp_path, 64, 36)
    frame = write_png(tmp_path / "f.png", pattern(36, 64, 3))
    monkeypatch.chdir(tmp_path / "s" / "protocols")
    folder, _, how = find_folder()
    assert folder == (tmp_path / "s" / "stimuli").resolve() and "study folder" in how
    r = cli(capsys, ["stimuli", "add", str(frame), "--id", "lab-01", "--display", str(disp),
                     "--licence", "CC0-1.0"])
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "s" / "stimuli" / "frames" / "lab-01.png").is_file()
    assert "lab-01" in StimulusSet(tmp_path / "s" / "stimuli").frames


# -- the rehearsal -------------------------------------------------------------------------------
def _lab_study(tmp_path: Path) -> Path:
    """A study on a 64x36 display with lab-01 (64x36) and lab-02 (32x18, added for another
    display): the protocol names both."""
    lab = tmp_path / "lab"
    tiny_display(lab, 64, 36)
    data = yaml.safe_load((REPO / "protocols" / "validation.yaml").read_text())
    data.update(display="tiny-64x36.yaml", experiment="v", images=["lab-01", "lab-02"])
    (lab / "v.yaml").write_text(yaml.safe_dump(data, default_flow_style=None))
    init_study(tmp_path / "s", [str(lab / "v.yaml")], "v")
    frames = tmp_path / "s" / "stimuli" / "frames"
    entries = []
    for name, (w, h) in (("lab-01", (64, 36)), ("lab-02", (32, 18))):
        f = write_png(frames / f"{name}.png", pattern(h, w, len(entries)))
        entries.append({"id": name, "path": f"frames/{name}.png", "source": "test",
                        "licence": "CC0-1.0", "sha256": hashlib.sha256(f.read_bytes()).hexdigest()})
    (tmp_path / "s" / "stimuli" / "manifest.yaml").write_text(yaml.safe_dump({"images": entries}))
    proto = tmp_path / "s" / "protocols" / "v.yaml"
    assert "images: [lab-01, lab-02]" in proto.read_text()
    return proto


def test_a_dry_run_at_the_display_size_refuses_what_the_session_refuses(
        tmp_path: Path, capsys) -> None:
    proto = _lab_study(tmp_path)
    lp = load_protocol(proto)
    with pytest.raises(FovexpError) as real:
        lp.prepare_images(lp.native_size, dry_run=False)
    with pytest.raises(FovexpError) as rehearsal:
        lp.prepare_images(lp.native_size, dry_run=True)
    assert str(rehearsal.value) == str(real.value)
    assert "image 'lab-02'" in str(real.value) and "is 32x18; the display shows 64x36" in str(
        real.value)
    # a smaller window scales, and the record says which
    images = lp.prepare_images((32, 18), dry_run=True)
    assert images["lab-01"].scaled and not images["lab-02"].scaled
    rec = lp.stimuli_record()
    assert rec["dry_run"] and rec["may_scale"] and rec["scaled"] == ["lab-01"]
    # the commands: the same line from fovexp run, a real session and a rehearsal, no window
    results = tmp_path / "results"
    common = ["run", str(proto), "--results", str(results)]
    a = cli(capsys, [*common, "--participant", "P01", "--tracker", "mouse"])
    b = cli(capsys, [*common, "--participant", "SIM01", "--dry-run", "--window", "64x36"])
    assert a.returncode == b.returncode == 2
    assert a.stderr == b.stderr and a.stderr.count("\n") == 1
    assert not results.exists()
    # fovexp stimuli check says the same for a rehearsal
    c = cli(capsys, ["stimuli", "check", str(proto), "--dry-run", "--window", "64x36"])
    assert c.returncode == 2 and "a rehearsal" in c.stdout
    assert re.search(r"^lab-02 .* refused: 32x18 is not 64x36", c.stdout, re.MULTILINE)
    c = cli(capsys, ["stimuli", "check", str(proto), "--dry-run", "--window", "32x18"])
    assert c.returncode == 0 and "scaled from 64x36" in c.stdout


def test_an_unknown_id_gets_the_closest_ones(tmp_path: Path, capsys) -> None:
    proto = _lab_study(tmp_path)
    proto.write_text(proto.read_text().replace("images: [lab-01, lab-02]", "images: [lab-1]"))
    with pytest.raises(FovexpError, match=r"images\[0\]: image 'lab-1' is neither .* "
                                          r"\(did you mean 'lab-01' or 'lab-02'\?\)"):
        load_protocol(proto)
    r = cli(capsys, ["stimuli", "check", str(proto)])
    assert r.returncode == 2 and "fix the id (did you mean 'lab-01' or 'lab-02'?)" in r.stdout
    # a generated scene's id too; nothing close: no guess
    stim = StimulusSet(tmp_path / "s" / "stimuli")
    assert "did you mean 'scene-05'" in stim.check("scene-5", (64, 36), False).problem
    assert "did you mean" not in stim.check("zzzzzzzz", (64, 36), False).problem


# -- the X screen ---------------------------------------------------------------------------------
def test_a_window_larger_than_the_x_screen_is_refused() -> None:
    check_window_fits((3840, 2160), None)  # unknown: not refused
    check_window_fits((1280, 720), (1280, 720))
    with pytest.raises(FovexpError, match=r"the window 3840x2160 is larger than the X screen "
                                          r"1280x720 .*-screen 0 3840x2160x24"):
        check_window_fits((3840, 2160), (1280, 720))
    assert x_screen_size("") is None


@pytest.mark.gui
def test_x_screen_size_and_the_run_refusal(tmp_path: Path, capsys, xvfb_display) -> None:  # noqa: F811
    size = x_screen_size()
    assert size is not None and min(size) > 0
    proto = _lab_study(tmp_path)
    w = size[0] + 2 - size[0] % 2
    r = cli(capsys, ["run", str(proto), "--participant", "SIM01", "--dry-run", "--window",
                     f"{w}x{size[1]}", "--results", str(tmp_path / "results")])
    assert r.returncode == 2 and "is larger than the X screen" in r.stderr
    assert not (tmp_path / "results").exists()


# -- --limit-trials --------------------------------------------------------------------------------
def test_limit_trials_keeps_a_scenes_methods_together(tmp_path: Path) -> None:
    import doctest

    res = doctest.DocTestRunner()
    for test in doctest.DocTestFinder().find(limit_order, globs={"limit_order": limit_order}):
        res.run(test)
    assert res.failures == 0 and res.tries == 3
    lp = load_protocol(REPO / "protocols" / "validation.yaml")
    _, full = lp.plan("P01", practice=0)
    for limit, scenes_kept in ((1, 1), (2, 1), (3, 2), (5, 3)):
        _, lim = lp.plan("P01", limit=limit, practice=0)
        kept = {t.image for t in lim}
        assert len(kept) == scenes_kept and len(lim) == 2 * scenes_kept
        assert all(sorted(t.method for t in lim if t.image == i) == ["contrast", "ours"]
                   for i in kept)
        # the kept trials in the full order, with their start values (the start is fixed at
        # 0 in the validation: the ids and order are what is checked here)
        same = [(t.image, t.method) for t in full if t.image in kept]
        assert [(t.image, t.method) for t in lim] == same
        assert [t.index for t in lim] == list(range(len(lim)))
    # one method per scene (the calibrations): the first N trials, as before
    fe = load_protocol(REPO / "protocols" / "calibration-fe.yaml")
    _, full = fe.plan("P02", practice=1)
    _, lim = fe.plan("P02", limit=3, practice=1)
    assert lim == full[:4]
    # a random start value follows its trial, not its place in the shorter plan
    data = yaml.safe_load((REPO / "protocols" / "validation.yaml").read_text())
    data["adjust"]["start"] = "random"
    data["display"] = "lg-oled55cx"
    (tmp_path / "v.yaml").write_text(yaml.safe_dump(data))
    rv = load_protocol(tmp_path / "v.yaml")
    _, full = rv.plan("P03", practice=2)
    _, lim = rv.plan("P03", limit=4, practice=2)
    by_trial = {(t.practice, t.image, t.method): t.start_value for t in full}
    assert [t.start_value for t in lim] == [by_trial[(t.practice, t.image, t.method)]
                                            for t in lim]
    assert len({t.start_value for t in lim}) == len(lim)
