"""The display side of a session before its first trial: the window opened at the display's
size, its refresh rate and size checked against the profile, the renderer started on the
window's GL context, the keyboard's time stamps and the wheel step's render time checked.

Each check returns what goes into the session file and, where the operator must hear of it,
the warning: the session says it (console, session file, instruction screen).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from fovexp import FovexpError

from ..interfaces import Renderer, Screen, ScreenFactory
from .render_budget import step_result, step_values, step_warning, time_renders

if TYPE_CHECKING:
    from fovexp import Display, EnhanceParams

    from .render import TestRenderer

#: (text, event, detail): a warning for the operator and the session file's event
Note = tuple[str, str, dict[str, Any]]


def cross_px(size: tuple[int, int], display: Display, ppd_centre: float,
             cross_size_deg: float) -> float:
    """The fixation cross's size in window pixels, from the protocol's degrees at the screen
    centre (at least 7 px)."""
    ppd = ppd_centre * size[0] / display.width_px
    return max(7.0, cross_size_deg * ppd)


def open_screen(factory: ScreenFactory | None, display: Display, *,
                window_size: tuple[int, int] | None, fullscreen: bool, dry_run: bool,
                screen: int, ppd_centre: float, cross_size_deg: float) -> Screen:
    """The window (the display's size unless ``window_size``; fullscreen unless a dry run);
    ``factory`` None: PsychoPy's (:class:`.window.PsychoScreen`)."""
    if factory is None:
        from .window import PsychoScreen

        factory = PsychoScreen
    size = window_size or (display.width_px, display.height_px)
    return factory(size=size, fullscreen=fullscreen and not dry_run,
                   cross_px=cross_px(size, display, ppd_centre, cross_size_deg),
                   dry_run=dry_run, refresh_hz=display.refresh_hz, screen=screen)


def check_display(screen: Screen, display: Display, *, dry_run: bool,
                  skip: bool) -> tuple[dict[str, Any], float]:
    """The measured refresh rate and window size against the profile (closes the window and
    raises on a mismatch unless ``skip``). Returns the session file's record and the rate
    dropped frames are counted against: the measured one where there is one."""
    from .window import check_display as check

    refresh_hz = float(getattr(screen, "refresh_hz", display.refresh_hz))
    if dry_run:
        return {"skipped": True, "reason": "dry run", "refresh_hz": refresh_hz}, refresh_hz
    measured, size, fb = screen.measure_display()
    if measured is not None:
        refresh_hz = measured
    if skip:
        return {"skipped": True, "reason": "--skip-display-check", "measured_refresh_hz":
                measured, "window_size": size, "framebuffer_size": fb,
                "refresh_hz": refresh_hz}, refresh_hz
    try:
        return check(measured, size, fb, display), refresh_hz
    except FovexpError:
        screen.close()
        raise


def start_renderer(display: Display, spec: Any, backend: str,
                   screen: Screen) -> TestRenderer:
    """The renderer's thread (:class:`.render.TestRenderer`) for the protocol's preset, on the
    window's own GL context where the screen shares one and the backend may use it."""
    from .render import TestRenderer

    share = getattr(screen, "gl_share", None)
    return TestRenderer(display, spec.preset, spec.geometry_model, backend,
                        gl_share=share() if share is not None and backend != "cpu" else None)


def keys_at_poll(info: dict[str, Any]) -> str | None:
    """Why the window's keys do not carry the time they went down (``info``: the window's
    :meth:`Screen.info`), with what to install; None when they do. An answer would then be the
    value on screen at the poll that saw Enter, up to a frame later than the press. The rig
    check fails its keyboard check with the same words."""
    kb = info.get("keyboard") or {}
    if kb.get("key_time") == "press":
        return None
    return (f"key presses are stamped when polled, not when pressed (keyboard backend "
            f"{kb.get('backend')!r}): install psychtoolbox's libjack (Debian/Ubuntu: "
            "apt-get install libjack-jackd2-0) or run an ioHub server")


def keyboard_note(info: dict[str, Any], dry_run: bool, accept: bool = False) -> Note | None:
    """A real session whose keys would be stamped at the poll does not start
    (:class:`FovexpError` naming what to install) unless ``accept`` (``--accept-poll-keys``):
    then a warning, its event recording the choice. A dry run's simulated participant answers
    at the poll anyway."""
    why = keys_at_poll(info)
    if why is None or dry_run:
        return None
    if not accept:
        raise FovexpError(f"{why}; --accept-poll-keys runs the session anyway (recorded)")
    return (why, "keyboard_stamps_at_poll",
            {"backend": (info.get("keyboard") or {}).get("backend"), "accepted": True})


def rig_note(results_root: Any, dry_run: bool, file: Any) -> Note | None:
    """The newest rig check under the results root (``fovexp rig check``): its name and sha256
    into this run's entry of the session ``file`` (``runs[].rig_check``); a warning for the
    operator of a real session when there is none from today, it failed, or it was only a dry
    run."""
    from fovexp.results.format import now_iso
    from fovexp.results.rigcheck import session_rig_record

    rec, warning = session_rig_record(results_root, now_iso()[:10], dry_run)
    file.set_in_run("rig_check", rec)
    if warning is None or dry_run:
        return None
    return (warning, "rig_check_warning", {"warning": warning})


def renderer_notes(info: dict[str, Any]) -> list[Note]:
    """The renderer's own warnings (``info``: its :meth:`Renderer.info`): ``auto`` fell back to
    the CPU, and any note the backend made."""
    notes: list[Note] = []
    if info.get("fallback"):
        notes.append((f"enhancer on the CPU: {info['fallback']}", "backend_fallback",
                      {"reason": info["fallback"]}))
    notes += [(n, "render_note", {"note": n}) for n in info.get("notes") or []]
    return notes


def render_budget(renderer: Renderer, spec: Any, frame: np.ndarray, start_value: float,
                  params: Callable[[float], EnhanceParams], cross_alone: Callable[[], None]
                  ) -> tuple[dict[str, Any], Note | None]:
    """Whether the renderer shows a wheel step within the protocol's budget
    (``render.max_step_ms``), measured on ``frame`` (the first remaining trial's: a warm-up
    render, then one wheel step, the cross alone on screen meanwhile). Returns the record and
    a warning when over the budget; never stops the session."""
    w = frame.shape[1]
    renderer.set_image(frame[:, w // 2:], (w, frame.shape[0]))
    adj = spec.adjust
    first_s, step_s = time_renders(
        renderer, [params(v) for v in step_values(start_value, adj.step, adj.range[1])],
        cross_alone)
    budget = spec.render.max_step_ms
    result = step_result(adj.parameter, first_s, step_s, budget)
    warning = step_warning(adj.parameter, step_s, budget, renderer.info()["backend"])
    return result, (None if warning is None else
                    (warning, "render_budget_exceeded", result))
