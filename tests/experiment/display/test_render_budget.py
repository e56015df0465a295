"""The wheel-step budget check before the first trial
(:mod:`fovexp.experiment.display.render_budget`), without a window: the values rendered, the
renderer's own times, the cross kept on screen while a render is under way, the warning over
the budget, and a hung render stopping with one line."""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass

import pytest

from fovexp import FovexpError
from fovexp.experiment.display.render_budget import (
    step_result,
    step_values,
    step_warning,
    time_renders,
)


@dataclass
class Done:
    serial: int
    params: object
    seconds: float


class SlowRenderer:
    """Serves each request after ``delay_s`` on its own thread (as ``TestRenderer`` does)."""

    def __init__(self, delay_s: float) -> None:
        self.delay_s, self.requests, self._done = delay_s, [], {}

    def request(self, params) -> int:
        serial = len(self.requests)
        self.requests.append(params)

        def work() -> None:
            time.sleep(self.delay_s)
            self._done[serial] = Done(serial, params, self.delay_s)

        threading.Thread(target=work, daemon=True).start()
        return serial

    def wait(self, serial: int, timeout: float = 120.0) -> Done:
        end = time.monotonic() + timeout
        while serial not in self._done:
            if time.monotonic() > end:
                raise TimeoutError
            time.sleep(0.005)
        return self._done[serial]


def test_step_values_stay_in_range() -> None:
    assert step_values(0.0, 0.02, 1.5) == (0.0, 0.02)
    assert step_values(1.5, 0.02, 1.5) == (1.5, 1.48)  # at the top: one step down


class GatedRenderer:
    """Finishes a render only once the cross has been drawn ``polls`` times since it was
    requested: what the test checks does not depend on the wall clock (issue 19: it had
    counted the polls of a 0.12 s sleep, a timing assert)."""

    def __init__(self, polls: int, seconds: float) -> None:
        self.polls, self.seconds, self.requests, self.drawn = polls, seconds, [], 0
        self._since = 0

    def draw(self) -> None:
        self.drawn += 1

    def request(self, params) -> int:
        self.requests.append(params)
        self._since = self.drawn
        return len(self.requests) - 1

    def wait(self, serial: int, timeout: float = 120.0) -> Done:
        if self.drawn - self._since < self.polls:
            raise TimeoutError
        return Done(serial, self.requests[serial], self.seconds)


def test_renders_are_timed_with_the_cross_meanwhile() -> None:
    """The renderer's own times come back, one render after the other, and the cross is drawn
    at every poll while a render is under way (here 5 polls each)."""
    r = GatedRenderer(polls=5, seconds=0.12)
    got = time_renders(r, ["a", "b"], r.draw, poll_s=0.02)
    assert got == [0.12, 0.12] and r.requests == ["a", "b"]
    assert r.drawn == 10


def test_a_hung_render_is_one_line() -> None:
    with pytest.raises(FovexpError, match="the warm-up render took more than 0.1 s"):
        time_renders(SlowRenderer(5.0), ["a"], lambda: None, poll_s=0.02, timeout_s=0.1)


def test_the_budget() -> None:
    ok = step_result("blur_rate", 2.0, 0.08, 100.0)
    assert ok == {"parameter": "blur_rate", "first_render_ms": 2000.0, "step_ms": 80.0,
                  "max_step_ms": 100.0, "within_budget": True}
    assert step_warning("blur_rate", 0.08, 100.0, "gpu") is None
    slow = step_result("blur_rate", 2.0, 2.7134, 100.0)
    assert not slow["within_budget"] and slow["step_ms"] == 2713.4
    assert step_warning("blur_rate", 2.7134, 100.0, "cpu") == (
        "a wheel step (blur_rate) takes 2713 ms on the cpu backend, above the protocol's "
        "render.max_step_ms = 100 ms")
