"""Participant IDs, validated for use in file names (docs/LOGS.md).

Pydantic validation errors become one line with :func:`fovexp.validation_error`.
"""

from __future__ import annotations

from fovexp import FovexpError

from .logformat import PARTICIPANT_PATTERN, PARTICIPANT_RE


def check_participant(pid: str) -> str:
    """A participant ID safe for file names (``[A-Za-z0-9_-]{1,32}``)."""
    if not isinstance(pid, str) or not PARTICIPANT_RE.match(pid):
        raise FovexpError(
            f"participant ID {pid!r} is not valid: use 1-32 letters, digits, '_' or '-' "
            f"({PARTICIPANT_PATTERN}; it becomes a folder name)"
        )
    return pid
