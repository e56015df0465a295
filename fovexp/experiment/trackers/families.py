"""The eye-tracker families ioHub reaches, and the ioHub configuration a lab already has.

PsychoPy reaches eye trackers through ioHub's common eye-tracker interface
(``psychopy.iohub.devices.eyetracker``): one device class per vendor, most of them in plugins
on PyPI (``psychopy-eyetracker-sr-research``, ``-tobii``, ``-gazepoint``, ``-pupil-labs``,
``-eyelogic``), and MouseGaze (the mouse as gaze) in PsychoPy itself. fovexp installs each
plugin through an extra of its own (:data:`FAMILIES`: ``pip install 'fovexp[eyelink]'``), and
names that extra when the plugin is missing (:func:`check_plugin`), before any window opens.

The configuration is the YAML a lab already uses for PsychoPy or ioHub
(:func:`load_iohub_config`), in either of ioHub's two forms:

- ``launchHubServer``'s keyword form, as PsychoPy Builder's ``ioConfig`` and ioHub's demos
  write it: a mapping whose key is the tracker's device class path
  (``eyetracker.hw.sr_research.eyelink.EyeTracker: {name: tracker, runtime_settings: ...}``),
  optionally beside other devices (``Keyboard``, ``Mouse``);
- an ``iohub_config.yaml``: the devices under ``monitor_devices`` (a list of one-key mappings,
  or a mapping).

The ``Display`` device is always fovexp's (:func:`hub_config`): its physical size and
viewing distance are the display profile's, its unit ``pix``, its screen the session's (a
tracker that maps gaze through ioHub's display, as EyeLink's plugin does, then measures the
same screen the blanking window is computed on).

Every family has an example in the keyword form, shipped as package data
(``configs/<family>.yaml``, :func:`example_path`): a lab starts from it (``fovexp tracker
example FAMILY`` prints it) instead of from ioHub's defaults, and ``--tracker-config
example:FAMILY`` reads it as it is. Before ioHub's server starts, :func:`check_device_module`
makes sure the class path names a module ioHub can import: the server would print some fifty
lines of tracebacks and then create no tracker. No PsychoPy import at import time here.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fovexp import FovexpError, did_you_mean, parse_yaml

#: The shipped example configurations, ``<family key>.yaml`` (package data of the wheel).
EXAMPLES_DIR = Path(__file__).resolve().parent / "configs"
#: ``--tracker-config example:eyelink``: the shipped example of a family, not a file.
EXAMPLE_PREFIX = "example:"
#: How a user gets an example (named in the one-line errors below).
EXAMPLE_HINT = "fovexp tracker example FAMILY prints an example"
#: The package ioHub imports device modules from (its server's rule: :func:`device_module`).
IOHUB_DEVICES = "psychopy.iohub.devices"


@dataclass(frozen=True)
class TrackerFamily:
    """One family of ioHub eye trackers: how fovexp installs, calibrates and tests it."""

    key: str
    label: str
    #: lower-case parts of the ioHub device class path that identify the family
    match: tuple[str, ...]
    #: fovexp's extra that installs the plugin (None: PsychoPy itself has it)
    extra: str | None
    #: the plugin's distribution on PyPI and its import name
    distribution: str | None
    module: str | None
    #: ``own``: the tracker's own set-up (``runSetupProcedure``), then fovexp's validation;
    #: ``none``: nothing to calibrate (MouseGaze)
    calibration: str
    #: what the samples' ``device_time`` counts, as the plugin reports it
    clock: str
    #: the mouse: a pilot session, not an eye tracker (the analysis leaves it out)
    pilot: bool = False
    #: the ioHub device class path of the family's example (``configs/<key>.yaml``)
    device_class: str = ""

    @property
    def install(self) -> str:
        """How the family's plugin is installed, for one-line messages."""
        return f"pip install 'fovexp[{self.extra}]'" if self.extra else "built into PsychoPy"


FAMILIES: tuple[TrackerFamily, ...] = (
    TrackerFamily(
        "eyelink", "SR Research EyeLink (1000 Plus, Portable Duo, ...)", ("sr_research", "eyelink"),
        "eyelink", "psychopy-eyetracker-sr-research", "psychopy_eyetracker_sr_research",
        "own", "the EyeLink host PC's clock (ms); ioHub subtracts the link delay it measures "
        "against the host's clock",
        device_class="eyetracker.hw.sr_research.eyelink.EyeTracker"),
    TrackerFamily(
        "tobii", "Tobii Pro (through ioHub)", ("tobii",), "tobii-iohub",
        "psychopy-eyetracker-tobii", "psychopy_eyetracker_tobii", "own",
        "the Tobii SDK's system_time_stamp (us), mapped by the plugin",
        device_class="eyetracker.hw.tobii.EyeTracker"),
    TrackerFamily(
        "gazepoint", "Gazepoint GP3", ("gazepoint", "gp3"), "gazepoint",
        "psychopy-eyetracker-gazepoint", "psychopy_eyetracker_gazepoint", "own",
        "Gazepoint Control's TIME (s since it started)",
        device_class="eyetracker.hw.gazepoint.gp3.EyeTracker"),
    TrackerFamily(
        "pupil-labs", "Pupil Labs (Core, Neon)", ("pupil_labs", "pupil_core", "neon"),
        "pupil-labs", "psychopy-eyetracker-pupil-labs", "psychopy_eyetracker_pupil_labs", "own",
        "Pupil's clock, synchronised by the plugin",
        device_class="eyetracker.hw.pupil_labs.pupil_core.EyeTracker"),
    TrackerFamily(
        "eyelogic", "EyeLogic", ("eyelogic",), "eyelogic", "psychopy-eyetracker-eyelogic",
        "psychopy_eyetracker_eyelogic", "own", "the EyeLogic server's clock (ns)",
        device_class="eyetracker.eyelogic.psychopy.eyetracker.EyeTracker"),
    TrackerFamily(
        "mousegaze", "ioHub MouseGaze (the mouse as gaze)", ("mouse",), None, None, None, "none",
        "PsychoPy's clock (the samples are made by the ioHub server)", pilot=True,
        device_class="eyetracker.hw.mouse.EyeTracker"),
)
#: A device class path no family names (a third-party ioHub tracker): installed by the lab.
#: Its label reads after "the" in messages ("the ioHub eye tracker (eyetracker.hw.acme...)").
OTHER = TrackerFamily("other", "ioHub eye tracker", (), None, None, None, "own",
                      "the tracker's own")


def family_of(device_class: str) -> TrackerFamily:
    """The family of an ioHub device class path (``eyetracker.hw.sr_research.eyelink.EyeTracker``
    -> EyeLink), :data:`OTHER` when none matches."""
    parts = device_class.lower().split(".")
    for fam in FAMILIES:
        if any(m in parts for m in fam.match):
            return fam
    return OTHER


def check_plugin(family: TrackerFamily, find: Any = None) -> str | None:
    """The plugin's version, or None where the family needs none; a FovexpError naming the
    extra to install when the plugin is missing (``find``: a module finder, for the tests)."""
    if family.module is None:
        return None
    import importlib.metadata
    import importlib.util

    finder = find or importlib.util.find_spec
    if finder(family.module) is None:
        raise FovexpError(
            f"--tracker iohub with a {family.label} needs PsychoPy's plugin "
            f"{family.distribution}: pip install 'fovexp[{family.extra}]'")
    try:
        return importlib.metadata.version(family.distribution or "")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"


def example_path(family_key: str) -> Path:
    """The shipped example configuration of the family ``family_key`` (``eyelink``, ...);
    a one-line FovexpError naming the families for any other name."""
    keys = [f.key for f in FAMILIES]
    if family_key not in keys:
        raise FovexpError(f"no example ioHub configuration {family_key!r}"
                          f"{did_you_mean(family_key, keys)}: the families are "
                          f"{', '.join(keys)}")
    return EXAMPLES_DIR / f"{family_key}.yaml"


def device_module(device_class: str) -> str:
    """The module ioHub's server imports for a device class path, by the server's own rule
    (``ioServer.addDeviceToMonitor``): :data:`IOHUB_DEVICES`, a dot, the path without its class
    name in lower case (``eyetracker.hw.mouse.EyeTracker`` ->
    ``psychopy.iohub.devices.eyetracker.hw.mouse``)."""
    head = device_class.rpartition(".")[0]
    return f"{IOHUB_DEVICES}.{head.lower()}" if head else f"{IOHUB_DEVICES}.{device_class.lower()}"


def plugin_device_modules() -> set[str]:
    """The device modules plugins add to ioHub through entry points (group
    ``psychopy.iohub.devices[.sub]``, name -> ``group.name``): the second place ioHub's
    ``importDeviceModule`` looks, EyeLogic's plugin among them."""
    import importlib.metadata

    eps: Any = importlib.metadata.entry_points()
    groups = eps.groups if hasattr(eps, "groups") else list(eps)  # Python 3.10's dict form
    out: set[str] = set()
    for group in groups:
        if group == IOHUB_DEVICES or group.startswith(IOHUB_DEVICES + "."):
            out.update(f"{group}.{ep.name}" for ep in importlib.metadata.entry_points(group=group))
    return out


def check_device_module(config: IoHubConfig, find: Callable[[str], Any] | None = None,
                        plugin_modules: Iterable[str] | None = None) -> str | None:
    """The device module of ``config``'s tracker (:func:`device_module`), checked before the
    server starts: when neither PsychoPy nor a plugin provides it (or the class name is
    ``EyeTracker`` in another case), ioHub's server prints some fifty lines of tracebacks and
    creates no tracker, so a one-line FovexpError names the module and the class paths fovexp
    knows instead. None when PsychoPy's ioHub itself is not installed (starting the server
    says so, naming the extra). ``find`` (a module finder) and ``plugin_modules``
    (:func:`plugin_device_modules`) are for the tests. Imports PsychoPy's ``psychopy.iohub``
    (a module's parents are imported to find it; no window, no display)."""
    import importlib.util

    finder = find or importlib.util.find_spec

    def found(name: str) -> bool:
        try:
            return finder(name) is not None
        except (ImportError, ValueError):  # a parent package is missing
            return False

    if not found(IOHUB_DEVICES):
        return None
    head, _, name = config.device_class.rpartition(".")
    if name.lower() == "eyetracker" and name != "EyeTracker":  # ioHub looks it up as written
        raise FovexpError(f"ioHub configuration {config.path}: {config.device_class}: ioHub's "
                          f"eye-tracker class is EyeTracker ({head}.EyeTracker)")
    module = device_module(config.device_class)
    if found(module):
        return module
    mods = plugin_device_modules() if plugin_modules is None else set(plugin_modules)
    if any(module == m or module.startswith(m + ".") for m in mods):
        return module
    what = f"ioHub has no device module {module} for {config.device_class} ({config.path})"
    fam = config.family
    if fam is not OTHER:
        raise FovexpError(f"{what}: the class path of the {fam.label} is {fam.device_class} "
                          f"({fam.install}); fovexp tracker example {fam.key} prints its "
                          "example")
    known = ", ".join(f"{f.device_class} ({f.install})" for f in FAMILIES)
    raise FovexpError(f"{what}: a misspelt class path, or a plugin that is not installed; "
                      f"the class paths fovexp knows: {known}; {EXAMPLE_HINT}")


@dataclass(frozen=True)
class IoHubConfig:
    """An ioHub eye-tracker configuration (module docstring): the tracker's device class path
    and settings, the other devices the file names, and what fovexp leaves out."""

    path: Path
    sha256: str
    device_class: str
    tracker: dict[str, Any]
    #: other devices (``Keyboard``, ``Mouse``, ...), passed on as they are
    devices: dict[str, Any]
    #: keys of the file fovexp does not pass on (its ``Display``: the profile's is used;
    #: ``data_store``: fovexp writes its own logs)
    ignored: tuple[str, ...]

    @property
    def family(self) -> TrackerFamily:
        return family_of(self.device_class)

    @property
    def name(self) -> str:
        """The device's name (``io.devices.<name>``; ioHub's default ``tracker``)."""
        return str(self.tracker.get("name") or "tracker")

    @property
    def sampling_hz(self) -> float | None:
        """``runtime_settings.sampling_rate`` (Hz), or None where the file leaves it to the
        plugin's default."""
        rt = self.tracker.get("runtime_settings") or {}
        try:
            return float(rt["sampling_rate"])
        except (KeyError, TypeError, ValueError):
            return None

    @property
    def track_eyes(self) -> str | None:
        rt = self.tracker.get("runtime_settings") or {}
        v = rt.get("track_eyes")
        return None if v is None else str(v)

    def to_dict(self) -> dict[str, Any]:
        """What the session file records."""
        return {"path": str(self.path), "sha256": self.sha256, "device_class": self.device_class,
                "family": self.family.key, "settings": self.tracker,
                "other_devices": sorted(self.devices), "ignored": list(self.ignored)}


#: Top-level keys of an ``iohub_config.yaml`` that are not devices.
_HUB_KEYS = frozenset({"monitor_devices", "data_store", "udp_port", "coverage_env_var",
                       "start_process_timeout", "global_event_buffer", "ioHub", "debug"})


def _devices(raw: Any, what: str) -> dict[str, Any]:
    """The device mapping of either form (module docstring)."""
    if not isinstance(raw, dict):
        raise FovexpError(f"{what}: expected a mapping of ioHub devices, got "
                          f"{type(raw).__name__}")
    if "monitor_devices" in raw:
        devs = raw["monitor_devices"]
        if isinstance(devs, list):
            out: dict[str, Any] = {}
            for d in devs:
                if not (isinstance(d, dict) and len(d) == 1):
                    raise FovexpError(f"{what}: each monitor_devices entry must be one "
                                      "'DeviceClass: {settings}' mapping")
                out.update(d)
            return out
        if isinstance(devs, dict):
            return dict(devs)
        raise FovexpError(f"{what}: monitor_devices must be a list or a mapping")
    return {k: v for k, v in raw.items() if k not in _HUB_KEYS}


def parse_iohub_config(text: str, path: Path) -> IoHubConfig:
    """An ioHub configuration from its YAML text (``path`` names it in errors and records)."""
    what = f"ioHub configuration {path}"
    raw = parse_yaml(text, what)
    if raw is None:  # an empty file, or comments only: YAML's null
        raise FovexpError(
            f"{what} is empty (or only comments): it must name one eye tracker by its ioHub "
            "device class path, with its settings, e.g. 'eyetracker.hw.mouse.EyeTracker: "
            f"{{name: tracker}}'; {EXAMPLE_HINT}")
    devices = _devices(raw, what)
    trackers = [k for k in devices if str(k).lower().startswith("eyetracker.")]
    if len(trackers) != 1:
        found = ", ".join(map(str, trackers)) or "none"
        raise FovexpError(
            f"{what}: needs exactly one eye tracker (a device class path such as "
            f"eyetracker.hw.sr_research.eyelink.EyeTracker or eyetracker.hw.mouse.EyeTracker); "
            f"found {found}")
    device_class = str(trackers[0])
    settings = devices.pop(device_class) or {}
    if not isinstance(settings, dict):
        raise FovexpError(f"{what}: the settings of {device_class} must be a mapping")
    if settings.get("enable") is False:
        raise FovexpError(f"{what}: {device_class} has enable: false")
    ignored = [k for k in ("Display",) if devices.pop(k, None) is not None]
    if isinstance(raw, dict):
        ignored += [k for k in ("data_store",) if k in raw]
    sha = hashlib.sha256(text.encode("utf-8")).hexdigest()
    return IoHubConfig(Path(path), sha, device_class, dict(settings), devices, tuple(ignored))


def load_iohub_config(path: str | Path) -> IoHubConfig:
    """:func:`parse_iohub_config` of the file ``path`` (one-line errors naming it), or of a
    family's shipped example when ``path`` is ``example:FAMILY`` (:func:`example_path`)."""
    if str(path).startswith(EXAMPLE_PREFIX):
        path = example_path(str(path)[len(EXAMPLE_PREFIX):])
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise FovexpError(f"cannot read ioHub configuration {path}: {exc.strerror}") from None
    except UnicodeDecodeError:
        raise FovexpError(f"ioHub configuration {path} is not UTF-8 text") from None
    return parse_iohub_config(text, path)


def display_config(display: Any, screen: int) -> dict[str, Any]:
    """ioHub's ``Display`` device for the session's screen: the display profile's physical size
    and viewing distance (mm), positions in pixels (origin at the screen's centre, y up)."""
    return {
        "name": "display", "reporting_unit_type": "pix", "device_number": int(screen),
        "physical_dimensions": {"width": 10.0 * float(display.width_cm),
                                "height": 10.0 * float(display.height_cm), "unit_type": "mm"},
        "default_eye_distance": {"surface_center": 10.0 * float(display.distance_cm),
                                 "unit_type": "mm"},
        "override_using_psycho_settings": False,
    }


def hub_config(config: IoHubConfig, display: Any, screen: int,
               overrides: dict[str, Any] | None = None) -> dict[str, Any]:
    """The ``iohub_config.yaml`` the server starts with (``launchHubServer(iohub_config_name=
    ...)``): fovexp's ``Display``, the file's other devices, and its tracker (with
    ``overrides`` merged into the tracker's settings, one level deep); its ``Keyboard`` uses
    PsychoPy's key names unless the file says otherwise."""
    tracker = dict(config.tracker)
    for k, v in (overrides or {}).items():
        tracker[k] = {**tracker.get(k, {}), **v} if isinstance(v, dict) else v
    tracker.setdefault("name", "tracker")
    others = {k: dict(v or {}) for k, v in config.devices.items()}
    # PsychoPy's key names ('space', 'return'): the window reads keys through ioHub's keyboard
    # while a server runs
    others.setdefault("Keyboard", {}).setdefault("use_keymap", "psychopy")
    devices = [{"Display": display_config(display, screen)}]
    devices += [{k: v} for k, v in others.items()]
    devices.append({config.device_class: tracker})
    return {"monitor_devices": devices}


__all__ = ["EXAMPLES_DIR", "EXAMPLE_PREFIX", "FAMILIES", "OTHER", "IoHubConfig", "TrackerFamily",
           "check_device_module", "check_plugin", "device_module", "display_config",
           "example_path", "family_of", "hub_config", "load_iohub_config",
           "parse_iohub_config", "plugin_device_modules"]
