"""``fovexp init``: a lab's own study folder, made from the shipped protocols, that works where
it lands (docs/STUDY.md).

::

    DIR/
      fovexp-study.yaml   marks the study folder (its name, the protocols, fovexp's version)
      README.md           the study's next commands (also printed)
      protocols/          copies of the named shipped protocols, ready to edit, each named
                          after its experiment (``fovexp run NAME`` finds it from DIR)
      stimuli/            the stimulus folder of every command run in DIR (or below it)
      results/            where ``fovexp run`` writes from DIR (``--results`` default)

Each copy keeps the shipped text (its comments too), with three lines set so that it loads
from its new place and keeps the lab's runs apart:

- ``experiment:`` the study's name (``--name``, default the folder's name) for a protocol whose
  wheel adjusts the blur-rate (the validation; ``NAME-<protocol>`` when there are several).
  The calibration protocols keep their names: the chain between them (``fe_results:
  calibration-fe``, ``{table: .}``) and the analysis' Table 2 find their results by those
  names, in the study's own ``results/``;
- ``display:`` the profile's name (``lg-oled55cx``) instead of the shipped path
  ``displays/lg-oled55cx.yaml``, which is relative to the shipped protocol's folder; a profile
  that is not shipped is copied into ``protocols/displays/``;
- ``stimuli: ../stimuli``: the study's stimulus folder, from wherever the protocol is run.

It writes everything into a temporary folder beside ``DIR`` and renames it into place once
every copy has loaded, so a failed ``init`` leaves nothing, and it never overwrites: an existing
``DIR`` that is not empty is refused.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from fovexp import FovexpError, __version__, did_you_mean, shipped_protocols
from fovexp.stimuli.folder import STUDY_FILE

#: what ``init`` copies when no ``--from`` is given
DEFAULT_PROTOCOLS = ("validation",)
#: a study's name becomes an experiment's name: the protocol's own pattern
NAME_PATTERN = r"[a-z0-9][a-z0-9_-]{0,40}"
STUDY_README = "README.md"


@dataclass
class Study:
    """What :func:`init_study` made."""

    folder: Path
    name: str
    #: protocol file (relative to the folder) -> its experiment's name
    protocols: dict[str, str] = field(default_factory=dict)
    display: str = ""
    size: tuple[int, int] = (0, 0)
    commands: str = ""


def study_name(text: str) -> str:
    """``text`` as a study (experiment) name: lower case, other characters as ``-``; refused
    when nothing usable is left."""
    name = re.sub(r"[^a-z0-9_-]+", "-", text.strip().lower()).strip("-_")[:41]
    if re.fullmatch(NAME_PATTERN, name) is None:
        raise FovexpError(f"--name {text!r}: a study's name needs a letter or digit first, "
                          "then up to 40 of a-z 0-9 _ - (it names the experiment)")
    return name


def _source(name: str) -> Path:
    """A shipped protocol by name, or a protocol file by path."""
    path = Path(name)
    if path.suffix in (".yaml", ".yml") or len(path.parts) > 1:
        if not path.is_file():
            raise FovexpError(f"--from {name}: no such protocol file")
        return path
    shipped = sorted(p.stem for p in shipped_protocols().glob("*.yaml"))
    if name not in shipped:
        raise FovexpError(f"--from {name}: not a shipped protocol{did_you_mean(name, shipped)} "
                          f"(shipped: {', '.join(shipped)}; or give a protocol file's path)")
    return shipped_protocols() / f"{name}.yaml"


def _set_key(text: str, key: str, value: str, after: str | None = None) -> str:
    """``text`` with its top-level ``key:`` line set to ``value`` (the rest of the file, its
    comments included, as it was); a key that is not there goes after the ``after`` line."""
    line = f"{key}: {value}"
    pattern = re.compile(rf"^{re.escape(key)}:[^\n]*$", re.MULTILINE)
    if pattern.search(text):
        return pattern.sub(lambda _: line, text, count=1)
    if after is not None:
        anchor = re.compile(rf"^{re.escape(after)}:[^\n]*$", re.MULTILINE).search(text)
        if anchor is not None:
            return text[:anchor.end()] + "\n" + line + text[anchor.end():]
    return text.rstrip("\n") + "\n" + line + "\n"


def _display_line(source: Path, display: str) -> tuple[str, Path | None]:
    """The ``display:`` value that loads from the copy's folder, and a profile file to copy
    into ``protocols/displays/`` (None: the value names a shipped profile or an absolute
    path)."""
    if not display.endswith((".yaml", ".yml")):
        beside = source.resolve().parent / "displays" / f"{display}.yaml"
        return (f"displays/{display}.yaml", beside) if beside.is_file() else (display, None)
    path = Path(display).expanduser()
    if not path.is_absolute():
        path = (source.resolve().parent / path).resolve()
    if not path.is_file():
        raise FovexpError(f"{source}: display: cannot read display profile {path}")
    shipped = shipped_protocols() / "displays"
    if path.parent.resolve() == shipped.resolve():
        return path.stem, None  # a shipped profile, by name
    return f"displays/{path.name}", path


def init_study(folder: str | Path, sources: list[str] | None = None,
               name: str | None = None) -> Study:
    """Make the study folder ``folder`` (module docstring) from the protocols ``sources``
    (shipped names or paths; default :data:`DEFAULT_PROTOCOLS`). Raises FovexpError, leaving
    nothing, when ``folder`` exists and is not empty, or a protocol does not load."""
    from .spec import Protocol, protocol_display, read_protocol

    folder = Path(folder).expanduser()
    if folder.exists() and (not folder.is_dir() or any(folder.iterdir())):
        raise FovexpError(f"{folder} already exists and is not empty: fovexp init never "
                          "overwrites a folder (choose a new one, or remove it first)")
    name = study_name(name if name is not None else folder.resolve().name)
    paths = list(dict.fromkeys(_source(s) for s in (sources or DEFAULT_PROTOCOLS)))
    specs = [read_protocol(p)[1] for p in paths]
    validations = [p for p, s in zip(paths, specs, strict=True)
                   if s.adjust.parameter == "blur_rate"]
    study = Study(folder, name)
    folder.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{folder.name}.init-", dir=folder.parent))
    try:
        umask = os.umask(0)
        os.umask(umask)
        tmp.chmod(0o777 & ~umask)  # a folder like any new one (mkdtemp's is private)
        for sub in ("protocols", "stimuli", "results"):
            (tmp / sub).mkdir()
        displays: set[str] = set()
        for path, spec in zip(paths, specs, strict=True):
            text = path.read_bytes().decode("utf-8")
            experiment = spec.experiment
            if path in validations:
                experiment = name if len(validations) == 1 else f"{name}-{path.stem}"[:41]
                text = _set_key(text, "experiment", experiment)
            if experiment in study.protocols.values():
                raise FovexpError(f"--from: two protocols of experiment {experiment!r}")
            line, profile = _display_line(path, spec.display)
            if profile is not None:
                target = tmp / "protocols" / "displays" / profile.name
                target.parent.mkdir(exist_ok=True)
                if not target.exists():
                    shutil.copyfile(profile, target)
            text = _set_key(text, "display", line)
            text = _set_key(text, "stimuli", "../stimuli", after="display")
            copy = tmp / "protocols" / f"{experiment}.yaml"  # fovexp run EXPERIMENT finds it
            copy.write_text(text, encoding="utf-8")
            _, loaded = read_protocol(copy)  # the copy loads where it is
            assert isinstance(loaded, Protocol)
            _, display = protocol_display(copy, loaded)
            displays.add(display.name)
            study.display = display.name
            study.size = (int(display.width_px), int(display.height_px))
            study.protocols[f"protocols/{copy.name}"] = experiment
        if len(displays) > 1:
            raise FovexpError(f"--from: the protocols name different displays "
                              f"({', '.join(sorted(displays))}); make one study per display")
        marker = {"study": name, "made_by": f"fovexp {__version__} (fovexp init)",
                  "protocols": dict(study.protocols), "display": study.display}
        (tmp / STUDY_FILE).write_text(
            "# A fovexp study folder (fovexp init). Commands run in this folder, or below it,\n"
            "# keep their stimuli in its stimuli/ (docs/STUDY.md).\n"
            + yaml.safe_dump(marker, sort_keys=False), encoding="utf-8")
        study.commands = next_commands(study)
        (tmp / STUDY_README).write_text(study_readme(study), encoding="utf-8")
        if folder.exists():
            folder.rmdir()  # empty (checked above); the rename puts the study in its place
        tmp.rename(folder)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return study


def study_protocols(study: Path) -> list[Path]:
    """The protocol files the study folder ``study`` lists in its :data:`STUDY_FILE` (the
    ``protocols`` :func:`init_study` wrote), those that exist, in the listed order."""
    from fovexp import read_yaml

    marker = read_yaml(study / STUDY_FILE, "study file")
    listed = marker.get("protocols") if isinstance(marker, dict) else None
    paths = [study / str(p) for p in listed] if isinstance(listed, (dict, list)) else []
    return [p for p in paths if p.is_file()]


def _size(size: tuple[int, int]) -> str:
    return f"{size[0]}x{size[1]}"


#: the comment that ends the commands a machine without the rig can run (``.ci/study-walk``
#: runs the printed commands up to it)
ON_THE_RIG = "# on the rig:"


def next_commands(study: Study) -> str:
    """The study's next commands, run from its folder (printed by ``init``, in its README, and
    docs/STUDY.md's recipe; ``.ci/study-walk`` runs them as printed). The test runs (the rig
    check's and the session's rehearsals) write into ``test-results/``, so that the study's
    ``results/`` holds only its participants."""
    size = _size(study.size)
    calib = [p for p, e in study.protocols.items() if e.startswith("calibration-")]
    valid = [p for p in study.protocols if p not in calib]
    main = valid[0] if valid else calib[0]
    main_name = Path(main).stem
    xvfb = f"xvfb-run -a -s '-screen 0 {size}x24'"
    lines = [
        f"cd {study.folder}",
        f"fovexp stimuli add FRAME.png --id lab-01 --licence CC-BY-4.0    # each frame, {size}",
        f"#   then name their ids in {main}: images: [lab-01, ...]",
        f"fovexp stimuli check {' '.join(Path(p).stem for p in study.protocols)}",
        f"{xvfb} fovexp rig check --dry-run --results test-results    # the rig check, rehearsed",
        f"{xvfb} fovexp run {main_name} --participant SIM01 --dry-run --window {size} "
        "--limit-trials 2 --practice 0 --sim-truth quick --results test-results"
        "    # a rehearsal at the display's size",
        "fovexp analyze test-results --out test-report",
        f"{ON_THE_RIG} the rig check, then each participant's session, then the analysis",
        "fovexp rig check",
        f"fovexp run {main_name} --participant P01",
        "fovexp analyze results --out report",
    ]
    return "\n".join(lines)


def study_readme(study: Study) -> str:
    """The study folder's README: what is where, and the next commands."""
    rows = "\n".join(f"| `{p}` | `{e}` |" for p, e in study.protocols.items())
    return f"""# Study `{study.name}`

Made by `fovexp init` (fovexp {__version__}). Run the commands below from this folder: its
`stimuli/` is the stimulus folder of every fovexp command run here, and `fovexp run` writes
into `results/`. `fovexp docs` shows the documentation (the guide to a study: "Your own
study").

| protocol | experiment (results/<experiment>/) |
|---|---|
{rows}

Every protocol names its display by the profile's name (`display: {study.display}`, a shipped
profile; a profile of your own goes in `protocols/displays/NAME.yaml` and is named the same
way) and this folder's stimuli (`stimuli: ../stimuli`). A real session shows every image at
the display's own size, {_size(study.size)}, and so does a dry run with `--window
{_size(study.size)}`: it refuses what the real session refuses. The dry run needs an X screen
that large (`xvfb-run -a -s '-screen 0 {_size(study.size)}x24'` on a machine without one).

## Next

```
{study.commands}
```

A rig installs `pip install 'fovexp[experiment,gpu,tracker]'` and runs `fovexp compile` once.
"""


# -- the command --------------------------------------------------------------------------------
def add_init_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add the ``init`` subcommand to ``subparsers`` (``fovexp.cli`` registers it)."""
    p = subparsers.add_parser(
        "init", help="make a study folder from the shipped protocols",
        description="Make DIR a study folder: protocols/ with copies of the named shipped "
        "protocols (experiment: set to NAME, display: and stimuli: lines that load from "
        "there), stimuli/ (the stimulus folder of every command run in DIR), results/, and a "
        "README with the next commands, which are also printed. Never overwrites: DIR must "
        "not exist or be empty. This is also how to get a shipped protocol out of the package.")
    p.add_argument("folder", type=Path, metavar="DIR")
    p.add_argument("--from", dest="sources", action="append", default=None, metavar="PROTOCOL",
                   help="a shipped protocol's name (calibration-fe, calibration-sk, "
                   "calibration-sf, validation) or a protocol file; repeat for several "
                   f"(default: {', '.join(DEFAULT_PROTOCOLS)})")
    p.add_argument("--name", default=None,
                   help="the study's name, the experiment of its validation protocol (default: "
                   "DIR's name)")
    p.set_defaults(func=init_command)
    return p


def init_command(args: argparse.Namespace) -> int:
    try:
        study = init_study(args.folder, args.sources, args.name)
    except FovexpError as exc:
        print(f"fovexp init: error: {exc}", file=sys.stderr)
        return 2
    listed = ", ".join(f"{p} (experiment {e})" for p, e in study.protocols.items())
    print(f"fovexp init: study {study.name} in {study.folder}: {listed}; stimuli/, results/, "
          f"README.md")
    print("next:")
    print("\n".join(f"  {line}" for line in study.commands.splitlines()))
    return 0
