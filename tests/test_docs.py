"""Issues 21 and 32: the documentation site. ``fovexp docs`` unpacks the packed site of the
package and gives a page's path; the build's hooks turn the docstrings into Markdown and check
the links that leave docs/; the build backend builds the site, strict, into every wheel
(test_a_site_that_does_not_build_fails_the_wheel, slow; CI builds a wheel with it in
.ci/wheel-smoke)."""

from __future__ import annotations

import logging
import shutil
import sys
import zipfile
from pathlib import Path
from types import SimpleNamespace

import pytest

from fovexp import FovexpError, docsite

ROOT = Path(__file__).resolve().parent.parent


def test_fovexp_docs_unpacks_the_packed_site_once(tmp_path: Path, monkeypatch, capsys) -> None:
    packed = tmp_path / "site.zip"
    with zipfile.ZipFile(packed, "w") as zf:
        zf.writestr("index.html", "<h1>fovexp</h1>")
        zf.writestr("STUDY.html", "<h1>Your own study</h1>")
        zf.writestr("reference/fovexp.html", "api")
    monkeypatch.setattr(docsite, "packed_site", lambda: packed)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    page = docsite.site_page("STUDY")
    assert page.read_text() == "<h1>Your own study</h1>"
    assert page.parent.parent == tmp_path / "cache" / "fovexp"
    assert docsite.site_page("reference/fovexp.html").read_text() == "api"
    page.write_text("kept")  # unpacked once: the next call does not unpack again
    assert docsite.site_page("STUDY.md").read_text() == "kept"
    assert docsite.site_page("study").read_text() == "kept"  # any case (issue 32)
    assert docsite.site_page("Reference/FOVEXP").read_text() == "api"
    with pytest.raises(FovexpError, match=r"no page 'nope' .*pages: STUDY, index, "
                                          r"reference/fovexp"):
        docsite.site_page("nope")
    from fovexp.cli import main

    assert main(["docs"]) == 0
    assert capsys.readouterr().out.strip().endswith("index.html")


def test_fovexp_docs_without_a_built_site_says_how_to_build_it(tmp_path: Path, monkeypatch,
                                                               capsys) -> None:
    monkeypatch.setattr(docsite, "packed_site", lambda: tmp_path / "site.zip")
    from fovexp.cli import main

    assert main(["docs"]) == 2
    err = capsys.readouterr().err
    assert "no documentation site" in err and "./dev docs" in err and err.count("\n") == 1


def _load(name: str):
    import importlib.util

    spec = importlib.util.spec_from_file_location(name, ROOT / "docs" / "_mkdocs" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_docstrings_become_markdown() -> None:
    pytest.importorskip("griffe", reason="the docs extra is not installed")
    import doctest

    mod = _load("griffe_markdown")
    runner = doctest.DocTestRunner(optionflags=doctest.NORMALIZE_WHITESPACE)
    for test in doctest.DocTestFinder().find(mod.to_markdown, globs=vars(mod)):
        runner.run(test)
    assert runner.tries == 1 and runner.failures == 0
    assert mod.to_markdown(":class:`~fovexp.Enhancer`") == "`fovexp.Enhancer`"
    example = "Text.\n\n    >" + ">> f(1)\n    2\n\nMore."
    assert mod.to_markdown(example) == (
        "Text.\n\n    ```pycon\n    >" + ">> f(1)\n    2\n    ```\n\nMore.")


def test_links_out_of_docs_are_checked(caplog) -> None:
    pytest.importorskip("mkdocs", reason="the docs extra is not installed")
    hooks = _load("hooks")
    page = SimpleNamespace(file=SimpleNamespace(src_uri="EXPERIMENT.md"))
    files = SimpleNamespace(documentation_pages=lambda: [
        SimpleNamespace(src_uri=n) for n in ("EXPERIMENT.md", "LOGS.md", "reference/a.md")])
    config = {"docs_dir": str(ROOT / "docs")}
    md = ("See [the bench](../benchmarks/BENCH.md), docs/LOGS.md and `docs/LOGS.md`, "
          "[a page](LOGS.md#files).\n```\ndocs/LOGS.md [x](../nope.md)\n```\n")
    with caplog.at_level(logging.WARNING):
        out = hooks.on_page_markdown(md, page, config, files)
    assert out.startswith("See the bench (`benchmarks/BENCH.md` in the source repository), "
                          "[docs/LOGS.md](LOGS.md) and [`docs/LOGS.md`](LOGS.md), "
                          "[a page](LOGS.md#files).")
    assert "docs/LOGS.md [x](../nope.md)" in out and not caplog.records  # code: untouched
    bad = "[gone](../benchmarks/GONE.md) and docs/GONE.md\n"
    with caplog.at_level(logging.WARNING):
        hooks.on_page_markdown(bad, page, config, files)
    assert [r.getMessage() for r in caplog.records] == [
        "EXPERIMENT.md: link to ../benchmarks/GONE.md, which does not exist in the repository",
        "EXPERIMENT.md: names docs/GONE.md, which does not exist"]
    # a file only the source repository has is marked so, in code and in prose (issue 32)
    mark = hooks._repo_mark("EXPERIMENT.md")
    assert "index.md#files-of-the-source-repository" in mark
    assert hooks.on_page_markdown(
        "See `tests/monitor/test_browser.py` and benchmarks/GATING.md, `fovexp run`.\n",
        page, config, files) == (f"See `tests/monitor/test_browser.py`{mark} and "
                                 f"benchmarks/GATING.md{mark}, `fovexp run`.\n")
    linked = hooks.on_page_markdown("[the bench](../benchmarks/BENCH.md)\n", page, config, files)
    assert "<sup" not in linked  # said in words already
    # from a page in a folder, a named page is linked relative to it
    sub = SimpleNamespace(file=SimpleNamespace(src_uri="reference/a.md"))
    assert hooks.on_page_markdown("docs/LOGS.md\n", sub, config, files) == (
        "[docs/LOGS.md](../LOGS.md)\n")


def _backend(root: Path, monkeypatch):
    """build_backend/fovexp_build.py as pip loads it (backend-path), pointed at ``root``."""
    import importlib

    monkeypatch.syspath_prepend(str(root / "build_backend"))
    for name in ("fovexp_build", "site_inputs"):
        sys.modules.pop(name, None)
    backend = importlib.import_module("fovexp_build")
    monkeypatch.setattr(backend, "ROOT", root)
    monkeypatch.setattr(backend, "SITE_ZIP", root / "fovexp" / "site.zip")
    return backend


def test_the_build_backend_knows_a_stale_site(tmp_path: Path, monkeypatch) -> None:
    """The packed site's stamp is the digest of its sources: a changed page makes it stale (the
    wheel's build then rebuilds it, with MkDocs as a build requirement); an sdist's tree, with
    no sources, uses the site it ships; a tree with neither refuses."""
    root = tmp_path / "repo"
    shutil.copytree(ROOT / "build_backend", root / "build_backend",
                    ignore=shutil.ignore_patterns("__pycache__"))
    (root / "docs").mkdir()
    (root / "docs" / "index.md").write_text("# fovexp\n")
    (root / "fovexp").mkdir()
    (root / "fovexp" / "api.py").write_text('"""The API."""\n')
    (root / "mkdocs.yml").write_text("site_name: x\n")
    (root / "pyproject.toml").write_bytes((ROOT / "pyproject.toml").read_bytes())
    backend = _backend(root, monkeypatch)
    assert backend._site_state() == "stale"  # no packed site
    assert any(r.startswith("mkdocs") for r in backend.get_requires_for_build_wheel())
    site_inputs = sys.modules["site_inputs"]
    with zipfile.ZipFile(root / "fovexp" / "site.zip", "w") as zf:
        zf.writestr("index.html", "x")
        zf.comment = site_inputs.STAMP_PREFIX + site_inputs.site_inputs_digest(root).encode()
    assert backend._site_state() == "current"
    assert not any(r.startswith("mkdocs") for r in backend.get_requires_for_build_wheel())
    (root / "fovexp" / "api.py").write_text('"""The API, changed."""\n')  # a docstring
    assert backend._site_state() == "stale"
    (root / "mkdocs.yml").unlink()  # an sdist: the built site, not its sources
    assert backend._site_state() == "shipped"
    (root / "fovexp" / "site.zip").unlink()
    with pytest.raises(backend.SiteBuildError, match="neither the documentation's sources"):
        backend._site_state()


@pytest.mark.slow
def test_a_site_that_does_not_build_fails_the_wheel(tmp_path: Path, monkeypatch) -> None:
    """The whole site through the backend, in a clean copy with a broken link: the build fails
    with MkDocs' warning and leaves no packed site (``--quiet`` once hid such warnings from
    strict mode). The site that builds, and its pages in the wheel, are checked by CI's wheel
    build (.ci/wheel-smoke: ``python -m build --wheel`` in a clean copy, then ``fovexp docs``)."""
    pytest.importorskip("mkdocs", reason="the docs extra is not installed")
    work = tmp_path / "repo"

    def ignore(folder: str, names: list[str]) -> set[str]:
        top = {".venv", ".git", "build", "results", "out", "report"} if Path(folder) == ROOT \
            else set()
        return top | {n for n in names if n in ("__pycache__", "generated", "frames")
                      or n.endswith(".zip")}

    shutil.copytree(ROOT, work, ignore=ignore)
    backend = _backend(work, monkeypatch)
    monkeypatch.chdir(work)
    index = work / "docs" / "index.md"
    index.write_text(index.read_text() + "\n[gone](NOPE.md)\n")
    assert backend._site_state() == "stale"
    with pytest.raises(backend.SiteBuildError, match=r"(?s)does not build.*NOPE\.md"):
        backend._ensure_site()
    assert not (work / "fovexp" / "site.zip").exists()
