"""The test half of the screen, rendered by the enhancer on a worker thread.

Per trial the processed half of the split screen (the reference's mirrored left half, paper
section 6.1) is given to :meth:`fovexp.Enhancer.set_image` once, as the right half of the
full-screen frame (``viewport``), so the enhancer computes only that half while eccentricity is
still measured from the screen centre; each wheel step then calls ``enhance`` with the new
parameters, and the enhancer's stage cache redoes only what the changed parameter affects. The
worker keeps only the latest request, so a fast wheel never queues stale frames, and the frame
loop keeps flipping (and blanking) at the display rate while a frame is computed; every result
carries the parameters it was computed with, so the frame loop knows what is on screen.
Errors on the worker reach the frame loop as one-line :class:`fovexp.FovexpError`.

The enhancer runs on the CPU or the GPU backend (``backend``: auto, cpu, gpu; see
:func:`fovexp.make_enhancer`); it is created on the worker thread, which owns its OpenGL
context, and :meth:`TestRenderer.info` says which backend and renderer it got.
"""

from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np

from fovexp import FovexpError

#: The gaze point of the enhancer: the fixation cross at the screen centre (normalised).
SCREEN_CENTRE = (0.5, 0.5)


class TestRenderer:
    """Renders the right (test) half for the latest requested parameters."""

    def __init__(self, display: Any, preset: str = "paper", geometry: str | None = None,
                 backend: str = "auto") -> None:
        self.preset = preset
        self.enhancer: Any = None
        self._make = (display, preset, geometry, backend)
        self._ready = threading.Event()
        self._cv = threading.Condition()
        self._image: tuple[np.ndarray, tuple[int, int, int, int]] | None = None
        self._image_new = False
        self._request: tuple[int, Any] | None = None
        self._result: tuple[int, Any, np.ndarray, float] | None = None
        self._error: Exception | None = None
        self._serial = 0
        self._stop = False
        self._busy = False
        self._thread = threading.Thread(target=self._run, name="fovexp-render", daemon=True)
        self._thread.start()

    def set_image(self, right: np.ndarray, screen_size: tuple[int, int]) -> None:
        """The processed (right) half of the next trial's split screen, whose full frame is
        ``screen_size = (width, height)`` px (applied before the next render)."""
        w, h = screen_size
        with self._cv:
            self._image = (right, (w - right.shape[1], 0, w, h))
            self._image_new = True
            self._request = None
            self._result = None

    def info(self, timeout: float = 60.0) -> dict[str, str]:
        """``{"backend": "cpu" | "gpu", "renderer": ...}`` once the worker has its enhancer."""
        if not self._ready.wait(timeout):
            raise TimeoutError(f"the renderer did not start within {timeout} s")
        with self._cv:
            self._raise_error()
        enh = self.enhancer
        return {"backend": enh.backend, "renderer": getattr(enh, "renderer", "numpy/numba")}

    def request(self, params: Any) -> int:
        """Ask for the test half with ``params`` (an EnhanceParams); returns a serial number."""
        with self._cv:
            self._serial += 1
            self._request = (self._serial, params)
            self._cv.notify()
            return self._serial

    def poll(self) -> tuple[int, Any, np.ndarray, float] | None:
        """The newest finished render ``(serial, params, right_half, seconds)``, once."""
        with self._cv:
            self._raise_error()
            out, self._result = self._result, None
            return out

    def _raise_error(self) -> None:
        if self._error is not None:
            err, self._error = self._error, None
            if isinstance(err, FovexpError):
                raise FovexpError(f"rendering failed: {err}")
            raise err  # a bug: the session records its traceback and reports one line

    def wait(self, serial: int, timeout: float = 120.0) -> tuple[int, Any, np.ndarray, float]:
        """Block until the render ``serial`` (or a newer one) is done."""
        deadline = time.monotonic() + timeout
        with self._cv:
            while True:
                self._raise_error()
                if self._result is not None and self._result[0] >= serial:
                    out, self._result = self._result, None
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

    def _run(self) -> None:
        from fovexp import make_enhancer  # public API (docs/API.md)

        try:
            display, preset, geometry, backend = self._make
            self.enhancer = make_enhancer(display, preset, geometry, backend=backend)
        except Exception as exc:  # e.g. --backend gpu with no OpenGL 4.5: reported, then stop
            with self._cv:
                self._error = exc
                self._cv.notify_all()
            return
        finally:
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
            try:
                t0 = time.perf_counter()
                if image is not None:
                    self.enhancer.set_image(image[0], viewport=image[1])
                res = self.enhancer.enhance(gaze=SCREEN_CENTRE, params=params)
                right = np.ascontiguousarray(res.output, dtype=np.float32)
                dt = time.perf_counter() - t0
                with self._cv:
                    self._result = (serial, params, right, dt)
                    self._cv.notify_all()
            except Exception as exc:  # handed to the frame loop, which stops the session
                with self._cv:
                    self._error = exc
                    self._cv.notify_all()
        close = getattr(self.enhancer, "close", None)
        if close is not None:  # the GPU backend's buffers and context, on their own thread
            close()
