"""``report.html``: the same report as ``report.md``, as a page readable offline (issue 23,
section 3). Its rendering in a real browser, with every figure loaded, is checked by
``tests/monitor/test_browser.py``."""

from __future__ import annotations

import re
from html.parser import HTMLParser
from pathlib import Path

import pytest

from fovexp.analysis.html import markdown_to_html
from fovexp.analysis.report import run_analysis

from analysis_fixtures import write_study


class _Page(HTMLParser):
    """The tags, image sources, table count and text of a page."""

    def __init__(self) -> None:
        super().__init__()
        self.tags: list[str] = []
        self.images: list[str] = []
        self.text: list[str] = []
        self.external: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.tags.append(tag)
        a = dict(attrs)
        if tag == "img":
            self.images.append(a.get("src") or "")
        for key in ("src", "href"):
            v = a.get(key) or ""
            if re.match(r"^(https?:)?//", v):
                self.external.append(v)

    def handle_data(self, data: str) -> None:
        self.text.append(data)


@pytest.fixture(scope="module")
def report(tmp_path_factory: pytest.TempPathFactory) -> Path:
    results = write_study(tmp_path_factory.mktemp("results"), n_participants=4, seed=3)
    out = tmp_path_factory.mktemp("report")
    run_analysis(results, out)
    return out


def test_the_page_has_the_reports_tables_figures_and_banner(report: Path) -> None:
    md = (report / "report.md").read_text()
    page_text = (report / "report.html").read_text()
    page = _Page()
    page.feed(page_text)
    # every Markdown table is an HTML table, every figure an image that exists beside it
    n_tables = len(re.findall(r"^\|---", md, flags=re.M))
    assert n_tables > 5 and page.tags.count("table") == n_tables
    figures = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", md)
    assert figures and page.images == figures
    for src in page.images:
        assert (report / src).is_file(), src
    # readable offline: nothing fetched from elsewhere (the style sheet is inside)
    assert page.external == [] and "<link" not in page_text and "<script" not in page_text
    # the dry-run warning is the first thing after the title
    text = "".join(page.text)
    assert page.tags[page.tags.index("h1") + 1] == "blockquote"
    assert "trials come from dry runs" in text[: text.index("Results folder")]
    # headings and rule texts as in the Markdown
    for heading in ("Calibration (section 5.3)", "Validation: validation", "Exclusions",
                    "R13 latency"):
        assert heading in text


def test_text_from_the_logs_is_shown_as_text_not_markup() -> None:
    page = markdown_to_html("# r\n\n| experiment |\n|---|\n| <script>alert(1)</script> |\n\n"
                            "note: <img src=x onerror=alert(1)> & more\n")
    assert "<script>" not in page and "<img" not in page
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in page
    assert "&lt;img src=x onerror=alert(1)&gt; &amp; more" in page


def test_no_banner_for_participants_data(tmp_path: Path) -> None:
    results = write_study(tmp_path / "results", n_participants=3, seed=4,
                          experiments=("validation",), tracker="tobii")
    run_analysis(results, tmp_path / "out", figures=False)
    page = (tmp_path / "out" / "report.html").read_text()
    assert "trials come from dry runs" not in page and "<blockquote>" not in page
    assert "<img" not in page  # --no-figures: no image left dangling
