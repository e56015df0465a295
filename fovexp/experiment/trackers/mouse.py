"""The mouse pointer as gaze (``--tracker mouse``): pilot sessions on a desktop, no eye
tracker; their sessions are pilots for the analysis (rule R7)."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from .gaze import GazeSample, SourceEvent, monotonic_us


class MouseGaze:
    """The mouse pointer as gaze, for pilot sessions on a desktop: one sample per poll.

    ``position()`` returns the pointer in normalised display coordinates (origin top-left) or
    None when it is outside the window.
    """

    name = "mouse"
    validated = False

    def __init__(self, position: Callable[[], tuple[float, float] | None] | None = None) -> None:
        self.position = position
        self.connected = True

    def attach(self, screen: Any) -> None:
        """The session's window: the pointer over it (``screen.mouse_position``)."""
        self.position = screen.mouse_position

    def start(self) -> None:
        pass

    def stop(self) -> None:
        pass

    def now_us(self) -> int:
        return monotonic_us()

    def poll_events(self) -> list[SourceEvent]:
        return []

    def info(self) -> dict[str, Any]:
        return {"name": "mouse"}

    def poll(self) -> list[GazeSample]:
        if self.position is None:
            return []
        pt = self.position()
        t = monotonic_us()
        if pt is None:
            return [GazeSample(t, t, math.nan, math.nan, False, math.nan, math.nan, False)]
        return [GazeSample(t, t, pt[0], pt[1], True, pt[0], pt[1], True)]
