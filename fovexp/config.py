"""The YAML files a user writes (protocols, display profiles, stimulus manifests, parameter
tables, simulated-participant truths), read one way: a key given twice is an error (PyYAML
would keep the last silently), and a syntax error is one line naming the file and position.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from .errors import FovexpError


class _DuplicateKey(yaml.constructor.ConstructorError):
    pass


class _UniqueKeyLoader(yaml.SafeLoader):
    """PyYAML's safe loader, refusing duplicate keys in a mapping."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict[Any, Any]:
        seen: set[Any] = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            if key in seen:
                raise _DuplicateKey(
                    None, None, f"key {key!r} is given twice", key_node.start_mark)
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


def parse_yaml(text: str, what: str) -> Any:
    """``text`` as YAML; ``what`` (e.g. ``"protocol x.yaml"``) prefixes the one-line error."""
    try:
        return yaml.load(text, Loader=_UniqueKeyLoader)  # noqa: S506 (a safe loader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" (line {mark.line + 1}, column {mark.column + 1})" if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        if isinstance(exc, _DuplicateKey):
            raise FovexpError(f"{what}{where}: {problem}") from None
        raise FovexpError(f"{what} is not valid YAML{where}: {problem}") from None


def read_yaml(path: str | Path, what: str) -> Any:
    """The YAML file ``path``; ``what`` names it in errors (``"display profile"`` ...)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise FovexpError(f"cannot read {what} {path}: {exc.strerror}") from None
    except UnicodeDecodeError:
        raise FovexpError(f"{what} {path} is not UTF-8 text") from None
    return parse_yaml(text, f"{what} {path}")
