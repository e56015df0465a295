"""What the session and the frame loop need from their window, gaze source and renderer, as
protocols (structural types): the real ones (``window.PsychoScreen``; the sources of
:mod:`fovexp.experiment.trackers`: ``TobiiGaze``, ``IoHubGaze``, ``SimulatedGaze``,
``MouseGaze``; ``render.TestRenderer``) and the window-free
stand-ins of the tests all satisfy them, so everything but the window itself runs without one.

Clocks. Every time a :class:`Screen` returns (flips, key presses) is on ``time.monotonic``'s
clock, in seconds; a :class:`GazeSource`'s times (``now_us``, the samples' ``system_time_us``)
are on its own clock, in whole microseconds (a Tobii's system clock). The frame loop puts a
flip on the gaze clock by reading ``now_us`` right after the flip returns
(:class:`fovexp.experiment.tasks.frameloop.TrialLoop`). A screen whose toolkit keeps another clock
(PsychoPy's, which is ``psychtoolbox.GetSecs``, seconds since the epoch, once psychtoolbox
loads) converts at the source, from the two clocks read back to back.

A frame's life on a :class:`Screen` (``frameloop.TrialLoop``): :meth:`Screen.prepare` draws it
into the back buffer and returns when the drawing is done; it may be called again before the
flip, and the later call replaces the frame (the loop draws the stimulus before it reads the
gaze, and blanks it cheaply if the gaze then says so); :meth:`Screen.flip` presents it at the
next vertical blank and returns :class:`FlipTimes`.

Optional capabilities are read with ``getattr`` where they are used: a gaze source's
``validated`` (False: not calibrated, the mouse), ``calibration()`` (a real tracker's),
``look_at`` (simulated eyes follow the targets), ``display_area()`` (a tracker's own),
``attach(screen)`` (a source that needs the window: the mouse's pointer, ioHub's window
rectangle);
a screen's ``gl_share()`` (the window's GL context, for the GPU backend).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any, NamedTuple, Protocol

import numpy as np

from .tasks.trial import InputEvent
from .trackers.gaze import GazeSample, SourceEvent

if TYPE_CHECKING:  # the renderer's module starts threads and GL on use, not on import
    from .display.render import Rendered


class FlipTimes(NamedTuple):
    """One flip, on ``time.monotonic``'s clock (s)."""

    #: the frame appeared: the vertical blank the flip returned at (``win.flip()``'s return
    #: value; a paced window's emulated blank)
    flip_s: float
    #: the frame was ready: its drawing done, so that from here it waited only for the
    #: vertical blank (the late latch measures its draw time up to here)
    ready_s: float


class GazeSource(Protocol):
    """A gaze stream on one clock (``now_us``, the samples' ``system_time_us``, whole
    microseconds)."""

    name: str

    def start(self) -> None: ...
    def stop(self) -> None: ...
    def now_us(self) -> int:
        """The source's clock now (us): the time a frame's blanking decision is made at."""
    def poll(self) -> list[GazeSample]:
        """The samples that arrived since the last call, oldest first; never waits (the frame
        loop calls it twice a frame when it late-latches: once to guess the frame, once to
        decide it)."""
    def poll_events(self) -> list[SourceEvent]: ...
    @property
    def connected(self) -> bool: ...
    def info(self) -> dict[str, Any]: ...


class Screen(Protocol):
    """The window a session draws on (``window.PsychoScreen``); times on ``time.monotonic``'s
    clock (module docstring)."""

    size: tuple[int, int]

    #: the rate the flips come at (Hz): the display's, or a paced window's
    refresh_hz: float

    def measure_display(self) -> tuple[float | None, tuple[int, int], tuple[int, int]]: ...
    def message(self, text: str, keys: list[str] | None, timeout_s: float | None,
                each_frame: Callable[[], None] | None = None) -> str | None: ...
    # the view is one of fovexp.experiment.trackers.calibration's view dataclasses
    def calibration_frame(self, view: Any) -> list[str]: ...
    def take_operator_keys(self) -> set[str]: ...
    def set_reference(self, left: np.ndarray) -> None: ...
    def set_test(self, right: Rendered | np.ndarray) -> None: ...
    def set_mirrored(self, mirrored: bool) -> None:
        """The whole split screen mirrored about the seam (the test half on the left)."""
    def prepare(self, blank: bool) -> None:
        """Draw the next frame into the back buffer, replacing what an earlier call drew since
        the last flip: both halves and the cross, or (blank) the cross alone on black; returns
        when the drawing is done."""
    def flip(self) -> FlipTimes:
        """Present the back buffer at the next vertical blank."""
    def draw(self, blank: bool) -> FlipTimes:
        """:meth:`prepare` and :meth:`flip`."""
    def poll_input(self) -> list[InputEvent]:
        """Wheel notches and keys since the last call (keys stamped with their press time where
        the keyboard gives it: :class:`fovexp.experiment.tasks.trial.Key`)."""
    def mouse_position(self) -> tuple[float, float] | None: ...
    def info(self) -> dict[str, Any]:
        """What the session file records of the window: its keyboard (``backend``, and
        ``key_time``: ``press`` where keys carry their press time, ``poll`` where not),
        pacing."""
    def close(self) -> None: ...


class Renderer(Protocol):
    """The test half's renderer (``render.TestRenderer``): requests are served in order on its
    own thread; only the newest pending one is rendered."""

    def set_image(self, right: np.ndarray, screen_size: tuple[int, int]) -> None: ...
    def info(self, timeout: float = 60.0) -> dict[str, Any]: ...
    def request(self, params: Any) -> int: ...
    def drop_pending(self) -> None: ...
    def poll(self) -> Rendered | None: ...
    def wait(self, serial: int, timeout: float = 120.0) -> Rendered: ...
    def close(self) -> None: ...


#: a screen factory: ``PsychoScreen`` or a test's stand-in
ScreenFactory = Callable[..., Screen]

class SessionRecord(Protocol):
    """The session file as the rooms below the session write it (the tracker's set-up, the
    screens around trials): :class:`fovexp.experiment.records.sessionfile.SessionFile`."""

    info: dict[str, Any]

    def write(self) -> None: ...

    def update(self, **update: Any) -> None: ...

    def event(self, kind: str, **detail: Any) -> None: ...

    def set_in_run(self, key: str, value: Any, write: bool = True) -> None: ...


__all__ = ["FlipTimes", "GazeSource", "Renderer", "Screen", "ScreenFactory", "SessionRecord"]
