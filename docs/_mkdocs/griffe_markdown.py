"""A Griffe extension (mkdocs.yml): the package's docstrings, written for reading in the source
(reST roles, ``>>>`` examples, ``::`` before literal blocks), as Markdown for the API pages."""

from __future__ import annotations

import re
from typing import Any

import griffe

_ROLE = re.compile(r":(?:py:)?(?:func|meth|class|mod|attr|data|obj|exc|const):`~?([^`]+)`")


def to_markdown(text: str) -> str:
    """Roles as code spans, ``>>>`` examples fenced as Python sessions, ``text::`` as
    ``text:`` (the indented block after it is a Markdown code block already).

    >>> print(to_markdown("See :func:`fovexp.make_params`::\\n\\n    x = 1"))
    See `fovexp.make_params`:
    <BLANKLINE>
        x = 1
    """
    text = _ROLE.sub(lambda m: f"`{m.group(1)}`", text)
    text = re.sub(r"(?m)(\S)::$", r"\1:", text)
    text = re.sub(r"(?m)^::$\n?", "", text)
    lines = text.splitlines()
    out: list[str] = []
    i = 0
    while i < len(lines):
        line = lines[i]
        if line.lstrip().startswith(">>>"):
            indent = line[: len(line) - len(line.lstrip())]
            block = []
            while i < len(lines) and lines[i].strip() and lines[i].startswith(indent):
                block.append(lines[i][len(indent):])
                i += 1
            out += [indent + "```pycon", *(indent + b for b in block), indent + "```"]
            continue
        out.append(line)
        i += 1
    return "\n".join(out)


class DocstringsAsMarkdown(griffe.Extension):
    """Rewrites every docstring with :func:`to_markdown` as Griffe loads it."""

    def on_instance(self, *, node: Any, obj: griffe.Object, agent: Any, **kwargs: Any) -> None:
        if obj.docstring is not None:
            obj.docstring.value = to_markdown(obj.docstring.value)
