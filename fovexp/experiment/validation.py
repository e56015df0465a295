"""Small helpers that turn pydantic validation errors into one line naming the key."""

from __future__ import annotations

import re

from pydantic import ValidationError

from fovexp.errors import FovexpError

PARTICIPANT_RE = re.compile(r"^[A-Za-z0-9_-]{1,32}$")


def first_error(exc: ValidationError) -> str:
    """``key.path: message (got value)`` for the first error of ``exc``."""
    err = exc.errors()[0]
    loc = ".".join(str(p) for p in err["loc"]) or "(top level)"
    msg = err["msg"]
    if err.get("type") == "extra_forbidden":
        return f"unknown key {loc!r}"
    got = err.get("input")
    if isinstance(got, dict | list) or got is None:
        return f"{loc}: {msg}"
    return f"{loc}: {msg} (got {got!r})"


def check_participant(pid: str) -> str:
    """A participant ID safe for file names (docs/LOGS.md: ``[A-Za-z0-9_-]{1,32}``)."""
    if not isinstance(pid, str) or not PARTICIPANT_RE.match(pid):
        raise FovexpError(
            f"participant ID {pid!r} is not valid: use 1-32 letters, digits, '_' or '-' "
            "(it becomes a folder name)"
        )
    return pid
