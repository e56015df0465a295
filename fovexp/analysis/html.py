"""``report.html``: the report's Markdown (:mod:`fovexp.analysis.report`) as one page a browser
opens offline, with the same tables, figures (``figures/*.png``, beside it) and notes.

Python-Markdown with its ``tables`` extension does the conversion; raw HTML in the Markdown is
not passed through (text from the logs, such as an experiment's name, is shown as text, never
read as markup). The style sheet is inside the page; nothing is fetched from elsewhere. The
warnings at the report's top (dry runs, pilots) are its first block quotes, shown as a banner.
"""

from __future__ import annotations

import html
from pathlib import Path

import markdown
from markdown.extensions import Extension

_STYLE = """
body { font: 15px/1.5 system-ui, -apple-system, "Segoe UI", "DejaVu Sans", sans-serif;
  max-width: 70em; margin: 1.5em auto; padding: 0 1.5em; color: #1d232a; }
h1 { margin-bottom: 0.4em; }
h2 { margin-top: 1.8em; border-bottom: 1px solid #d5dae0; padding-bottom: 0.2em; }
h1 + blockquote, h1 + blockquote + blockquote { margin: 0.8em 0; padding: 0.7em 1em;
  background: #fff3cd; border: 2px solid #e0a43a; border-radius: 6px; font-size: 1.05em; }
blockquote { margin-left: 0; padding-left: 1em; border-left: 4px solid #d5dae0; }
table { border-collapse: collapse; margin: 0.6em 0 1.2em; font-size: 0.9em;
  display: block; overflow-x: auto; }
th, td { border: 1px solid #d5dae0; padding: 0.25em 0.6em; text-align: left; }
th { background: #f2f4f7; }
tr:nth-child(even) td { background: #fafbfc; }
td { font-variant-numeric: tabular-nums; }
img { max-width: 100%; height: auto; display: block; margin: 0.6em 0 1.2em; }
code { background: #f2f4f7; padding: 0 0.25em; border-radius: 3px; }
"""


class _NoRawHtml(Extension):
    """Raw HTML in the Markdown is escaped, not passed through."""

    def extendMarkdown(self, md: markdown.Markdown) -> None:  # noqa: N802 (the library's name)
        md.preprocessors.deregister("html_block")
        md.inlinePatterns.deregister("html")


def markdown_to_html(text: str, title: str = "fovexp analysis report") -> str:
    """The report's Markdown as a whole HTML page (module docstring)."""
    body = markdown.markdown(text, extensions=["tables", _NoRawHtml()],
                             output_format="html")
    return (f'<!doctype html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
            f'<meta name="viewport" content="width=device-width, initial-scale=1">\n'
            f"<title>{html.escape(title)}</title>\n<style>{_STYLE}</style>\n</head>\n"
            f"<body>\n{body}\n</body>\n</html>\n")


def write_report_html(text: str, path: Path) -> Path:
    """Write ``report.html`` for the report's Markdown ``text``."""
    path.write_text(markdown_to_html(text), encoding="utf-8")
    return path


__all__ = ["markdown_to_html", "write_report_html"]
