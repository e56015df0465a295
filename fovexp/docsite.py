"""``fovexp docs``: the documentation site, unpacked where a browser can open it.

The site (docs/*.md and the API reference made from the docstrings, MkDocs Material) is built
by every wheel's build (``build_backend/fovexp_build.py``) or by ``./dev docs`` (``mkdocs build
--strict``) and packed into ``fovexp/site.zip``, which the wheel ships as package data, so a lab
with only the wheel has the documentation, offline. The
first ``fovexp docs`` unpacks it into the user's cache folder (one folder per packed site); its
pages open from disk (``file://``), search included (docs/DOCS.md).
"""

from __future__ import annotations

import argparse
import hashlib
import shutil
import sys
import tempfile
import zipfile
from pathlib import Path
from typing import Any

from ._version import __version__
from .errors import FovexpError

#: the packed site inside the package
SITE_ZIP = "site.zip"


def packed_site() -> Path:
    """The packed site's path in the package (it may be absent: :func:`site_folder` says so)."""
    return Path(__file__).resolve().parent / SITE_ZIP


def site_folder(cache: Path | None = None) -> Path:
    """The site, unpacked (once per packed site) into ``cache`` (default: the user's cache
    folder, ``platformdirs.user_cache_dir("fovexp")``). Raises FovexpError when this
    installation has no packed site."""
    packed = packed_site()
    if not packed.is_file():
        raise FovexpError(
            f"this installation has no documentation site ({packed} is missing): it is an "
            "editable install of a checkout in which the site was not built. Build it there "
            "with './dev docs' (pip install 'fovexp[docs]'), or read docs/*.md in the source")
    if cache is None:
        import platformdirs

        cache = Path(platformdirs.user_cache_dir("fovexp", appauthor=False))
    digest = hashlib.sha256(packed.read_bytes()).hexdigest()[:12]
    folder = cache / f"docs-{__version__}-{digest}"
    if not (folder / "index.html").is_file():
        cache.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=".docs-", dir=cache))
        try:
            with zipfile.ZipFile(packed) as zf:
                zf.extractall(tmp)
            try:
                tmp.rename(folder)
            except OSError:  # another fovexp docs unpacked it meanwhile
                if not (folder / "index.html").is_file():
                    raise
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
    return folder


def site_page(page: str = "index", cache: Path | None = None) -> Path:
    """A page of the site (``index``, ``STUDY``, ``EXPERIMENT``, ``reference/fovexp``, ...),
    its name in any case (``study`` is ``STUDY``); raises FovexpError when the site or the
    page is not there."""
    folder = site_folder(cache)
    pages = {p.relative_to(folder).with_suffix("").as_posix(): p
             for p in folder.rglob("*.html") if p.stem != "404"}
    name = page.removesuffix(".html").removesuffix(".md")
    by_folded = {key.casefold(): path for key, path in pages.items()}
    path = pages.get(name) or by_folded.get(name.casefold())
    if path is None:
        raise FovexpError(f"no page {page!r} in the documentation site (pages: "
                          f"{', '.join(sorted(pages))})")
    return path


def add_docs_parser(subparsers: Any) -> argparse.ArgumentParser:
    p = subparsers.add_parser(
        "docs", help="the documentation: print where the built site is, or open it",
        description="The documentation site shipped with fovexp (the guides and the API "
        "reference; it works offline, from disk). Prints the path of its page; --open opens "
        "it in the default web browser.")
    p.add_argument("page", nargs="?", default="index",
                   help="a page: index (default), STUDY (your own study), EXPERIMENT, "
                   "ANALYSIS, LOGS, API, ...")
    p.add_argument("--open", action="store_true", help="open it in the default web browser")
    p.set_defaults(func=docs_command)
    return p


def docs_command(args: argparse.Namespace) -> int:
    try:
        path = site_page(args.page)
    except FovexpError as exc:
        print(f"fovexp docs: error: {exc}", file=sys.stderr)
        return 2
    print(path)
    if args.open:
        import webbrowser

        if not webbrowser.open(path.as_uri()):
            print(f"fovexp docs: no web browser found; open {path.as_uri()}", file=sys.stderr)
            return 2
    return 0
