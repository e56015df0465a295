"""The one exception type that user-facing code turns into a clear message and exit status 2."""

from __future__ import annotations

import difflib
from collections.abc import Iterable
from typing import Any


def closest(word: str, candidates: Iterable[str], n: int = 1) -> list[str]:
    """The ``n`` candidates most like ``word`` (difflib's ratio, at least 0.6), best first:
    what a misspelt key or id was probably meant to be.

    >>> closest("seeed", ["seed", "repetitions"])
    ['seed']
    >>> closest("lab-1", ["lab-01", "lab-02", "scene-01"], n=3)
    ['lab-01', 'lab-02']
    """
    return difflib.get_close_matches(word, list(candidates), n=n)


def did_you_mean(word: str, candidates: Iterable[str], n: int = 1) -> str:
    """`` (did you mean 'x'?)`` (or ``'x' or 'y'``) for the closest candidates, else ``""``:
    appended to the one-line error about ``word``."""
    close = closest(word, candidates, n)
    if not close:
        return ""
    return " (did you mean " + " or ".join(repr(c) for c in close) + "?)"


class FovexpError(ValueError):
    """Bad input: a malformed file, an out-of-range parameter, a missing resource.

    The message names the problem (the file, the key, the value) in one line.
    """


def validation_error(what: str, exc: Any) -> FovexpError:
    """One line from a pydantic ``ValidationError``: ``what``, the first bad field (dotted
    path), its value and pydantic's reason. Raise it ``from None``."""
    errs = exc.errors()
    # an unknown key first: a misspelt required key also shows up as "missing", which names
    # the right key but not the wrong one
    extra = [e for e in errs if e["type"] == "extra_forbidden"]
    err = extra[0] if extra else errs[0]
    msg = err["msg"].removeprefix("Value error, ")
    if extra:
        parent = err["loc"][:-1]
        missing = [str(e["loc"][-1]) for e in errs
                   if e["type"] == "missing" and e["loc"][:-1] == parent]
        msg += did_you_mean(str(err["loc"][-1]), missing)
    where = ".".join(str(p) for p in err["loc"])
    if not where:  # a check across fields names its keys in its own message
        return FovexpError(f"{what}: {msg}")
    value = f"={err['input']!r}" if "input" in err and not isinstance(err["input"], dict) else ""
    return FovexpError(f"{what}: {where}{value}: {msg}")
