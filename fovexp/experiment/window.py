"""The PsychoPy window: the only module that imports psychopy (lazily, when a session opens).

It draws the split screen of paper section 6.1 (reference half left, processed mirror right,
fixation cross on the seam), black frames when the gaze check says so (the cross stays, so the
participant can find it again), text screens and calibration targets, and reads the wheel
(Shift held: fine step) and the keys. Under Xvfb there is no vsync, so a dry run paces flips to
``refresh_hz`` itself.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from fovexp import FovexpError

from .trial import InputEvent, Key, WheelCarry, wheel_notches

KEYS = ["return", "num_enter", "escape", "space", "q", "r"]
#: measured refresh may differ from the profile by this fraction (a 120 Hz screen run at 60 Hz
#: is off by 50 %, far outside it)
REFRESH_TOLERANCE = 0.05
#: a dry run paces its flips to this rate (Xvfb has no vsync)
DRY_RUN_REFRESH_HZ = 60.0


def check_display(measured_hz: float | None, window_size: tuple[int, int],
                  framebuffer_size: tuple[int, int], profile: Any) -> dict[str, Any]:
    """The display check of a session's start (docs/EXPERIMENT.md): the measured refresh rate
    within :data:`REFRESH_TOLERANCE` of the profile's (a 120 Hz screen run at 60 Hz fails), and
    window and framebuffer exactly the profile's pixel size (desktop scaling fails).

    Returns what was measured and expected; raises FovexpError naming every mismatch.
    """
    size = (int(window_size[0]), int(window_size[1]))
    fb = (int(framebuffer_size[0]), int(framebuffer_size[1]))
    expected = (int(profile.width_px), int(profile.height_px))
    info = {"measured_refresh_hz": measured_hz, "window_size": size, "framebuffer_size": fb,
            "profile": profile.name, "profile_refresh_hz": profile.refresh_hz,
            "profile_size": expected}
    problems = []
    if measured_hz is None:
        problems.append("the refresh rate could not be measured (frame times unstable)")
    elif abs(measured_hz - profile.refresh_hz) > REFRESH_TOLERANCE * profile.refresh_hz:
        problems.append(f"measured refresh {measured_hz:.1f} Hz, profile {profile.name!r} says "
                        f"{profile.refresh_hz:g} Hz (set the display mode, or check that "
                        "vsync is on)")
    if size != expected or fb != expected:
        problems.append(f"window is {size[0]}x{size[1]} px (framebuffer {fb[0]}x{fb[1]}), "
                        f"profile {profile.name!r} says {expected[0]}x{expected[1]} "
                        "(desktop scaling or a different display mode?)")
    if problems:
        raise FovexpError("display check failed: " + "; ".join(problems)
                          + " -- fix the display, or rerun with --skip-display-check")
    return info


class PsychoScreen:
    """A PsychoPy window of ``size`` pixels (the stimulus fills it)."""

    def __init__(self, size: tuple[int, int], fullscreen: bool = True, cross_px: float = 20.0,
                 dry_run: bool = False, refresh_hz: float = 60.0) -> None:
        try:  # importing PsychoPy's window module already connects to the X display
            from psychopy import logging as plog

            plog.console.setLevel(plog.ERROR)
            from psychopy import event, visual
            from pyglet.window import key as pkey
        except ModuleNotFoundError as exc:
            if (exc.name or "").split(".")[0] not in ("psychopy", "pyglet"):
                raise FovexpError(f"PsychoPy cannot be imported: {exc}") from None
            raise FovexpError(f"the experiment runner needs PsychoPy ({exc}): pip install "
                              "'fovexp[experiment]'") from None
        except Exception as exc:
            raise FovexpError(f"cannot open a window ({type(exc).__name__}: {exc}); is DISPLAY "
                              "set? (a dry run on a server needs Xvfb: xvfb-run -a fovexp run "
                              "...)") from None
        self._event = event
        self.size = (int(size[0]), int(size[1]))
        self.dry_run = dry_run
        # In a dry run flips are paced (Xvfb has no vsync).
        self.refresh_hz = DRY_RUN_REFRESH_HZ if dry_run else float(refresh_hz)
        w, h = self.size
        try:
            self.win = visual.Window(
                size=self.size, fullscr=fullscreen, units="pix", color=(-1, -1, -1),
                colorSpace="rgb", allowGUI=not fullscreen, winType="pyglet",
                checkTiming=False, waitBlanking=not dry_run, useFBO=False,
                gammaErrorPolicy="ignore",
            )
        except Exception as exc:
            raise FovexpError(f"cannot open a window ({exc}); is DISPLAY set? "
                              "(a dry run on a server needs Xvfb)") from None
        self._keys = pkey.KeyStateHandler()
        self._pkey = pkey
        self._wheel: list[tuple[float, bool]] = []
        self._wheel_carry: WheelCarry = (0.0, False)  # a fraction of a notch (hi-res wheels)
        # Our own pyglet handlers: PsychoPy's wheel handler drops scroll events whenever a
        # psychopy.hardware.mouse.Mouse exists, and the modifier must be read at scroll time.
        self.win.winHandle.push_handlers(self._keys, on_mouse_scroll=self._on_scroll)
        self.mouse = event.Mouse(win=self.win, visible=not fullscreen)
        half = (w // 2, h)
        self.left = visual.ImageStim(self.win, image=np.zeros((h, w // 2, 3)), size=half,
                                     pos=(-w / 4, 0), units="pix", interpolate=False)
        self.right = visual.ImageStim(self.win, image=np.zeros((h, w // 2, 3)), size=half,
                                      pos=(w / 4, 0), units="pix", interpolate=False)
        arm = max(7.0, float(cross_px))
        thick = max(2.0, round(arm / 10))
        self.cross = [
            visual.Rect(self.win, width=arm, height=thick, pos=(0, 0), fillColor=(1, -1, -1),
                        lineColor=None, units="pix"),
            visual.Rect(self.win, width=thick, height=arm, pos=(0, 0), fillColor=(1, -1, -1),
                        lineColor=None, units="pix"),
        ]
        self.text = visual.TextStim(self.win, text="", color=(0.8, 0.8, 0.8), units="pix",
                                    height=max(12, h // 30), wrapWidth=0.8 * w)
        self.dot = visual.Circle(self.win, radius=max(6, h // 60), fillColor=(1, 1, 1),
                                 lineColor=None, units="pix")
        self.dot_centre = visual.Circle(self.win, radius=max(2, h // 250),
                                        fillColor=(-1, -1, -1), lineColor=None, units="pix")
        self._last_flip: float | None = None
        #: keep a copy of every frame shown in ``last_frame`` (tests; slow)
        self.capture = False
        self.last_frame: np.ndarray | None = None

    # -- checks --------------------------------------------------------------------------------
    def measure_display(self) -> tuple[float | None, tuple[int, int], tuple[int, int]]:
        """Measured refresh rate (Hz; None when frame times are unstable), window size and
        framebuffer size (px), for :func:`check_display`."""
        measured = self.win.getActualFrameRate(nIdentical=20, nMaxFrames=240,
                                               nWarmUpFrames=20, threshold=1)
        size = (int(self.win.size[0]), int(self.win.size[1]))
        fb = tuple(int(v) for v in getattr(self.win, "frameBufferSize", size))
        return (None if measured is None else float(measured)), size, (fb[0], fb[1])

    # -- drawing -------------------------------------------------------------------------------
    @staticmethod
    def _tex(img: np.ndarray) -> np.ndarray:
        # Display-encoded [0, 1] values go to the screen unchanged (this PsychoPy maps float
        # textures [0, 1] -> [0, 255]; tests/test_experiment_window.py checks a ramp). Numpy
        # textures are drawn bottom row first, so rows are flipped to keep row 0 at the top.
        return np.ascontiguousarray(np.asarray(img, dtype=np.float32)[::-1])

    def set_reference(self, left: np.ndarray) -> None:
        """A new trial's reference half; wheel turns from before it (a break, the last trial's
        leftover fraction) do not move its start value."""
        self.left.image = self._tex(left)
        self._wheel, self._wheel_carry = [], (0.0, False)

    def set_test(self, right: np.ndarray) -> None:
        self.right.image = self._tex(right)

    def _flip(self) -> float:
        if self.capture:
            # The back buffer just before the flip is exactly the frame about to be shown.
            self.last_frame = np.asarray(self.win._getFrame(buffer="back"))
        self.win.flip()
        t = time.monotonic()
        if self.dry_run:
            period = 1.0 / self.refresh_hz
            if self._last_flip is not None and t - self._last_flip < period:
                time.sleep(period - (t - self._last_flip))
                t = time.monotonic()
        self._last_flip = t
        return t

    def draw(self, blank: bool) -> float:
        """Draw the next frame (black but for the cross when ``blank``); returns its time."""
        if not blank:
            self.left.draw()
            self.right.draw()
        for c in self.cross:
            c.draw()
        return self._flip()

    def show_point(self, x: float, y: float) -> None:
        w, h = self.size
        pos = ((x - 0.5) * w, (0.5 - y) * h)
        self.dot.pos = pos
        self.dot_centre.pos = pos
        self.dot.draw()
        self.dot_centre.draw()
        self._flip()

    def message(self, text: str, keys: list[str] | None, timeout_s: float | None,
                each_frame: Callable[[], None] | None = None) -> str | None:
        """Show ``text`` until one of ``keys`` is pressed (returned) or ``timeout_s`` passes;
        ``each_frame`` is called after every flip (the session empties the gaze buffer)."""
        self._event.clearEvents()
        self.text.text = text
        t0 = time.monotonic()
        while True:
            self.text.draw()
            self._flip()
            if each_frame is not None:
                each_frame()
            if keys:
                got = self._event.getKeys(keyList=keys)
                if got:
                    return got[0]
            if timeout_s is not None and time.monotonic() - t0 >= timeout_s:
                return None

    # -- input ---------------------------------------------------------------------------------
    def _on_scroll(self, x: float, y: float, scroll_x: float, scroll_y: float) -> None:
        k = self._pkey
        fine = bool(self._keys[k.LSHIFT] or self._keys[k.RSHIFT])
        self._wheel.append((float(scroll_y), fine))
        # returning None lets PsychoPy's own handler run too

    def poll_input(self) -> list[InputEvent]:
        """Wheel notches since the last call (merged per modifier state, in order) and keys."""
        self.win.winHandle.dispatch_events()
        events, self._wheel = self._wheel, []
        wheel, self._wheel_carry = wheel_notches(events, self._wheel_carry)
        out: list[InputEvent] = list(wheel)
        for name in self._event.getKeys(keyList=KEYS):
            out.append(Key(name))
        return out

    def mouse_position(self) -> tuple[float, float] | None:
        x, y = self.mouse.getPos()
        w, h = self.size
        nx, ny = float(x) / w + 0.5, 0.5 - float(y) / h
        if not (0 <= nx <= 1 and 0 <= ny <= 1):
            return None
        return nx, ny

    def close(self) -> None:
        try:
            self.win.close()
        except Exception:  # already closed (display check) or the X server went away
            pass
