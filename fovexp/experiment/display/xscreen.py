"""The X screen's size, asked before any window opens (no PsychoPy, no pyglet: Xlib through
ctypes), so that a window larger than the screen is refused with one line rather than opened
partly off-screen.

A dry run at the display's own size (``--window 3840x2160``) is a rehearsal of the real
session; on a machine without such a display it needs a virtual screen that large
(``xvfb-run -a -s "-screen 0 3840x2160x24"``), and a smaller one would show, and time, only part
of every frame.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os

from fovexp import FovexpError


def x_screen_size(display: str | None = None) -> tuple[int, int] | None:
    """(width, height) in pixels of the default screen of the X display ``display`` (default
    ``$DISPLAY``); None where that cannot be known (no ``DISPLAY``, no libX11, no server)."""
    name = display if display is not None else os.environ.get("DISPLAY")
    if not name:
        return None
    path = ctypes.util.find_library("X11")
    if path is None:
        return None
    try:
        xlib = ctypes.CDLL(path)
    except OSError:
        return None
    xlib.XOpenDisplay.restype = ctypes.c_void_p
    xlib.XOpenDisplay.argtypes = [ctypes.c_char_p]
    for fn in (xlib.XDefaultScreen, xlib.XCloseDisplay):
        fn.argtypes = [ctypes.c_void_p]
    for fn in (xlib.XDisplayWidth, xlib.XDisplayHeight):
        fn.argtypes = [ctypes.c_void_p, ctypes.c_int]
    dpy = xlib.XOpenDisplay(name.encode())
    if not dpy:
        return None
    try:
        screen = xlib.XDefaultScreen(dpy)
        return int(xlib.XDisplayWidth(dpy, screen)), int(xlib.XDisplayHeight(dpy, screen))
    finally:
        xlib.XCloseDisplay(dpy)


def check_window_fits(window: tuple[int, int], screen: tuple[int, int] | None) -> None:
    """Refuse a window larger than the X screen (``screen``; None: unknown, not refused)."""
    if screen is None or (window[0] <= screen[0] and window[1] <= screen[1]):
        return
    w, h = window
    raise FovexpError(
        f"the window {w}x{h} is larger than the X screen {screen[0]}x{screen[1]} "
        f"(DISPLAY={os.environ.get('DISPLAY', '')}): part of every frame would be off-screen. "
        f"Run it on a screen that large; without one, a virtual screen: xvfb-run -a -s "
        f"\"-screen 0 {w}x{h}x24\" fovexp run ...")
