"""MkDocs hooks of the documentation site (mkdocs.yml; docs/DOCS.md).

- The API reference pages (``reference/*.md``) are made here, not kept in docs/, so that docs/
  stays a set of pages that read well on GitHub: each is a list of mkdocstrings directives
  (``::: fovexp.Enhancer``), rendered from the docstrings.
- docs/*.md link to the project's other files (``../benchmarks/BENCH.md``) and name each other
  in prose (``docs/LOGS.md``). In the site a link out of docs/ becomes the file's path in the
  source repository (the installed site has no benchmarks/), and a page named in prose becomes
  a link to it. Either, naming a file that does not exist, is a warning, and ``mkdocs build
  --strict`` fails on it, as on MkDocs' own broken links and anchors.
"""

from __future__ import annotations

import logging
import posixpath
import re
import sys
from pathlib import Path
from typing import Any

from mkdocs.plugins import event_priority
from mkdocs.structure.files import File, Files

log = logging.getLogger("mkdocs.plugins.fovexp")

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "build_backend"))
from site_inputs import STAMP_PREFIX, site_inputs_digest  # noqa: E402 (the path just above)

#: The reference pages: path -> (title, introduction, directives). A directive is an object's
#: dotted path, optionally with the members to show.
REFERENCE: dict[str, tuple[str, str, list[tuple[str, list[str] | None]]]] = {
    "reference/protocol.md": (
        "Protocols", "A protocol file's keys and their checks (docs/EXPERIMENT.md, \"The "
        "protocols\"), and how a loaded protocol plans a session.",
        [("fovexp.experiment.protocol.spec", ["Protocol", "AdjustSpec", "ParamSource",
                                               "FixationSpec", "TrackerSpec", "RenderSpec",
                                               "load_protocol", "LoadedProtocol", "limit_order",
                                               "protocol_display"]),
         ("fovexp.experiment.protocol.defaults", None)]),
    "reference/stimuli.md": (
        "Stimuli and study folders", "The stimulus folder, the checks a session makes of its "
        "images, and the study folder `fovexp init` makes (docs/STUDY.md).",
        [("fovexp.stimuli.folder", ["StimulusSet", "ImageCheck", "may_scale", "find_folder",
                                    "find_study", "generate_scenes"]),
         ("fovexp.experiment.protocol.study", ["init_study", "Study", "next_commands"])]),
    "reference/results.md": (
        "Trial logs", "The log formats the runner writes and the analysis reads "
        "(docs/LOGS.md), and loading them with the exclusion rules.",
        [("fovexp.results.format", None),
         ("fovexp.results.loading", ["load_results", "Dataset", "Exclusion", "rules"])]),
    "reference/analysis.md": (
        "Analysis", "`fovexp analyze` as functions (docs/ANALYSIS.md).",
        [("fovexp.analysis.report", ["run_analysis"]),
         ("fovexp.analysis.validation", ["validate", "ValidationResult",
                                         "one_participant_reason"]),
         ("fovexp.analysis.stats", None)]),
}


def _directive(path: str, members: list[str] | None) -> str:
    if members is None:
        return f"::: {path}\n"
    listed = ", ".join(members)
    return f"::: {path}\n    options:\n      members: [{listed}]\n"


def _public_api_page() -> str:
    import fovexp

    names = [n for n in fovexp.__all__ if not n.startswith("__")]
    parts = ["# fovexp: the public API\n",
             "Every name the package `fovexp` exports (docs/API.md says how they fit "
             "together), from its docstring. The runner and the analysis use only these.\n"]
    parts += [f"::: fovexp.{n}\n    options:\n      show_root_full_path: false\n"
              for n in names]
    return "\n".join(parts)


def on_files(files: Files, config: Any) -> Files:
    files.append(File.generated(config, "reference/fovexp.md", content=_public_api_page()))
    for path, (title, intro, items) in REFERENCE.items():
        text = f"# {title}\n\n{intro}\n\n" + "\n".join(_directive(p, m) for p, m in items)
        files.append(File.generated(config, path, content=text))
    return files


_FENCE = re.compile(r"^(```|~~~)")
_LINK = re.compile(r"(?<!!)\[([^\]]+)\]\(([^)\s]+)\)")
_CODE = re.compile(r"(`+)(.+?)\1")
_DOC_MENTION = re.compile(r"(?<![\w/.`-])docs/([A-Za-z0-9_-]+\.md)\b")
#: a file of the source repository that no installation has (issue 32): the tests, the
#: benchmarks' records and scripts, CI's scripts, the development script
_REPO_ONLY = re.compile(r"(?:tests|benchmarks|\.ci)/[\w./-]*|\./dev\b[^`]*")
_REPO_MENTION = re.compile(r"(?<![\w/.`-])((?:tests|benchmarks)/[\w/-]+(?:\.[a-z]+)?)")
#: what a repository-only path gets in the site: a marker that says so, linking the index's
#: paragraph on it
_REPO_MARK = ('<sup title="a file of the source repository, not of an installed fovexp">'
              "[repo]({index}#files-of-the-source-repository)</sup>")


def _outside_link(match: re.Match[str], page_dir: Path, docs: Path, where: str) -> str:
    text, target = match.group(1), match.group(2)
    if re.match(r"^[a-z]+:", target) or target.startswith("#"):
        return match.group(0)
    path = (page_dir / target.split("#")[0]).resolve()
    if path == docs or docs in path.parents:
        return match.group(0)  # MkDocs checks links inside the site
    if not path.exists():
        log.warning(f"{where}: link to {target}, which does not exist in the repository")
        return match.group(0)
    rel = path.relative_to(ROOT).as_posix()
    return f"{text} (`{rel}` in the source repository)"


def _mention(match: re.Match[str], pages: set[str], docs: Path, page: str, where: str) -> str:
    name = match.group(1)
    if not (docs / name).is_file():
        log.warning(f"{where}: names docs/{name}, which does not exist")
        return match.group(0)
    if name not in pages or name == page:
        return match.group(0)
    return f"[docs/{name}]({_rel(name, page)})"


def _repo_mark(page: str) -> str:
    return _REPO_MARK.format(index=_rel("index.md", page))


def _mark_repo_mentions(line: str, page: str) -> str:
    """A repository-only path named in prose (outside code spans, links and the markers
    already made) gets the marker too."""
    pieces, last = [], 0
    for m in re.finditer(r"`+.+?`+|\[[^\]]*\]\([^)]*\)|<sup[^>]*>.*?</sup>", line):
        pieces.append(_REPO_MENTION.sub(lambda x: x.group(1) + _repo_mark(page),
                                        line[last:m.start()]))
        pieces.append(m.group(0))
        last = m.end()
    pieces.append(_REPO_MENTION.sub(lambda x: x.group(1) + _repo_mark(page), line[last:]))
    return "".join(pieces)


def _rel(target: str, page: str) -> str:
    """``target`` (a path in docs/) as a link from the page ``page``."""
    return posixpath.relpath(target, posixpath.dirname(page) or ".")


def on_page_markdown(markdown: str, page: Any, config: Any, files: Files) -> str:
    docs = Path(config["docs_dir"]).resolve()
    src = page.file.src_uri
    page_dir = (docs / src).parent
    pages = {f.src_uri for f in files.documentation_pages()}
    out, fenced = [], False
    for line in markdown.splitlines(keepends=True):
        if _FENCE.match(line.lstrip()):
            fenced = not fenced
            out.append(line)
            continue
        if fenced or line.startswith("    "):
            out.append(line)
            continue
        line = _LINK.sub(lambda m: _outside_link(m, page_dir, docs, src), line)
        # prose outside code spans: a page named as docs/NAME.md becomes a link to it
        pieces, last = [], 0
        for m in _CODE.finditer(line):
            pieces.append(_DOC_MENTION.sub(lambda x: _mention(x, pages, docs, src, src),
                                           line[last:m.start()]))
            code = m.group(0)
            inner = re.fullmatch(r"docs/([A-Za-z0-9_-]+\.md)", m.group(2))
            if inner and inner.group(1) in pages and inner.group(1) != src:
                code = f"[{code}]({_rel(inner.group(1), src)})"
            elif inner and not (docs / inner.group(1)).is_file():
                log.warning(f"{src}: names docs/{inner.group(1)}, which does not exist")
            elif _REPO_ONLY.fullmatch(m.group(2)) and not line[m.end():].startswith(
                    " in the source repository"):
                code += _repo_mark(src)
            pieces.append(code)
            last = m.end()
        pieces.append(_DOC_MENTION.sub(lambda x: _mention(x, pages, docs, src, src),
                                       line[last:]))
        out.append(_mark_repo_mentions("".join(pieces), src))
    return "".join(out)


#: the packed site the wheel ships (pyproject.toml's package data; fovexp/docsite.py unpacks it)
SITE_ZIP = ROOT / "fovexp" / "site.zip"


@event_priority(-200)  # after Material's offline plugin (-100) wrote search/search_index.js
def on_post_build(config: Any) -> None:
    """What the installed site never loads is left out (source maps; the search's language
    packs: the site is English, and Material loads none for it), and the site is packed into
    :data:`SITE_ZIP`: one file of package data, where a folder of assets would look to
    setuptools like packages missing from its list."""
    import shutil
    import zipfile

    site = Path(config["site_dir"])
    for path in site.rglob("*.map"):
        path.unlink()
    lunr = site / "assets" / "javascripts" / "lunr"
    if lunr.is_dir():
        shutil.rmtree(lunr)
    tmp = SITE_ZIP.with_suffix(".zip.tmp")
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED, compresslevel=9) as zf:
        for path in sorted(site.rglob("*")):
            if path.is_file():
                zf.write(path, path.relative_to(site).as_posix())
        # stamped with its sources' digest: the wheel's build uses a site that is up to date
        # and rebuilds a stale one (build_backend/fovexp_build.py)
        zf.comment = STAMP_PREFIX + site_inputs_digest(ROOT).encode("ascii")
    tmp.replace(SITE_ZIP)
    log.info(f"fovexp: the site packed into {SITE_ZIP} ({SITE_ZIP.stat().st_size / 1e6:.2f} MB)")
