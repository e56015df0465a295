"""The one exception type that user-facing code turns into a clear message and exit status 2."""

from __future__ import annotations

from typing import Any


class FovexpError(ValueError):
    """Bad input: a malformed file, an out-of-range parameter, a missing resource.

    The message names the problem (the file, the key, the value) in one line.
    """


def validation_error(what: str, exc: Any) -> FovexpError:
    """One line from a pydantic ``ValidationError``: ``what``, the first bad field (dotted
    path), its value and pydantic's reason. Raise it ``from None``."""
    err = exc.errors()[0]
    msg = err["msg"].removeprefix("Value error, ")
    where = ".".join(str(p) for p in err["loc"])
    if not where:  # a check across fields names its keys in its own message
        return FovexpError(f"{what}: {msg}")
    value = f"={err['input']!r}" if "input" in err and not isinstance(err["input"], dict) else ""
    return FovexpError(f"{what}: {where}{value}: {msg}")
