"""The test half of the screen, rendered by the enhancer on a worker thread, display-ready.

Per trial the processed half of the split screen (the reference's mirrored left half, paper
section 5.1) is given to :meth:`fovexp.Enhancer.set_image` once, as the right half of the
full-screen frame (``viewport``), so the enhancer computes only that half while eccentricity is
still measured from the screen centre; each wheel step then calls ``enhance`` with the new
parameters, and the enhancer's stage cache redoes only what the changed parameter affects. The
worker keeps only the latest request, so a fast wheel never queues stale frames, and the frame
loop keeps flipping (and blanking) at the display rate while a frame is computed; every result
carries the parameters it was computed with, so the frame loop knows what is on screen.
Errors on the worker reach the frame loop as one-line :class:`fovexp.FovexpError`.

Everything a result needs before it can be shown happens here, off the display thread
(docs/EXPERIMENT.md, "The display loop"):

- CPU backend: the frame is quantised to 8-bit RGBA (:func:`to_rgba8`), so the display thread's
  only work is one 8-bit texture upload (a quarter of the float32 bytes, in the texture's own
  format: no conversion by the driver);
- GPU backend in a context sharing objects with the window's (``gl_share``, given by the window):
  the enhancer writes its output into one of two textures GPU-side
  (``GpuEnhancer.write_output_to``), and the display thread only switches the texture it draws
  (zero-copy). The worker never writes the texture on screen.

The enhancer runs on the CPU or the GPU backend (``backend``: auto, cpu, gpu; see
:func:`fovexp.make_enhancer`); it is created on the worker thread, which owns its OpenGL
context, and :meth:`TestRenderer.info` says which backend, renderer and output path it got, and
why ``auto`` fell back to the CPU when it did.
"""

from __future__ import annotations

import os
import threading
import time
from dataclasses import dataclass
from typing import Any

import numba
import numpy as np

from fovexp import FovexpError

#: The gaze point of the enhancer: the fixation cross at the screen centre (normalised).
SCREEN_CENTRE = (0.5, 0.5)
#: The render thread's nice value above the process's (Linux: per thread; Numba's worker
#: threads, started from it, inherit it): when the machine is short of cores, the scheduler
#: runs the display thread first.
RENDER_NICE = 10


def _lower_priority() -> None:
    """This thread at :data:`RENDER_NICE` more than the process (where the OS allows)."""
    try:
        tid = threading.get_native_id()
        os.setpriority(os.PRIO_PROCESS, tid, os.getpriority(os.PRIO_PROCESS, tid) + RENDER_NICE)
    except (AttributeError, OSError):  # not Linux, or not allowed: the default priority
        pass


@numba.njit(cache=True, nogil=True)
def _quantize_rgba8(img: np.ndarray, out: np.ndarray) -> None:  # pragma: no cover - compiled
    h, w, c = img.shape
    for y in range(h):
        for x in range(w):
            for k in range(3):
                v = img[y, x, k if c >= 3 else 0] * 255.0 + 0.5
                if not v >= 0.0:  # also NaN
                    v = 0.0
                elif v > 255.0:
                    v = 255.0
                out[y, x, k] = np.uint8(v)
            out[y, x, 3] = 255


def to_rgba8(img: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """A display-encoded image in [0, 1] (H, W) or (H, W, 3) as 8-bit RGBA (H, W, 4), each value
    the nearest 8-bit level (out of range clipped, NaN black), alpha opaque, row 0 at the top:
    what the window uploads as it is. Compiled without the GIL (the display thread runs on)."""
    a = np.asarray(img, dtype=np.float32)
    if a.ndim == 2:
        a = a[:, :, None]
    if a.ndim != 3 or a.shape[2] not in (1, 3):
        raise FovexpError(f"to_rgba8: expected (H, W) or (H, W, 3), got {np.shape(img)}")
    h, w = a.shape[:2]
    if out is None or out.shape != (h, w, 4):
        out = np.empty((h, w, 4), np.uint8)
    _quantize_rgba8(np.ascontiguousarray(a), out)
    return out


@dataclass(frozen=True)
class Rendered:
    """A finished render: what the window shows (``rgba8`` to upload, or ``texture``, a GL
    texture name in the window's share group), the parameters it was computed with, and how
    long the worker took (render and preparation for display)."""

    serial: int
    params: Any
    seconds: float
    rgba8: np.ndarray | None = None
    texture: int | None = None


class TestRenderer:
    """Renders the right (test) half for the latest requested parameters (module docstring).

    ``gl_share``: an object with ``make_current()`` and ``release_current()`` that puts a GL
    context sharing objects with the window's on the calling thread (``PsychoScreen.gl_share``);
    with it, the GPU backend renders into textures the window draws directly.
    """

    __test__ = False  # not a pytest class

    def __init__(self, display: Any, preset: str = "paper", geometry: str | None = None,
                 backend: str = "auto", gl_share: Any = None) -> None:
        self.preset = preset
        self.enhancer: Any = None
        self._make = (display, preset, geometry, backend)
        self._gl_share = gl_share
        self._gl_ctx: Any = None  # moderngl context on the shared GL context (zero-copy)
        self._textures: list[Any] = []
        self._front: int | None = None  # GL name of the texture on screen (never written)
        self._notes: list[str] = []
        self._ready = threading.Event()
        self._cv = threading.Condition()
        self._image: tuple[np.ndarray, tuple[int, int, int, int]] | None = None
        self._image_new = False
        self._request: tuple[int, Any] | None = None
        self._result: Rendered | None = None
        self._error: Exception | None = None
        self._serial = 0
        self._dropped_upto = 0  # renders of requests up to this serial are never shown
        self.enhancer_shape: tuple[int, int] = (0, 0)
        self.enhancer_channels = 3
        self._stop = False
        self._thread = threading.Thread(target=self._run, name="fovexp-render", daemon=True)
        self._thread.start()

    def set_image(self, right: np.ndarray, screen_size: tuple[int, int]) -> None:
        """The processed (right) half of the next trial's split screen, whose full frame is
        ``screen_size = (width, height)`` px (applied before the next render). A render still
        pending is dropped."""
        w, h = screen_size
        with self._cv:
            self._image = (right, (w - right.shape[1], 0, w, h))
            self._image_new = True
            self._request = None
            self._result = None
            self._dropped_upto = self._serial

    def info(self, timeout: float = 60.0) -> dict[str, Any]:
        """``{"backend", "renderer", "requested", "output", "fallback"}`` once the worker has its
        enhancer: the backend used (``cpu`` / ``gpu``) and asked for, the GL renderer, how the
        half reaches the screen (``8-bit upload`` / ``texture``), and why ``auto`` took the CPU
        (None when it did not)."""
        if not self._ready.wait(timeout):
            raise TimeoutError(f"the renderer did not start within {timeout} s")
        with self._cv:
            self._raise_error()
        enh = self.enhancer
        return {"backend": enh.backend, "renderer": getattr(enh, "renderer", "numpy/numba"),
                "requested": self._make[3],
                "output": "texture" if self._gl_ctx is not None else "8-bit upload",
                "fallback": getattr(enh, "fallback_reason", None),
                "notes": list(self._notes)}

    def request(self, params: Any) -> int:
        """Ask for the test half with ``params`` (an EnhanceParams); returns a serial number."""
        with self._cv:
            self._serial += 1
            self._request = (self._serial, params)
            self._cv.notify()
            return self._serial

    def drop_pending(self) -> None:
        """Forget the pending request and any result not yet taken (Enter: what is on screen
        is the answer; a render under way is discarded when it finishes)."""
        with self._cv:
            self._request = None
            self._result = None
            self._dropped_upto = self._serial  # a render under way finishes unseen

    def poll(self) -> Rendered | None:
        """The newest finished render, once; from now on it is on screen (the worker will not
        write its texture)."""
        with self._cv:
            self._raise_error()
            out, self._result = self._result, None
            if out is not None and out.texture is not None:
                self._front = out.texture
            return out

    def _raise_error(self) -> None:
        if self._error is not None:
            err, self._error = self._error, None
            if isinstance(err, FovexpError):
                raise FovexpError(f"rendering failed: {err}")
            raise err  # a bug: the session records its traceback and reports one line

    def wait(self, serial: int, timeout: float = 120.0) -> Rendered:
        """Block until the render ``serial`` (or a newer one) is done (taken as by :meth:`poll`)."""
        deadline = time.monotonic() + timeout
        with self._cv:
            while True:
                self._raise_error()
                if self._result is not None and self._result.serial >= serial:
                    out, self._result = self._result, None
                    if out.texture is not None:
                        self._front = out.texture
                    return out
                left = deadline - time.monotonic()
                if left <= 0:
                    raise TimeoutError(f"render {serial} took more than {timeout} s")
                self._cv.wait(left)

    def close(self) -> None:
        with self._cv:
            self._stop = True
            self._cv.notify_all()
        self._thread.join(timeout=30)

    # -- the worker ----------------------------------------------------------------------------
    def _start_enhancer(self) -> None:
        from fovexp import make_enhancer  # public API (docs/API.md)

        display, preset, geometry, backend = self._make
        ctx = None
        if self._gl_share is not None and backend != "cpu":
            ctx = self._shared_context()
        extra = {"ctx": ctx} if ctx is not None else {}
        self.enhancer = make_enhancer(display, preset, geometry, backend=backend, **extra)
        if ctx is not None and self.enhancer.backend != "gpu":
            self._release_shared()  # auto chose the CPU: the shared context is not needed
        elif ctx is not None:
            self._gl_ctx = ctx

    def _shared_context(self) -> Any:
        """A moderngl context on the window's shared GL context (None, with a note, when that
        cannot be had: the GPU backend then uses its own context and a read-back)."""
        try:
            import moderngl
        except ImportError:  # no GPU extra: auto takes the CPU and says so (make_enhancer)
            return None
        try:
            self._gl_share.make_current()
            return moderngl.create_context()
        except Exception as exc:  # no GLX, a driver that refuses sharing
            self._notes.append(f"no GL context shared with the window ({exc}); the GPU "
                               "output is read back and uploaded")
            self._release_shared()
            return None

    def _release_shared(self) -> None:
        try:
            self._gl_share.release_current()
        except Exception:  # closing must not hide the reason it closes
            pass

    def _target_texture(self, size: tuple[int, int], components: int) -> Any:
        """A texture the worker may write: not the one on screen; a result not yet taken that
        sits in it is withdrawn (a newer one replaces it)."""
        import moderngl  # noqa: F401 - the context's module

        if not self._textures or tuple(self._textures[0].size) != size or \
                self._textures[0].components != components:
            for t in self._textures:
                t.release()
            self._textures = [self._gl_ctx.texture(size, components, dtype="f4")
                              for _ in range(2)]
            with self._cv:
                self._front = None
        with self._cv:
            tex = next(t for t in self._textures if t.glo != self._front)
            if self._result is not None and self._result.texture == tex.glo:
                self._result = None
        return tex

    def _render(self, image: Any, params: Any) -> Rendered:
        t0 = time.perf_counter()
        if image is not None:
            self.enhancer.set_image(image[0], viewport=image[1])
        if self._gl_ctx is not None:
            h, w = self.enhancer_shape
            tex = self._target_texture((w, h), self.enhancer_channels)
            used = self.enhancer.write_output_to(tex, gaze=SCREEN_CENTRE, params=params)
            self._gl_ctx.finish()  # complete before the window draws it
            return Rendered(0, used, time.perf_counter() - t0, texture=int(tex.glo))
        res = self.enhancer.enhance(gaze=SCREEN_CENTRE, params=params)
        rgba = to_rgba8(res.output)
        return Rendered(0, res.params, time.perf_counter() - t0, rgba8=rgba)

    def _run(self) -> None:
        _lower_priority()
        try:
            self._start_enhancer()
        except Exception as exc:  # e.g. --backend gpu with no OpenGL 4.5: reported, then stop
            with self._cv:
                self._error = exc
                self._cv.notify_all()
            self._ready.set()
            self._release_shared()
            return
        self._ready.set()
        while True:
            with self._cv:
                while not self._stop and self._request is None:
                    self._cv.wait()
                if self._stop:
                    break
                serial, params = self._request  # type: ignore[misc]
                self._request = None
                image = self._image if self._image_new else None
                self._image_new = False
                if image is not None:
                    self.enhancer_shape = image[0].shape[:2]
                    self.enhancer_channels = image[0].shape[2] if image[0].ndim == 3 else 1
            try:
                out = self._render(image, params)
                with self._cv:
                    # a newer request does not hide this render (the wheel is shown moving);
                    # one dropped meanwhile (Enter, the next trial's image) is never shown
                    if serial > self._dropped_upto:
                        self._result = Rendered(serial, out.params, out.seconds, out.rgba8,
                                                out.texture)
                        self._cv.notify_all()
            except Exception as exc:  # handed to the frame loop, which stops the session
                with self._cv:
                    self._error = exc
                    self._cv.notify_all()
        self._close_worker()

    def _close_worker(self) -> None:
        for t in self._textures:
            try:
                t.release()
            except Exception:
                pass
        self._textures = []
        close = getattr(self.enhancer, "close", None)
        if close is not None:  # the GPU backend's buffers and context, on their own thread
            try:
                close()
            except Exception:
                pass
        if self._gl_ctx is not None:
            self._gl_ctx = None
            self._release_shared()
