"""The adjustment's window-free logic (:mod:`fovexp.experiment.tasks.trial`): value stepping,
the wheel, the frame timer and the blanking log of an attempt."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fovexp.experiment.tasks.trial import (
    BlankingLog,
    FrameTimer,
    Key,
    TrialState,
    ValueAdjuster,
    Wheel,
    wheel_notches,
)

# -- value stepping --------------------------------------------------------------------------

def test_adjuster_steps_and_clamps() -> None:
    a = ValueAdjuster(0.0, 0.4, 0.02, 0.005, 0.1)
    assert a.apply(Wheel(3)) and a.value == pytest.approx(0.16)
    assert a.apply(Wheel(-2, fine=True)) and a.value == pytest.approx(0.15)
    a.apply(Wheel(100))
    assert a.value == 0.4
    assert not a.apply(Wheel(1))  # at the end of the range: no change, still counted
    assert a.notches == 3 + 2 + 100 + 1
    a.apply(Wheel(-1000))
    assert a.value == 0.0


def test_wheel_notches_sum_fractions() -> None:
    """A high-resolution wheel reports fractions of a notch: they add up to whole notches."""
    assert wheel_notches([(1.0, False), (2.0, False), (-1.0, True)]) == (
        [Wheel(3), Wheel(-1, fine=True)], (0.0, True))
    wheel, carry = wheel_notches([(0.4, False)] * 3)
    assert wheel == [Wheel(1)] and carry == (pytest.approx(0.2), False)
    wheel, carry = wheel_notches([(0.4, False), (0.5, False)], carry)  # carried over
    assert wheel == [Wheel(1)] and carry == (pytest.approx(0.1), False)
    wheel, carry = wheel_notches([(-0.3, False)] * 4, carry)  # back the other way
    assert wheel == [Wheel(-1)] and carry == (pytest.approx(-0.1), False)  # 0.1 - 1.2 = -1.1
    # ten tenths are one notch, although their float sum is 0.999...
    assert wheel_notches([(0.1, False)] * 10)[0] == [Wheel(1)]
    assert wheel_notches([(0.1, False)] * 20)[0] == [Wheel(2)]
    # a fine half-turn and a coarse half-turn are not one coarse notch
    wheel, carry = wheel_notches([(0.6, True), (0.6, False)])
    assert wheel == [] and carry == (pytest.approx(0.6), False)


@given(st.lists(st.tuples(st.integers(-5, 5), st.booleans()), max_size=200))
@settings(max_examples=50, deadline=None)
def test_adjuster_never_leaves_range(moves: list[tuple[int, bool]]) -> None:
    a = ValueAdjuster(0.0, 45.0, 1.5, 0.25, 20.0)
    for n, fine in moves:
        a.apply(Wheel(n, fine))
        assert 0.0 <= a.value <= 45.0
        # Values stay on the step grid (no floating-point drift).
        assert abs(a.value * 4 - round(a.value * 4)) < 1e-6


def test_trial_state_confirm_and_pause() -> None:
    s = TrialState(ValueAdjuster(0, 1, 0.1, 0.01, 0.5), 60.0)
    assert s.handle([Wheel(1), Key("return")]) is None  # nothing counts before the first frame
    s.flip(10.0, False, "")
    assert s.handle([Wheel(2)]) == "changed" and s.value == pytest.approx(0.7)
    assert s.handle([Key("escape")]) == "pause"
    assert s.handle([Key("return")]) == "confirm"
    s.finish(11.5)
    assert s.response_time_s == pytest.approx(1.5)


def test_frame_timer_counts_dropped() -> None:
    t = FrameTimer(120.0)
    times = [0, 1 / 120, 2 / 120, 4 / 120, 5 / 120, 5.5 / 120 + 1 / 120]
    for x in times:
        t.flip(x)
    assert t.dropped == 1 and len(t.intervals) == 5


def test_blanking_log_episodes() -> None:
    b = BlankingLog()
    pattern = [0, 0, 1, 1, 1, 0, 0, 1, 0, 1, 1]
    for i, blank in enumerate(pattern):
        b.frame(i * 0.01, bool(blank), "outside" if blank else "")
    b.close(0.2)
    assert [(round(e.start_s, 3), round(e.end_s, 3), e.frames) for e in b.episodes] == [
        (0.02, 0.05, 3), (0.07, 0.08, 1), (0.09, 0.2, 2)]
    # time-weighted, on the episodes' own time base: (0.03 + 0.01 + 0.11) / 0.2
    assert b.fraction == pytest.approx(sum(e.end_s - e.start_s for e in b.episodes) / 0.2)
    assert b.fraction == pytest.approx(0.75)
    assert (b.frames, b.blanked) == (11, 6)


def test_blanked_fraction_counts_how_long_a_black_frame_stayed() -> None:
    """One black frame followed by a dropped (0.49 s) interval: black for 98 % of the trial, not
    for 1 of 4 frames."""
    b = BlankingLog()
    for t, blank in ((0.0, False), (0.01, True), (0.50, False), (0.51, False)):
        b.frame(t, blank, "outside" if blank else "")
    b.close(0.51)
    assert b.fraction == pytest.approx(0.49 / 0.51)
    assert b.episodes[0].end_s - b.episodes[0].start_s == pytest.approx(0.49)
