"""Whether the renderer shows a wheel step in time, measured before the first trial, without a
window: a warm-up render of the start value, then one of the value a wheel step away, timed by
the renderer itself; against the protocol's ``render.max_step_ms``. A step slower than that is
a warning for the operator (console, session file, instruction screen), never a stop: paper
section 5.1 ("Task") updates the test half "in real-time", which only the GPU backend does at
4K.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from fovexp import FovexpError

from ..interfaces import Renderer

#: a render taking longer than this stops the session (a hung backend)
RENDER_TIMEOUT_S = 300.0


def step_values(start: float, step: float, hi: float) -> tuple[float, float]:
    """The start value and the value one coarse step away (up, or down at the range's top)."""
    return start, (start + step if start + step <= hi else start - step)


def time_renders(renderer: Renderer, params: list[Any], between: Callable[[], None],
                 poll_s: float = 0.05, timeout_s: float = RENDER_TIMEOUT_S) -> list[float]:
    """Render ``params`` one after the other; the renderer's own seconds for each. ``between``
    runs every ``poll_s`` while a render is under way (the session draws the cross alone and
    drains the gaze)."""
    out = []
    for p in params:
        deadline = time.monotonic() + timeout_s
        serial = renderer.request(p)
        while True:
            try:
                out.append(renderer.wait(serial, timeout=poll_s).seconds)
                break
            except TimeoutError:
                if time.monotonic() > deadline:
                    raise FovexpError(f"the warm-up render took more than {timeout_s:g} s"
                                      ) from None
                between()
    return out


def step_result(parameter: str, first_s: float, step_s: float,
                max_step_ms: float) -> dict[str, Any]:
    """What the session file records (``render.wheel_step``)."""
    step_ms = 1e3 * step_s
    return {"parameter": parameter, "first_render_ms": round(1e3 * first_s, 1),
            "step_ms": round(step_ms, 1), "max_step_ms": max_step_ms,
            "within_budget": step_ms <= max_step_ms}


def step_warning(parameter: str, step_s: float, max_step_ms: float,
                 backend: str) -> str | None:
    """The operator's warning for a step over the budget; None within it."""
    step_ms = 1e3 * step_s
    if step_ms <= max_step_ms:
        return None
    return (f"a wheel step ({parameter}) takes {step_ms:.0f} ms on the {backend} backend, "
            f"above the protocol's render.max_step_ms = {max_step_ms:g} ms")


__all__ = ["RENDER_TIMEOUT_S", "step_result", "step_values", "step_warning", "time_renders"]
