"""Where the shipped data are: display profiles, protocols and the generated scenes' pins.

They live in the project's top-level folders (``protocols/``, ``protocols/displays/``,
``stimuli/``) and are installed inside the package as ``fovexp.protocols`` and
``fovexp.stimuli.shipped`` (pyproject.toml), so the same lookup works from a clone (an editable
install) and from a wheel, in any folder. A lab's own files come first: a name is searched in
``./protocols`` (``./protocols/displays``) of the current folder before the shipped ones.
"""

from __future__ import annotations

import importlib.resources
from pathlib import Path

from .errors import FovexpError


def shipped(package: str) -> Path:
    """The folder of a data package (``"fovexp.protocols"``, ``"fovexp.stimuli.shipped"``)."""
    return Path(str(importlib.resources.files(package)))


def shipped_protocols() -> Path:
    """The paper's protocols (``calibration-fe.yaml`` ..., ``validation-12.yaml``)."""
    return shipped("fovexp.protocols")


def shipped_displays() -> Path:
    """The shipped display profiles (``lg-oled55cx.yaml``)."""
    return shipped_protocols() / "displays"


def shipped_stimuli() -> Path:
    """The folder of the shipped stimulus data: ``scenes.yaml``, the generated scenes' sha256
    per resolution (read-only; the scenes themselves go to a lab's stimulus folder,
    ``fovexp.stimuli.folder``)."""
    return shipped("fovexp.stimuli.shipped")


def find_protocol(name_or_path: str | Path) -> Path:
    """A protocol file: ``name_or_path`` itself when it is a file, else ``NAME.yaml`` in
    ``./protocols`` or among the shipped protocols (``fovexp run validation``).

    >>> from fovexp import find_protocol
    >>> find_protocol("calibration-sk").name
    'calibration-sk.yaml'
    >>> find_protocol("no-such-protocol")
    Traceback (most recent call last):
    fovexp.errors.FovexpError: ...
    """
    path = Path(name_or_path)
    if path.is_file():
        return path
    if path.suffix in (".yaml", ".yml") or len(path.parts) > 1:
        raise FovexpError(f"protocol {str(name_or_path)!r} does not exist")
    folders = [Path.cwd() / "protocols", shipped_protocols()]
    for folder in folders:
        candidate = folder / f"{name_or_path}.yaml"
        if candidate.is_file():
            return candidate
    known = sorted(p.stem for p in shipped_protocols().glob("*.yaml"))
    raise FovexpError(f"protocol {str(name_or_path)!r} not found (looked in "
                      f"{', '.join(str(f) for f in folders)}; shipped: {', '.join(known)})")
