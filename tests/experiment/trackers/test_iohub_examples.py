"""The shipped example ioHub configurations and the checks before ioHub's server starts
(issue 32): one example per tracker family, in the form ``--tracker-config`` reads, each
loading with fovexp's own checks for its family (and with its plugin's own setting names where
the plugin is installed), shipped in the wheel and printed by ``fovexp tracker example``; a
class path no module answers to, and an empty configuration, are one line each, without
ioHub's tracebacks. The MouseGaze example also runs through the real server:
test_iohub.py."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from typing import Any

import pytest
import yaml

from fovexp import FovexpError, load_display
from fovexp.experiment.trackers.families import (
    EXAMPLES_DIR,
    FAMILIES,
    OTHER,
    check_device_module,
    check_plugin,
    device_module,
    example_path,
    hub_config,
    load_iohub_config,
    parse_iohub_config,
)
from fovexp.experiment.trackers.iohub import eyes_of

try:
    import tomllib
except ImportError:  # Python 3.10
    import tomli as tomllib

from experiment_helpers import make_workspace, run_cli

ROOT = Path(__file__).resolve().parents[3]
LG = load_display("lg-oled55cx")

#: where each family's plugin keeps ioHub's description of its settings
#: (``default_eyetracker.yaml``, ``supported_config_settings.yaml``): package, folder in it
PLUGIN_SETTINGS = {
    "mousegaze": ("psychopy", "iohub/devices/eyetracker/hw/mouse"),
    "eyelink": ("psychopy_eyetracker_sr_research", "sr_research/eyelink"),
    "tobii": ("psychopy_eyetracker_tobii", "tobii"),
    "gazepoint": ("psychopy_eyetracker_gazepoint", "gazepoint/gp3"),
    "pupil-labs": ("psychopy_eyetracker_pupil_labs", "pupil_labs/pupil_core"),
    "eyelogic": ("psychopy_eyetracker_eyelogic", "eyelogic/psychopy"),
}
#: keys an example may add to its plugin's: the nominal rate fovexp reads where the plugin
#: leaves the rate to the vendor's software (Pupil Capture)
FOVEXP_KEYS = {"runtime_settings.sampling_rate"}


def test_every_family_has_one_example_and_no_other_is_shipped() -> None:
    """A family added to families.py without an example fails here (and so does an example no
    family has)."""
    shipped = sorted(p.stem for p in EXAMPLES_DIR.glob("*.yaml"))
    assert shipped == sorted(f.key for f in FAMILIES)
    assert OTHER.key not in shipped
    assert set(PLUGIN_SETTINGS) == {f.key for f in FAMILIES}


@pytest.mark.parametrize("fam", FAMILIES, ids=lambda f: f.key)
def test_each_example_loads_as_its_family(fam) -> None:
    """The example in the form --tracker-config reads (Builder's: the class path, then its
    settings), through ``example:FAMILY`` as a user names it: its family, the family's class
    path, a nominal rate (the validation's expected samples), eyes; only the tracker (no
    Display or data_store for fovexp to leave out); the server's configuration made from it."""
    path = example_path(fam.key)
    assert path.is_file() and path.parent == EXAMPLES_DIR
    cfg = load_iohub_config(f"example:{fam.key}")
    assert cfg == load_iohub_config(path)  # the same file, the same record
    assert cfg.family == fam and cfg.device_class == fam.device_class
    assert cfg.name == "tracker" and cfg.devices == {} and cfg.ignored == ()
    assert cfg.sampling_hz is not None and cfg.sampling_hz > 0
    eyes = eyes_of(cfg.track_eyes, fam.pilot)
    assert eyes in (("left",), ("right",), ("left", "right"))
    devs = hub_config(cfg, LG, 0)["monitor_devices"]
    assert next(iter(devs[0])) == "Display" and devs[-1] == {
        fam.device_class: {**cfg.tracker, "name": "tracker"}}
    # its plugin: none, or the one the family's extra installs
    if fam.extra is None:
        assert check_plugin(fam, find=lambda name: None) is None
    else:
        with pytest.raises(FovexpError, match=rf"pip install 'fovexp\[{fam.extra}\]'"):
            check_plugin(fam, find=lambda name: None)


def _key_paths(tree: Any, prefix: str = "") -> set[str]:
    """The dotted key paths of a settings tree; ioHub's ``IOHUB_*`` constraints are leaves."""
    out: set[str] = set()
    if not isinstance(tree, dict) or any(str(k).startswith("IOHUB_") for k in tree):
        return out
    for k, v in tree.items():
        path = f"{prefix}{k}"
        out.add(path)
        out |= _key_paths(v, path + ".")
    return out


@pytest.mark.parametrize("fam", FAMILIES, ids=lambda f: f.key)
def test_each_example_uses_its_plugins_setting_names(fam) -> None:
    """Where the plugin is installed: every setting of the example is one the plugin's own
    files name (ioHub itself only checks the top level), and ioHub finds the device module
    before its server starts."""
    package, folder = PLUGIN_SETTINGS[fam.key]
    spec = importlib.util.find_spec(package)
    if spec is None or (fam.module and importlib.util.find_spec(fam.module) is None):
        pytest.skip(f"{fam.distribution or package} is not installed")
    where = Path(next(iter(spec.submodule_search_locations or []))) / folder
    known: set[str] = set()
    for name in ("default_eyetracker.yaml", "supported_config_settings.yaml"):
        if (where / name).is_file():
            tree = yaml.safe_load((where / name).read_text())
            known |= _key_paths(next(iter(tree.values())))
    assert known, f"no settings files in {where}"
    cfg = load_iohub_config(example_path(fam.key))
    unknown = _key_paths(cfg.tracker) - known - FOVEXP_KEYS
    assert not unknown, f"{fam.key}: settings its plugin does not name: {sorted(unknown)}"
    assert check_device_module(cfg) == device_module(fam.device_class)


def test_example_family_names_a_shipped_example_wherever_a_configuration_is_named() -> None:
    """``--tracker-config example:FAMILY``, or the protocol's ``tracker.iohub_config:
    example:FAMILY``: the shipped file itself (the session file records its path and sha256);
    a family that does not exist is one line naming them."""
    from types import SimpleNamespace

    from fovexp.experiment.trackers import iohub_config_path

    def protocol(iohub_config: str | None) -> Any:
        return SimpleNamespace(path=Path("/lab/protocols/validation.yaml"), spec=SimpleNamespace(
            tracker=SimpleNamespace(iohub_config=iohub_config)))

    assert iohub_config_path(protocol(None), Path("example:eyelink")) == example_path("eyelink")
    assert iohub_config_path(protocol("example:gazepoint"), None) == example_path("gazepoint")
    assert iohub_config_path(protocol("lab/el.yaml"), None) == Path("/lab/protocols/lab/el.yaml")
    with pytest.raises(FovexpError, match=r"no example ioHub configuration 'eylink' \(did you "
                       r"mean 'eyelink'\?\): the families are eyelink, tobii"):
        iohub_config_path(protocol(None), "example:eylink")


def test_the_examples_are_package_data_of_the_wheel() -> None:
    conf = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    package = "fovexp.experiment.trackers.configs"
    assert package in conf["packages"]
    patterns = conf["package-data"][package]
    assert all(any(p.match(g) for g in patterns) for p in EXAMPLES_DIR.glob("*"))


def test_fovexp_tracker_example_prints_and_lists(capsys) -> None:
    from fovexp.cli import main

    assert main(["tracker", "example", "eyelink"]) == 0
    out = capsys.readouterr().out
    assert out == example_path("eyelink").read_text()
    assert parse_iohub_config(out, Path("lab/eyelink.yaml")).family.key == "eyelink"
    assert main(["tracker", "example"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [ln.split()[0] for ln in lines] == [f.key for f in FAMILIES]
    assert "eyetracker.hw.mouse.EyeTracker (built into PsychoPy)" in lines[-1]
    assert main(["tracker", "example", "eylink"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "(did you mean 'eyelink'?)" in err


# -- the checks before ioHub's server ----------------------------------------------------------
def _cfg(device_class: str) -> Any:
    return parse_iohub_config(f"{device_class}: {{name: tracker}}\n", Path("lab/t.yaml"))


def test_device_module_is_iohubs_rule() -> None:
    assert device_module("eyetracker.hw.mouse.EyeTracker") == \
        "psychopy.iohub.devices.eyetracker.hw.mouse"
    assert device_module("eyetracker.hw.SR_Research.EyeLink.EyeTracker") == \
        "psychopy.iohub.devices.eyetracker.hw.sr_research.eyelink"


def test_a_missing_device_module_is_one_line() -> None:
    """No module for the class path (ioHub's server would print some fifty lines of
    tracebacks): one line naming the module and the class paths fovexp knows with what
    installs each; a known family's own path and extra when the path is its family's."""
    have = {"psychopy.iohub.devices", "psychopy.iohub.devices.eyetracker.hw.mouse"}

    def find(name: str) -> object | None:
        return object() if name in have else None

    with pytest.raises(FovexpError) as e:
        check_device_module(_cfg("eyetracker.hw.nosuch.EyeTracker"), find=find,
                            plugin_modules=())
    msg = str(e.value)
    assert msg.startswith("ioHub has no device module psychopy.iohub.devices.eyetracker.hw."
                          "nosuch for eyetracker.hw.nosuch.EyeTracker (lab/t.yaml)")
    assert "eyetracker.hw.sr_research.eyelink.EyeTracker (pip install 'fovexp[eyelink]')" in msg
    assert "eyetracker.hw.mouse.EyeTracker (built into PsychoPy)" in msg
    assert "fovexp tracker example FAMILY" in msg and "\n" not in msg
    with pytest.raises(FovexpError) as e:
        check_device_module(_cfg("eyetracker.hw.sr_research.eyelnk.EyeTracker"), find=find,
                            plugin_modules=())
    assert "the class path of the SR Research EyeLink" in str(e.value)
    assert "is eyetracker.hw.sr_research.eyelink.EyeTracker (pip install 'fovexp[eyelink]')" \
        in str(e.value)
    # found: by PsychoPy's own module, or a plugin's entry point (EyeLogic's)
    assert check_device_module(_cfg("eyetracker.hw.mouse.EyeTracker"), find=find,
                               plugin_modules=()) == "psychopy.iohub.devices.eyetracker.hw.mouse"
    eyelogic = _cfg("eyetracker.eyelogic.psychopy.eyetracker.EyeTracker")
    assert check_device_module(
        eyelogic, find=find, plugin_modules={"psychopy.iohub.devices.eyetracker.eyelogic"}) \
        == "psychopy.iohub.devices.eyetracker.eyelogic.psychopy.eyetracker"
    # ioHub's class name is EyeTracker, as written
    with pytest.raises(FovexpError, match=r"ioHub's eye-tracker class is EyeTracker "
                       r"\(eyetracker.hw.mouse.EyeTracker\)"):
        check_device_module(_cfg("eyetracker.hw.mouse.Eyetracker"), find=find,
                            plugin_modules=())
    # no PsychoPy: nothing to say here (starting the server names the extra)
    assert check_device_module(_cfg("eyetracker.hw.nosuch.EyeTracker"),
                               find=lambda name: None, plugin_modules=()) is None


def test_an_unknown_tracker_stops_with_one_line_and_no_traceback(tmp_path) -> None:
    """The whole command, with PsychoPy's real module finder: exit 2, one line naming the
    missing module, no traceback (fovexp's nor ioHub's: no server is started), nothing
    written."""
    ws = make_workspace(tmp_path / "u")
    cfg = ws / "nosuch.yaml"
    cfg.write_text("eyetracker.hw.nosuch.EyeTracker: {name: tracker}\n")
    r = run_cli(["run", "calibration-fe", "--participant", "P01", "--tracker", "iohub",
                 "--tracker-config", str(cfg), "--results", str(ws / "results"),
                 "--window", "480x270"], cwd=ws, env_update={"DISPLAY": None})
    assert r.returncode == 2, r.stderr[-2000:]
    assert "Traceback" not in r.stderr + r.stdout and "Error during device creation" not in r.stderr
    errors = [x for x in r.stderr.splitlines() if "error" in x.lower()]
    assert len(errors) == 1 and errors[0].startswith("fovexp run: error: ioHub has no device "
                                                     "module psychopy.iohub.devices.eyetracker."
                                                     "hw.nosuch for eyetracker.hw.nosuch")
    assert not any((ws / "results").iterdir())


@pytest.mark.parametrize("text", ["", "\n\n", "# the lab's tracker, to do\n# (nothing yet)\n"])
def test_an_empty_configuration_is_one_line_naming_the_file(tmp_path, text: str) -> None:
    path = tmp_path / "lab" / "tracker.yaml"
    path.parent.mkdir()
    path.write_text(text)
    with pytest.raises(FovexpError) as e:
        load_iohub_config(path)
    msg = str(e.value)
    assert msg.startswith(f"ioHub configuration {path} is empty (or only comments): it must "
                          "name one eye tracker by its ioHub device class path")
    assert "NoneType" not in msg and "\n" not in msg
