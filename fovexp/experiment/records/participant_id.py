"""Participant IDs, validated for use in file names (docs/LOGS.md).

Pydantic validation errors become one line with :func:`fovexp.validation_error`.
"""

from __future__ import annotations

from fovexp import FovexpError
from fovexp.results.format import PARTICIPANT_PATTERN, is_participant_id


def check_participant(pid: str) -> str:
    """A participant ID safe for file names (``[A-Za-z0-9_-]{1,32}``, not a Windows device
    name such as ``CON``)."""
    if not is_participant_id(pid):
        raise FovexpError(
            f"participant ID {pid!r} is not valid: use 1-32 letters, digits, '_' or '-', not a "
            f"device name such as CON ({PARTICIPANT_PATTERN}; it becomes a folder name)"
        )
    return pid
