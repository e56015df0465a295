"""The PsychoPy window: the only module that imports psychopy (lazily, when a session opens).

It draws the split screen of paper section 5.1 (reference half left, processed mirror right,
fixation cross on the seam), black frames when the gaze check says so (the cross stays, so the
participant can find it again), text screens and the calibration screens (the views of
``fovexp.experiment.trackers.calibration``: head-position box, animated targets, per-point
results), and reads the wheel (Shift held: fine step) and the keys.

Each half is a GL texture the window owns, drawn by PsychoPy's ``ImageStim`` (as a movie frame
is: ``ImageStim`` reads the texture name from ``colorTexture`` at each draw). A new test half
reaches it as 8-bit RGBA prepared by the render thread, uploaded in the texture's own format
(one ``glTexSubImage2D``: about 1 ms for a 4K half on Mesa llvmpipe, against 64 ms for the
float32 array ``ImageStim.image`` took; benchmarks/DISPLAY_LOOP.md), or, from the GPU backend,
as a texture the render thread wrote in a GL context sharing objects with the window's
(:meth:`PsychoScreen.gl_share`): then the display thread only switches texture names.

Flip times come from ``win.flip()``'s return value (the time the driver released the buffer,
close to the vertical blank; ``waitBlanking`` is always on, so every frame's drawing is finished
when it returns), on ``time.monotonic``'s clock. Xvfb has no vsync: a window opened with
``pace_hz`` emulates it, holding each flip to the next boundary of a fixed ``1/pace_hz`` grid
(a frame that misses one lands on a later one, as with vsync). :meth:`PsychoScreen.prepare`
finishes its drawing (``glFinish``) before it returns, so that a frame drawn before the gaze is
read costs nothing after it (the frame loop's late latch); a flip's ``ready_s`` is when the
frame waited only for the vertical blank: right after ``prepare`` (with vsync), or after the
swap's copy into the X server (paced: that copy is the software display's own work).

Keys come from PsychoPy's ``Keyboard`` where its backend stamps the press ('ptb', which needs
psychtoolbox and libjack; else 'iohub' when an ioHub server runs): each key carries the time it
went down, so the answer is the value on screen at the press, not at the poll that saw it
(../docs/EXPERIMENT.md). Without either, keys come from PsychoPy's event module and are stamped
at the poll (``info()["keyboard"]["key_time"] == "poll"``; the session warns). PsychoPy keeps
its own clock (``psychtoolbox.GetSecs``, seconds since the epoch, once psychtoolbox loads):
every time taken from it is put on ``time.monotonic``'s clock by
:meth:`PsychoScreen._to_monotonic` (both clocks read back to back). 'ptb' stamps a press on
that clock; 'iohub' on the hub's, which agrees with it to within about 0.4 ms.
"""

from __future__ import annotations

import ctypes
import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from fovexp import FovexpError

from ..interfaces import FlipTimes
from ..tasks.trial import InputEvent, Key, WheelCarry, wheel_notches
from ..trackers.calibration import CAL_KEYS, HeadBoxView, ResultView, TargetView, TextView
from .render import Rendered, to_rgba8

KEYS = ["return", "num_enter", "escape", "space", "q", "r", "c"]
#: how many key presses are remembered to drop the second report of one press (PsychoPy's
#: ``Keyboard`` reports a key once while down and again when released)
KEYS_REMEMBERED = 64
#: measured refresh may differ from the profile by this fraction (a 120 Hz screen run at 60 Hz
#: is off by 50 %, far outside it)
REFRESH_TOLERANCE = 0.05
#: a dry run paces its flips to this rate (Xvfb has no vsync)
DRY_RUN_REFRESH_HZ = 60.0
#: the operator's keys between trials, noticed on any screen (a trial's included): D a drift
#: check, C a recalibration, after the current trial
OPERATOR_KEYS = ("d", "c")
#: calibration screens: Titta's mid-grey background; the two eyes' colours on the result plot
CAL_BACKGROUND = (0.0, 0.0, 0.0)
EYE_COLOURS = {"left": (-0.9, 0.7, -0.9), "right": (-0.5, 0.1, 1.0)}


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


class _TextureSource:
    """An ``ImageStim`` image that is a GL texture (PsychoPy's interface for movie frames:
    ``colorTexture`` is read at every draw, row 0 drawn at the top)."""

    isLumImage = False

    def __init__(self, name: Any) -> None:
        self.colorTexture = name


class _HalfTexture:
    """One half of the split screen: an RGBA8 texture updated in place from 8-bit RGBA rows
    (row 0 at the top), in its own format so the driver copies without converting."""

    def __init__(self, gl: Any, width: int, height: int) -> None:
        self._gl = gl
        self.name = gl.GLuint()
        gl.glGenTextures(1, ctypes.byref(self.name))
        self.size = (0, 0)
        self._allocate(width, height)

    def _allocate(self, width: int, height: int) -> None:
        gl = self._gl
        gl.glBindTexture(gl.GL_TEXTURE_2D, self.name)
        for p in (gl.GL_TEXTURE_MIN_FILTER, gl.GL_TEXTURE_MAG_FILTER):
            gl.glTexParameteri(gl.GL_TEXTURE_2D, p, gl.GL_NEAREST)
        for p in (gl.GL_TEXTURE_WRAP_S, gl.GL_TEXTURE_WRAP_T):
            gl.glTexParameteri(gl.GL_TEXTURE_2D, p, gl.GL_CLAMP_TO_EDGE)
        gl.glTexImage2D(gl.GL_TEXTURE_2D, 0, gl.GL_RGBA8, width, height, 0, gl.GL_RGBA,
                        gl.GL_UNSIGNED_BYTE, None)
        gl.glBindTexture(gl.GL_TEXTURE_2D, 0)
        self.size = (width, height)

    def upload(self, rgba8: np.ndarray) -> None:
        gl = self._gl
        h, w = rgba8.shape[:2]
        if (w, h) != self.size:
            self._allocate(w, h)
        data = np.ascontiguousarray(rgba8)
        gl.glBindTexture(gl.GL_TEXTURE_2D, self.name)
        gl.glPixelStorei(gl.GL_UNPACK_ALIGNMENT, 4)  # RGBA8 rows are whole words
        gl.glTexSubImage2D(gl.GL_TEXTURE_2D, 0, 0, 0, w, h, gl.GL_RGBA, gl.GL_UNSIGNED_BYTE,
                           data.ctypes.data_as(ctypes.c_void_p))
        gl.glBindTexture(gl.GL_TEXTURE_2D, 0)

    def delete(self) -> None:
        if self.name.value:
            self._gl.glDeleteTextures(1, ctypes.byref(self.name))
            self.name = self._gl.GLuint(0)


class SharedGLContext:
    """A GLX context sharing objects (textures, buffers) with the window's, on a 1x1 pbuffer, for
    the render thread: the GPU backend renders there into textures the window draws.

    Created on the window's thread; :meth:`make_current` / :meth:`release_current` on the render
    thread; :meth:`destroy` on the window's thread once the render thread let go of it.
    """

    def __init__(self, pyglet_window: Any) -> None:
        from pyglet.gl import glx

        self._glx = glx
        main = pyglet_window.context
        if not hasattr(main, "glx_context"):
            raise FovexpError("sharing a GL context needs GLX (Linux/X11)")
        self._dpy = main.x_display
        self._context = main.config.create_context(main)
        attrs = (ctypes.c_int * 5)(glx.GLX_PBUFFER_WIDTH, 1, glx.GLX_PBUFFER_HEIGHT, 1, 0)
        self._pbuffer = glx.glXCreatePbuffer(self._dpy, main.config._fbconfig, attrs)
        if not self._pbuffer:
            self.destroy()
            raise FovexpError("the window's GL configuration has no pbuffer for a shared context")

    def make_current(self) -> None:
        if not self._glx.glXMakeContextCurrent(self._dpy, self._pbuffer, self._pbuffer,
                                               self._context.glx_context):
            raise FovexpError("cannot make the shared GL context current")

    def release_current(self) -> None:
        self._glx.glXMakeContextCurrent(self._dpy, 0, 0, None)

    def destroy(self) -> None:
        glx = self._glx
        if getattr(self, "_pbuffer", None):
            glx.glXDestroyPbuffer(self._dpy, self._pbuffer)
            self._pbuffer = None
        ctx = getattr(self._context, "glx_context", None)
        if ctx:
            glx.glXDestroyContext(self._dpy, ctx)
            self._context.glx_context = None


def no_display_hint(command: str) -> str:
    """What to do without a display, for ``command`` (``fovexp run``, ``fovexp rig check``):
    the one wording of it, each command naming itself."""
    return f"a dry run on a server needs Xvfb: xvfb-run -a {command} ..."


class PsychoScreen:
    """A PsychoPy window of ``size`` pixels (the stimulus fills it) on monitor ``screen``.

    ``pace_hz`` emulates vsync at that rate where there is none (Xvfb); a dry run paces at
    :data:`DRY_RUN_REFRESH_HZ` by default. ``refresh_hz`` is then the paced rate.
    ``command``: the command that opens it (``fovexp run``, ``fovexp rig check``), which the
    error without a display tells the user to run under Xvfb.
    """

    def __init__(self, size: tuple[int, int], fullscreen: bool = True, cross_px: float = 20.0,
                 dry_run: bool = False, refresh_hz: float = 60.0, screen: int = 0,
                 pace_hz: float | None = None, command: str = "fovexp run") -> None:
        try:  # importing PsychoPy's window module already connects to the X display
            import pyglet

            # no glGetError after every GL call (pyglet's default; PsychoPy's modules set
            # this too, but only take effect when imported before pyglet.gl)
            pyglet.options["debug_gl"] = False
            from psychopy import logging as plog

            plog.console.setLevel(plog.ERROR)
            from psychopy import event, visual
            from pyglet import gl
            from pyglet.window import key as pkey
        except ModuleNotFoundError as exc:
            if (exc.name or "").split(".")[0] not in ("psychopy", "pyglet"):
                raise FovexpError(f"PsychoPy cannot be imported: {exc}") from None
            raise FovexpError(f"the experiment runner needs PsychoPy ({exc}): pip install "
                              "'fovexp[experiment]'") from None
        except Exception as exc:
            raise FovexpError(f"cannot open a window ({type(exc).__name__}: {exc}); is DISPLAY "
                              f"set? ({no_display_hint(command)})") from None
        self._event = event
        self._gl = gl
        self._clock = plog.defaultClock  # win.flip() returns times on this clock
        self.size = (int(size[0]), int(size[1]))
        self.dry_run = dry_run
        self.screen = int(screen)
        if pace_hz is None and dry_run:
            pace_hz = DRY_RUN_REFRESH_HZ
        self.pace_hz = pace_hz
        self.refresh_hz = float(pace_hz) if pace_hz else float(refresh_hz)
        w, h = self.size
        try:
            self.win = visual.Window(
                size=self.size, fullscr=fullscreen, screen=self.screen, units="pix",
                color=(-1, -1, -1), colorSpace="rgb", allowGUI=not fullscreen,
                winType="pyglet", checkTiming=False, waitBlanking=True, useFBO=False,
                gammaErrorPolicy="ignore",
            )
        except Exception as exc:
            raise FovexpError(f"cannot open a window on screen {self.screen} ({exc}); is "
                              f"DISPLAY set? ({no_display_hint(command)})") from None
        self._keys = pkey.KeyStateHandler()
        self._pkey = pkey
        self._wheel: list[tuple[float, bool]] = []
        self._wheel_carry: WheelCarry = (0.0, False)  # a fraction of a notch (hi-res wheels)
        # Our own pyglet handlers: PsychoPy's wheel handler drops scroll events whenever a
        # psychopy.hardware.mouse.Mouse exists, and the modifier must be read at scroll time.
        self.win.winHandle.push_handlers(self._keys, on_mouse_scroll=self._on_scroll)
        # a frame of its own: in the one above it would replace the KeyStateHandler's
        self._operator_keys: set[str] = set()
        self.win.winHandle.push_handlers(on_key_press=self._on_key_press)
        self.mouse = event.Mouse(win=self.win, visible=not fullscreen)
        self._kb, self._kb_backend = self._open_keyboard()
        self._kb_seen: list[tuple[str, float]] = []
        half = (w // 2, h)
        self._tex_left = _HalfTexture(gl, w // 2, h)
        self._tex_right = _HalfTexture(gl, w // 2, h)
        self._src_right = _TextureSource(self._tex_right.name)
        self.left = self._texture_stim(visual, self._tex_left.name, half, -w / 4)
        self.right = self._texture_stim(visual, self._src_right, half, w / 4)
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
        self._visual = visual
        self._cal: dict[str, Any] | None = None  # the calibration screens' stimuli, made once
        self._plot: tuple[Any, list[Any]] | None = None  # (the result view drawn, its stimuli)
        self._grid0: float | None = None  # paced flips: the emulated vblank grid's origin
        self._grid_k = -1
        self._shared: SharedGLContext | None = None
        #: seconds the last :meth:`set_test` / :meth:`set_reference` spent uploading
        self.last_upload_s = 0.0
        #: the photodiode patch in the bottom-left corner (``fovexp rig check --photodiode``):
        #: None not drawn, True white, False black (on every frame until changed)
        self.photodiode: bool | None = None
        side = max(16, h // 20)
        self._patch = visual.Rect(self.win, width=side, height=side, units="pix",
                                  pos=(-w / 2 + side / 2, -h / 2 + side / 2), lineColor=None,
                                  fillColor=(1, 1, 1))
        #: keep a copy of every frame shown in ``last_frame`` (tests; slow)
        self.capture = False
        self.last_frame: np.ndarray | None = None

    @staticmethod
    def _open_keyboard() -> tuple[Any, str]:
        """PsychoPy's ``Keyboard`` with a backend that stamps the press: 'ptb' where
        psychtoolbox loads (it reads the keyboards itself, beside an ioHub server if one
        runs), else 'iohub' when an ioHub server already runs (an ioHub gaze source; started
        with ``Keyboard=dict(use_keymap='psychopy')`` its key names are PsychoPy's). Returns
        (None, 'event') when neither is to be had (psychtoolbox not importable: libjack
        missing); PsychoPy picks its keyboard backend once per process."""
        import sys

        from psychopy.hardware import keyboard

        iohub = sys.modules.get("psychopy.iohub.client")
        # 'ptb' first: ioHub's keyboard asks the ioHub server on every poll, so the display
        # thread would wait on it (up to a request's timeout when the server is gone)
        if keyboard.havePTB:
            want = "ptb"
        elif iohub is not None and iohub.ioHubConnection.getActiveConnection() is not None:
            want = "iohub"
        else:
            return None, "event"
        kb = keyboard.Keyboard(backend=want)
        got = kb.getBackend()
        if got not in ("ptb", "iohub"):  # chosen before, in this process
            return None, str(got or "event")
        return kb, str(got)

    def info(self) -> dict[str, Any]:
        """The keyboard (``backend``; ``key_time``: ``press`` when keys carry the time they went
        down, ``poll`` when only the poll that saw them), the pacing and the refresh rate."""
        return {"keyboard": {"backend": self._kb_backend,
                             "key_time": "press" if self._kb is not None else "poll"},
                "pace_hz": self.pace_hz, "refresh_hz": self.refresh_hz}

    def _to_monotonic(self, t_psychopy: float) -> float:
        """A time on PsychoPy's clock (``logging.defaultClock``: flips, key presses) on
        ``time.monotonic``'s: both clocks read back to back, the interval since ``t_psychopy``
        taken from PsychoPy's."""
        now = time.monotonic()
        return now - (self._clock.getTime() - t_psychopy)

    def _texture_stim(self, visual: Any, source: Any, size: tuple[int, int], x: float) -> Any:
        if not isinstance(source, _TextureSource):
            source = _TextureSource(source)
        stim = visual.ImageStim(self.win, image=source, size=size, pos=(x, 0), units="pix",
                                interpolate=False)
        # ImageStim made a texture of its own, which it never uses with an external one
        self._gl.glDeleteTextures(1, ctypes.byref(stim._texID))
        stim._texID = source.colorTexture
        stim._needUpdate = True
        return stim

    # -- checks --------------------------------------------------------------------------------
    def measure_display(self) -> tuple[float | None, tuple[int, int], tuple[int, int]]:
        """Measured refresh rate (Hz; None when frame times are unstable), window size and
        framebuffer size (px), for :func:`check_display`."""
        measured = self.win.getActualFrameRate(nIdentical=20, nMaxFrames=240,
                                               nWarmUpFrames=20, threshold=1)
        size = (int(self.win.size[0]), int(self.win.size[1]))
        fb = tuple(int(v) for v in getattr(self.win, "frameBufferSize", size))
        return (None if measured is None else float(measured)), size, (fb[0], fb[1])

    def gl_share(self) -> SharedGLContext | None:
        """A GL context sharing objects with this window's, for the render thread (None where
        there is none to be had: not GLX, or no pbuffer)."""
        if self._shared is None:
            try:
                self._shared = SharedGLContext(self.win.winHandle)
            except FovexpError:
                return None
            except Exception:  # an X error from a driver that refuses it
                return None
        return self._shared

    # -- drawing -------------------------------------------------------------------------------
    @staticmethod
    def _rgba8(img: np.ndarray) -> np.ndarray:
        a = np.asarray(img)
        if a.dtype == np.uint8 and a.ndim == 3 and a.shape[2] == 4:
            return a
        # display-encoded [0, 1] values go to the screen unchanged (tests/experiment/
        # test_window.py checks a random image to 8-bit rounding)
        return to_rgba8(a)

    def set_reference(self, left: np.ndarray) -> None:
        """A new trial's reference half (display-encoded [0, 1], or 8-bit RGBA); wheel turns
        and keys from before it (a break, the last trial's leftover fraction) do not move its
        start value or answer it."""
        t0 = time.perf_counter()
        self._tex_left.upload(self._rgba8(left))
        self.last_upload_s = time.perf_counter() - t0
        self._wheel, self._wheel_carry = [], (0.0, False)
        if self._kb is not None:
            try:
                self._kb.clearEvents()
            except RuntimeError:  # ioHub's keyboard without its server (gone; started again)
                pass

    def set_test(self, right: Rendered | np.ndarray) -> None:
        """The test half from now on: a render (its 8-bit RGBA uploaded, or its texture drawn as
        it is) or an image (display-encoded [0, 1], or 8-bit RGBA)."""
        t0 = time.perf_counter()
        if isinstance(right, Rendered) and right.texture is not None:
            name = self._gl.GLuint(right.texture)
        else:
            img = right.rgba8 if isinstance(right, Rendered) else right
            self._tex_right.upload(self._rgba8(img))
            name = self._tex_right.name
        self._use_texture(self.right, self._src_right, name)
        self.last_upload_s = time.perf_counter() - t0

    def set_mirrored(self, mirrored: bool) -> None:
        """Both halves mirrored about the seam (``mirrored``) or as they are: the test half
        drawn flipped on the left and the reference flipped on the right, the forced-choice
        task's degraded left half (:mod:`fovexp.experiment.tasks.forced_choice`)."""
        w = self.size[0]
        for stim, x in ((self.left, -w / 4), (self.right, w / 4)):
            stim.flipHoriz = bool(mirrored)
            stim.pos = (-x if mirrored else x, 0)

    @staticmethod
    def _use_texture(stim: Any, source: _TextureSource, name: Any) -> None:
        if source.colorTexture.value != name.value:
            source.colorTexture = stim._texID = name
            # with pyglet < 2 PsychoPy draws from a display list that names the texture
            stim._needUpdate = True

    def prepare(self, blank: bool) -> None:
        """Draw the next frame into the back buffer, replacing whatever an earlier call drew
        there since the last flip: both halves and the cross, or the cross alone on black when
        ``blank``. Returns when the drawing is done (``glFinish``): a frame drawn with the
        stimulus before the gaze was read is blanked afterwards by a clear and the cross."""
        self.win.clearBuffer()  # the window's colour: black
        if not blank:
            self.left.draw()
            self.right.draw()
        for c in self.cross:
            c.draw()
        if self.photodiode is not None:
            self._patch.fillColor = (1, 1, 1) if self.photodiode else (-1, -1, -1)
            self._patch.draw()
        self._gl.glFinish()

    def flip(self) -> FlipTimes:
        """Show the back buffer; returns the flip time (``time.monotonic`` seconds) from
        ``win.flip()``'s return value, or the emulated vblank when pacing, and when the frame
        was ready (:class:`~fovexp.experiment.interfaces.FlipTimes`)."""
        if self.capture:
            # The back buffer just before the flip is exactly the frame about to be shown.
            self.last_frame = np.asarray(self.win._getFrame(buffer="back"))
        ready = time.monotonic()  # prepare() finished the drawing: vsync only waits from here
        ret = self.win.flip()
        t = time.monotonic() if ret is None else min(time.monotonic(), self._to_monotonic(ret))
        if self.pace_hz:
            ready = t  # the swap's copy into Xvfb is the software display's drawing
            t = self._pace(t)
        return FlipTimes(t, ready)

    def _pace(self, t: float) -> float:
        """Hold the flip at ``t`` to the next boundary of the ``1/pace_hz`` grid (vsync): a
        frame that took longer than a period lands on a later boundary."""
        period = 1.0 / float(self.pace_hz)  # type: ignore[arg-type]
        if self._grid0 is None:
            self._grid0, self._grid_k = t, 0
            return t
        k = max(math.ceil((t - self._grid0) / period), self._grid_k + 1)
        self._grid_k = k
        due = self._grid0 + k * period
        wait = due - time.monotonic()
        if wait > 0:
            time.sleep(wait)
        return due

    def draw(self, blank: bool) -> FlipTimes:
        """:meth:`prepare` and :meth:`flip`."""
        self.prepare(blank)
        return self.flip()

    # -- calibration screens -------------------------------------------------------------
    def _px(self, x: float, y: float) -> tuple[float, float]:
        """Normalised (origin top-left, y down) to PsychoPy pixels (origin centre, y up)."""
        w, h = self.size
        return (x - 0.5) * w, (0.5 - y) * h

    def _cal_stims(self) -> dict[str, Any]:
        if self._cal is None:
            v, (w, h) = self._visual, self.size
            grey = CAL_BACKGROUND
            self._cal = {
                "bg": v.Rect(self.win, width=w, height=h, fillColor=grey, lineColor=None,
                             units="pix"),
                "shade": v.Rect(self.win, width=w, height=h, fillColor=grey, lineColor=None,
                                opacity=0.85, units="pix"),
                "disc": v.Circle(self.win, radius=1, fillColor=(-1, -1, -1), lineColor=None,
                                 units="pix", edges=64),
                "bar": v.Rect(self.win, width=1, height=1, fillColor=(1, 1, 1), lineColor=None,
                              units="pix"),
                "ring": v.Circle(self.win, radius=1, fillColor=None, lineColor=(1, 1, 1),
                                 lineWidth=max(1.0, h / 540), units="pix", edges=64),
                "box": v.Rect(self.win, width=1, height=1, fillColor=None, lineColor=(1, 1, 1),
                              lineWidth=max(1.0, h / 360), units="pix"),
                "line": v.Line(self.win, start=(0, 0), end=(1, 1), lineColor=(1, 1, 1),
                               lineWidth=max(1.0, h / 720), units="pix"),
                "text": v.TextStim(self.win, text="", color=(1, 1, 1), units="pix",
                                   height=max(10, h // 40), wrapWidth=0.9 * w,
                                   alignText="center"),
                "prompt": v.TextStim(self.win, text="", color=(0.7, 0.7, 0.7), units="pix",
                                     height=max(9, h // 55), wrapWidth=0.95 * w,
                                     pos=(0, -0.45 * h)),
            }
        return self._cal

    def calibration_frame(self, view: Any) -> list[str]:
        """Draw one frame of a calibration screen's view and flip; returns the keys pressed
        since the last call (:data:`fovexp.experiment.trackers.calibration.CAL_KEYS`)."""
        self._cal_stims()["bg"].draw()
        self._draw_view(view)
        self.flip()
        return list(self._event.getKeys(keyList=CAL_KEYS))

    def _draw_view(self, view: Any) -> None:
        if isinstance(view, TargetView):
            self._draw_target(view.pos, view.back_px, view.front_px)
        elif isinstance(view, HeadBoxView):
            self._draw_head_box(view)
        elif isinstance(view, ResultView):
            self._draw_result(view)
        elif isinstance(view, TextView):
            c = self._cal_stims()
            if view.behind is not None:
                self._draw_view(view.behind)
                c["shade"].draw()
            self._text(view.text, (0, 0.05 * self.size[1]))
            self._prompt(view.prompt)

    def _text(self, text: str, pos: tuple[float, float]) -> None:
        t = self._cal_stims()["text"]
        if t.text != text:
            t.text = text
        t.pos = pos
        t.draw()

    def _prompt(self, text: str) -> None:
        t = self._cal_stims()["prompt"]
        if t.text != text:
            t.text = text
        t.draw()

    def _draw_target(self, pos: tuple[float, float], back_px: float, front_px: float) -> None:
        """Thaler et al. 2013's ABC target, centred exactly on ``pos`` (normalised)."""
        c = self._cal_stims()
        xy = self._px(*pos)
        disc, bar = c["disc"], c["bar"]
        disc.pos, disc.radius, disc.fillColor = xy, back_px / 2, (-1, -1, -1)
        disc.draw()
        bar.pos = xy
        for wh in ((back_px, front_px), (front_px, back_px)):
            bar.width, bar.height = wh
            bar.draw()
        disc.radius = front_px / 2
        disc.draw()

    def _draw_head_box(self, view: HeadBoxView) -> None:
        c = self._cal_stims()
        w, h = self.size
        bh = 0.45 * h
        bw = bh * 340 / 260  # the proportions of a Tobii Pro Spectrum's track box
        box = c["box"]
        box.width, box.height, box.pos = bw, bh, (0, 0)
        box.lineColor = (-0.6, 0.8, -0.6) if view.ok else (1.0, -0.2, -0.8)
        box.draw()
        found = [e for e in view.eyes if e is not None]
        if found:
            mx = sum(e[0] for e in found) / len(found)
            my = sum(e[1] for e in found) / len(found)
            ring = c["ring"]
            ring.pos = ((mx - 0.5) * bw, (0.5 - my) * bh)
            ring.radius = 0.28 * bh * view.scale
            ring.lineColor = (1, 1, 1)
            ring.draw()
            disc = c["disc"]
            for eye, e in zip(("left", "right"), view.eyes, strict=True):
                if e is None:
                    continue
                disc.pos = ((e[0] - 0.5) * bw, (0.5 - e[1]) * bh)
                disc.radius = 0.035 * bh * view.scale
                disc.fillColor = EYE_COLOURS[eye]
                disc.draw()
        self._text(view.text, (0, 0.36 * h))
        self._prompt(view.prompt)

    def _draw_result(self, view: ResultView) -> None:
        if self._plot is None or self._plot[0] is not view:
            self._plot = (view, self._result_stims(view))
        c = self._cal_stims()
        for p in view.points:
            self._draw_target(p.target, view.target_px, max(2.0, view.target_px / 6))
            if p.target == (0.5, 0.5) and view.mode == "validation":
                ring = c["ring"]
                ring.pos, ring.radius = self._px(*p.target), view.window_radius_px
                ring.lineColor = (1, 1, 1) if p.ok else (1.0, -0.2, -0.8)
                ring.draw()
            line = c["line"]
            for eye, m in p.mean.items():
                if m is not None:
                    line.start, line.end = self._px(*p.target), self._px(*m)
                    line.lineColor = EYE_COLOURS[eye]
                    line.draw()
        for stim in self._plot[1]:
            stim.draw()
        self._text(view.title + "\n" + view.text, (0, 0.36 * self.size[1]))
        self._prompt(view.prompt)

    def _result_stims(self, view: ResultView) -> list[Any]:
        """The samples (one ElementArrayStim per eye: one draw call each) and the labels."""
        v, h = self._visual, self.size[1]
        out: list[Any] = []
        dot = max(2.0, h / 500)
        for eye in ("left", "right"):
            xys = [self._px(x, y) for p in view.points for x, y in p.samples.get(eye, [])]
            means = [self._px(*m) for p in view.points if (m := p.mean.get(eye)) is not None]
            if xys:
                out.append(v.ElementArrayStim(
                    self.win, units="pix", nElements=len(xys), xys=xys, sizes=dot,
                    colors=EYE_COLOURS[eye], colorSpace="rgb", elementTex=None,
                    elementMask="circle"))
            if means:
                out.append(v.ElementArrayStim(
                    self.win, units="pix", nElements=len(means), xys=means, sizes=4 * dot,
                    colors=EYE_COLOURS[eye], colorSpace="rgb", elementTex=None,
                    elementMask="circle"))
        for p in view.points:
            x, y = self._px(*p.target)
            out.append(v.TextStim(self.win, text=f"{p.number}  {p.label}".strip(),
                                  color=(1, 1, 1) if p.ok else (1.0, -0.2, -0.8), units="pix",
                                  height=max(9, h // 60), pos=(x, y - 0.06 * h)))
        return out

    def take_operator_keys(self) -> set[str]:
        """The operator's between-trial keys (:data:`OPERATOR_KEYS`) pressed since the last
        call, on whatever screen was up."""
        self.win.winHandle.dispatch_events()
        keys, self._operator_keys = self._operator_keys, set()
        return keys

    def _on_key_press(self, symbol: int, modifiers: int) -> None:
        name = self._pkey.symbol_string(symbol).lower()
        if name in OPERATOR_KEYS:
            self._operator_keys.add(name)
        # returning None lets the other handlers (PsychoPy's key buffer) see the key too

    def message(self, text: str, keys: list[str] | None, timeout_s: float | None,
                each_frame: Callable[[], None] | None = None) -> str | None:
        """Show ``text`` until one of ``keys`` is pressed (returned) or ``timeout_s`` passes;
        ``each_frame`` is called after every flip (the session empties the gaze buffer)."""
        self._event.clearEvents()
        self.text.text = text
        t0 = time.monotonic()
        while True:
            self.text.draw()
            self.flip()
            if each_frame is not None:
                each_frame()
            if keys:
                got = self._event.getKeys(keyList=keys)
                if got:
                    # a key that answered this screen (C confirms the display checklist) is
                    # not also an operator's between-trial request
                    self._operator_keys.discard(got[0])
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
        """Wheel notches since the last call (merged per modifier state, in order) and keys in
        the order they went down, each with its press time where the keyboard stamps it."""
        self.win.winHandle.dispatch_events()
        events, self._wheel = self._wheel, []
        wheel, self._wheel_carry = wheel_notches(events, self._wheel_carry)
        out: list[InputEvent] = list(wheel)
        if self._kb is None:
            out += [Key(name) for name in self._event.getKeys(keyList=KEYS)]
            return out
        try:
            return out + self._pressed_keys()
        except RuntimeError:  # ioHub's keyboard without its server (gone; started again)
            return out + [Key(name) for name in self._event.getKeys(keyList=KEYS)]

    def _pressed_keys(self) -> list[Key]:
        """The keys that went down since the last call, with their press times: those still
        held (``waitRelease=False``) and those already released (a tap between two polls); a
        press reported again at its release is dropped."""
        kb = self._kb
        got = [*kb.getKeys(keyList=KEYS, waitRelease=False),
               *kb.getKeys(keyList=KEYS, waitRelease=True)]
        out = []
        for k in sorted(got, key=lambda k: float(k.tDown)):
            ident = (str(k.name), float(k.tDown))
            if ident in self._kb_seen:
                continue
            self._kb_seen = [*self._kb_seen[-(KEYS_REMEMBERED - 1):], ident]
            out.append(Key(ident[0], self._to_monotonic(ident[1])))
        self._event.clearEvents("keyboard")  # the event module saw them too: not for later
        return out

    def mouse_position(self) -> tuple[float, float] | None:
        x, y = self.mouse.getPos()
        w, h = self.size
        nx, ny = float(x) / w + 0.5, 0.5 - float(y) / h
        if not (0 <= nx <= 1 and 0 <= ny <= 1):
            return None
        return nx, ny

    def window_rect(self) -> tuple[int, int, int, int]:
        """The window's place on its screen: left, top, width, height (px); a full-screen
        window's is the whole screen (a source that reports positions on the screen, ioHub's,
        normalises them over it)."""
        if getattr(self.win, "_isFullScr", False):
            return 0, 0, self.size[0], self.size[1]
        x, y = self.win.winHandle.get_location()
        return int(x), int(y), self.size[0], self.size[1]

    def close(self) -> None:
        """Close the window (call after the render thread let go of :meth:`gl_share`)."""
        try:
            for stim in (self.left, self.right):
                stim._texID = self._gl.GLuint(0)  # ours: deleted below, not by ImageStim
            self._tex_left.delete()
            self._tex_right.delete()
            if self._shared is not None:
                self._shared.destroy()
                self._shared = None
        except Exception:  # the X server went away
            pass
        try:
            self.win.close()
        except Exception:  # already closed (display check) or the X server went away
            pass
