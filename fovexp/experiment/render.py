"""The test half of the screen, rendered by the enhancer on a worker thread.

Per trial the split-screen frame (reference left half and its mirror, paper section 6.1) is given
to :meth:`fovexp.Enhancer.set_image` once; each wheel step then calls ``enhance`` with the new
parameters, and the enhancer's stage cache redoes only what the changed parameter affects. The
worker keeps only the latest request, so a fast wheel never queues stale frames, and the frame
loop keeps flipping (and blanking) at the display rate while a frame is computed.
"""

from __future__ import annotations

import threading
import time
import traceback
from typing import Any

import numpy as np


class TestRenderer:
    """Renders the right (test) half for the latest requested parameters."""

    def __init__(self, display: Any, preset: str = "paper") -> None:
        from fovexp import Enhancer  # public API (docs/API.md)

        self.enhancer = Enhancer(display)
        self.preset = preset
        self._cv = threading.Condition()
        self._image: np.ndarray | None = None
        self._image_new = False
        self._request: tuple[int, Any] | None = None
        self._result: tuple[int, Any, np.ndarray, float] | None = None
        self._error: str | None = None
        self._serial = 0
        self._stop = False
        self._busy = False
        self._thread = threading.Thread(target=self._run, name="fovexp-render", daemon=True)
        self._thread.start()

    def set_image(self, frame: np.ndarray) -> None:
        """The split-screen frame of the next trial (applied before the next render)."""
        with self._cv:
            self._image = frame
            self._image_new = True
            self._request = None
            self._result = None

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
            if self._error is not None:
                err, self._error = self._error, None
                raise RuntimeError(f"rendering failed:\n{err}")
            out, self._result = self._result, None
            return out

    def wait(self, serial: int, timeout: float = 120.0) -> tuple[int, Any, np.ndarray, float]:
        """Block until the render ``serial`` (or a newer one) is done."""
        deadline = time.monotonic() + timeout
        with self._cv:
            while True:
                if self._error is not None:
                    err, self._error = self._error, None
                    raise RuntimeError(f"rendering failed:\n{err}")
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
        while True:
            with self._cv:
                while not self._stop and self._request is None:
                    self._cv.wait()
                if self._stop:
                    return
                serial, params = self._request  # type: ignore[misc]
                self._request = None
                image = self._image if self._image_new else None
                self._image_new = False
            try:
                t0 = time.perf_counter()
                if image is not None:
                    self.enhancer.set_image(image)
                res = self.enhancer.enhance(gaze=(0.5, 0.5), params=params)
                out = np.asarray(res.output, dtype=np.float32)
                w = out.shape[1]
                right = np.ascontiguousarray(out[:, w // 2:])
                dt = time.perf_counter() - t0
                with self._cv:
                    self._result = (serial, params, right, dt)
                    self._cv.notify_all()
            except Exception:
                with self._cv:
                    self._error = traceback.format_exc()
                    self._cv.notify_all()
