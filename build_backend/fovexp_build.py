"""fovexp's build backend: setuptools', with the documentation site built into every wheel.

A wheel, however a lab builds it (``python -m build``, ``python -m build --wheel``, ``pip wheel
.``, ``pip install .``), ships the documentation site as ``fovexp/site.zip`` (docs/DOCS.md), so
that ``fovexp docs`` works from the wheel alone. Before setuptools builds a wheel or an sdist,
this backend makes sure the packed site is the one of the tree being built:

- the tree has the site's sources (``mkdocs.yml``) and a packed site stamped with their digest
  (``build_backend/site_inputs.py``; ``./dev docs`` writes it): used as it is;
- the tree has the sources and no packed site, or a stale one: the site is built, strict
  (``mkdocs build --strict``), and the build fails with MkDocs' own words when it does not build.
  MkDocs and its plugins are then asked for as build requirements (the ``[docs]`` extra,
  read from pyproject.toml), only for this case;
- the tree has no sources but a packed site (an sdist, which ships the site built rather than
  the pages, their images and the files they link to): used as it is.

An editable install (``pip install -e .``, ``./dev setup``) builds no site: the checkout's own
``./dev docs`` does.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path
from typing import Any

from setuptools import build_meta as _setuptools
from setuptools.build_meta import (  # noqa: F401 (the hooks this backend does not change)
    build_editable,
    get_requires_for_build_editable,
    prepare_metadata_for_build_editable,
    prepare_metadata_for_build_wheel,
)
from site_inputs import packed_stamp, site_inputs_digest

ROOT = Path.cwd()
SITE_ZIP = ROOT / "fovexp" / "site.zip"


class SiteBuildError(RuntimeError):
    """The documentation site could not be built, so no wheel is."""


def _docs_requirements() -> list[str]:
    """The ``[docs]`` extra of pyproject.toml: one list of MkDocs' pins for the project."""
    try:
        import tomllib  # Python 3.11+
        with open(ROOT / "pyproject.toml", "rb") as f:
            data = tomllib.load(f)
    except ModuleNotFoundError:
        from setuptools.config.pyprojecttoml import load_file

        data = load_file(ROOT / "pyproject.toml")
    return list(data["project"]["optional-dependencies"]["docs"])


def _site_state() -> str:
    """'current', 'stale' (sources here, packed site absent or of other sources) or 'shipped'
    (no sources, a packed site: an sdist's); raises when there is neither."""
    if (ROOT / "mkdocs.yml").is_file():
        return "current" if packed_stamp(SITE_ZIP) == site_inputs_digest(ROOT) else "stale"
    if SITE_ZIP.is_file():
        return "shipped"
    raise SiteBuildError(
        f"{ROOT} has neither the documentation's sources (mkdocs.yml, docs/) nor a built site "
        "(fovexp/site.zip): build from a clone of the repository or from fovexp's sdist")


def _ensure_site() -> None:
    if _site_state() != "stale":
        return
    try:
        import mkdocs  # noqa: F401
    except ModuleNotFoundError:
        raise SiteBuildError(
            "building fovexp builds its documentation site, which needs MkDocs: build with "
            "build isolation (the default: the backend asks for it), or install the docs extra "
            "first (pip install 'fovexp[docs]' from the checkout)") from None
    print("fovexp: building the documentation site (mkdocs build --strict)", file=sys.stderr)
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    # not --quiet: it hides the warnings, and strict mode fails only on the warnings it sees
    run = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict"],
                         cwd=ROOT, env=env, capture_output=True, text=True)
    if run.returncode != 0 or packed_stamp(SITE_ZIP) != site_inputs_digest(ROOT):
        SITE_ZIP.unlink(missing_ok=True)  # never ship a site from a failed build
        out = "\n".join(line for line in (run.stdout + run.stderr).splitlines()
                        if not line.startswith("INFO"))[-4000:]
        raise SiteBuildError(
            "the documentation site does not build (mkdocs build --strict), so no wheel is "
            f"built. MkDocs said:\n{out or '(nothing)'}")


def get_requires_for_build_wheel(config_settings: Any = None) -> list[str]:
    reqs = list(_setuptools.get_requires_for_build_wheel(config_settings))
    return reqs + (_docs_requirements() if _site_state() == "stale" else [])


def get_requires_for_build_sdist(config_settings: Any = None) -> list[str]:
    reqs = list(_setuptools.get_requires_for_build_sdist(config_settings))
    return reqs + (_docs_requirements() if _site_state() == "stale" else [])


def build_wheel(wheel_directory: str, config_settings: Any = None,
                metadata_directory: str | None = None) -> str:
    _ensure_site()
    return _setuptools.build_wheel(wheel_directory, config_settings, metadata_directory)


def build_sdist(sdist_directory: str, config_settings: Any = None) -> str:
    _ensure_site()
    return _setuptools.build_sdist(sdist_directory, config_settings)
