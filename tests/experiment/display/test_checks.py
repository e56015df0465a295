"""The display's checks before a session's first trial, without a window
(:mod:`fovexp.experiment.display.checks`, :func:`fovexp.experiment.display.window.check_display`):
the refresh rate and size against the profile, the cross's size, the operator's warnings."""

from __future__ import annotations

import pytest

from fovexp import FovexpError, load_display
from fovexp.experiment.display.checks import cross_px, keyboard_note, renderer_notes
from fovexp.experiment.display.window import check_display
from fovexp.experiment.trackers.gaze import FixationGeometry

DISPLAY = load_display("lg-oled55cx")


def test_display_check_refresh_rate() -> None:
    size = (DISPLAY.width_px, DISPLAY.height_px)
    info = check_display(119.2, size, size, DISPLAY)
    assert info["measured_refresh_hz"] == 119.2 and info["profile_refresh_hz"] == 120
    # The 120 Hz screen running at 60 Hz stops the session.
    with pytest.raises(FovexpError, match=r"measured refresh 60\.0 Hz.*says 120 Hz"):
        check_display(60.0, size, size, DISPLAY)
    with pytest.raises(FovexpError, match="could not be measured"):
        check_display(None, size, size, DISPLAY)


def test_display_check_scaling() -> None:
    size = (DISPLAY.width_px, DISPLAY.height_px)
    # 150 % desktop scaling: the window reports fewer pixels than the framebuffer has.
    with pytest.raises(FovexpError) as err:
        check_display(120.0, (2560, 1440), size, DISPLAY)
    msg = str(err.value)
    assert "window is 2560x1440 px (framebuffer 3840x2160)" in msg and "3840x2160" in msg
    assert "--skip-display-check" in msg and "\n" not in msg
    with pytest.raises(FovexpError, match="framebuffer 1920x1080"):
        check_display(120.0, size, (1920, 1080), DISPLAY)
    # Both problems at once are both named.
    with pytest.raises(FovexpError, match=r"60\.0 Hz.*; window is"):
        check_display(60.0, (2560, 1440), (2560, 1440), DISPLAY)


def test_the_cross_is_its_degrees_at_the_centre_in_window_pixels() -> None:
    """0.5 deg at the centre of the 4K profile, in the full window and in a quarter-size one
    (pixels per degree scale with the window's width); never under 7 px."""
    ppd = FixationGeometry(DISPLAY).ppd_centre
    full = cross_px((3840, 2160), DISPLAY, ppd, 0.5)
    assert full == pytest.approx(0.5 * ppd) and full > 7.0
    assert cross_px((960, 540), DISPLAY, ppd, 0.5) == pytest.approx(max(7.0, full / 4))
    assert cross_px((480, 270), DISPLAY, ppd, 0.01) == 7.0


def test_warnings_for_the_operator() -> None:
    """Keys stamped at the poll stop a real session unless accepted (then a warning whose
    event records the choice), never a dry run; the renderer's fallback and notes become one
    warning each, with their session-file events."""
    poll = {"keyboard": {"backend": "event", "key_time": "poll"}}
    with pytest.raises(FovexpError, match="libjack.*--accept-poll-keys"):
        keyboard_note(poll, dry_run=False)
    text, event, detail = keyboard_note(poll, dry_run=False, accept=True)
    assert event == "keyboard_stamps_at_poll" and detail == {"backend": "event", "accepted": True}
    assert "libjack" in text
    assert keyboard_note(poll, dry_run=True) is None
    assert keyboard_note({"keyboard": {"backend": "ptb", "key_time": "press"}}, False) is None
    notes = renderer_notes({"fallback": "software GL", "notes": ["a", "b"]})
    assert [(e, d) for _, e, d in notes] == [("backend_fallback", {"reason": "software GL"}),
                                             ("render_note", {"note": "a"}),
                                             ("render_note", {"note": "b"})]
    assert renderer_notes({"backend": "cpu"}) == []
