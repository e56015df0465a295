"""The one exception type that user-facing code turns into a clear message and exit status 2."""

from __future__ import annotations

import difflib
from typing import Any


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
        close = difflib.get_close_matches(str(err["loc"][-1]), missing, n=1)
        if close:
            msg += f" (did you mean {close[0]!r}?)"
    where = ".".join(str(p) for p in err["loc"])
    if not where:  # a check across fields names its keys in its own message
        return FovexpError(f"{what}: {msg}")
    value = f"={err['input']!r}" if "input" in err and not isinstance(err["input"], dict) else ""
    return FovexpError(f"{what}: {where}{value}: {msg}")
