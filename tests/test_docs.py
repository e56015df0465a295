"""Issue 21: the documentation site. ``fovexp docs`` unpacks the packed site of the package and
gives a page's path; the build's hooks turn the docstrings into Markdown and check the links
that leave docs/. The strict build itself runs in CI (.ci/wheel-smoke) and in
test_the_site_builds_strict (slow)."""

from __future__ import annotations

import logging
import shutil
import subprocess
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
    # from a page in a folder, a named page is linked relative to it
    sub = SimpleNamespace(file=SimpleNamespace(src_uri="reference/a.md"))
    assert hooks.on_page_markdown("docs/LOGS.md\n", sub, config, files) == (
        "[docs/LOGS.md](../LOGS.md)\n")


@pytest.mark.slow
def test_the_site_builds_strict(tmp_path: Path) -> None:
    """The whole site, strict, into a scratch folder (CI builds it again for the wheel)."""
    pytest.importorskip("mkdocs", reason="the docs extra is not installed")
    mkdocs = Path(sys.executable).parent / "mkdocs"
    work = tmp_path / "repo"
    def ignore(folder: str, names: list[str]) -> set[str]:
        top = {".venv", ".git", "build", "results", "out", "report"} if Path(folder) == ROOT \
            else set()
        return top | {n for n in names if n in ("__pycache__", "generated", "frames")
                      or n.endswith(".zip")}

    shutil.copytree(ROOT, work, ignore=ignore)
    r = subprocess.run([str(mkdocs), "build", "--strict", "--quiet"], cwd=work,
                       capture_output=True, text=True, env={"NO_MKDOCS_2_WARNING": "1",
                                                            "PATH": "/usr/bin:/bin"})
    assert r.returncode == 0, r.stderr[-3000:]
    with zipfile.ZipFile(work / "fovexp" / "site.zip") as zf:
        names = set(zf.namelist())
    assert {"index.html", "STUDY.html", "reference/fovexp.html",
            "search/search_index.js"} <= names
    assert not any(n.endswith(".map") for n in names)
