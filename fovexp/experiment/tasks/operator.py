"""The operator's side of a session, without a window: the participant form, the display set-up
checklist, and the console line after each trial (docs/EXPERIMENT.md, "The operator").

The form and the checklist are recorded in the session file; neither is asked in a dry run.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np

from fovexp import FovexpError

#: The display settings a session relies on (paper section 5.1, "Hardware": an LG OLED55CX at
#: 4K, 120 Hz, peak luminance 167.33 cd/m2); the operator confirms them at the start of each
#: run, and the session file records it. docs/EXPERIMENT.md lists the same items.
DISPLAY_CHECKLIST: tuple[str, ...] = (
    "the display runs at the profile's mode: 3840x2160, 120 Hz, no desktop scaling",
    "the TV's low-latency mode: its game or PC mode, which shows each frame without the "
    "picture processing that holds it back by tens of ms (for the LG OLED55CX: picture mode "
    "Game, the HDMI input's icon set to PC); that mode turns off motion interpolation, noise "
    "reduction, sharpness enhancement and super-resolution, and dynamic contrast: check each "
    "below, a mode's defaults vary between firmware versions",
    "the picture calibrated in that mode: peak luminance 167 cd/m2 (measured on a full-white "
    "patch)",
    "sharpening (Sharpness) at 0 / off, and any super-resolution off",
    "noise reduction (noise and MPEG noise reduction) off",
    "motion smoothing (TruMotion / motion interpolation and OLED motion / black-frame "
    "insertion) off",
    "dynamic contrast, energy saving and automatic brightness limiting off",
    "the room: diffuse light behind a dark curtain, no reflections on the screen",
)

#: Answers the participant form accepts (the first letter is enough).
SEX_CHOICES: tuple[str, ...] = ("female", "male", "other", "undisclosed")
VISION_CHOICES: tuple[str, ...] = ("none", "glasses", "contact lenses", "other")
FORM_FIELDS: tuple[str, ...] = ("age", "sex", "vision_correction")


def _choice(field: str, text: str, choices: tuple[str, ...]) -> str:
    t = text.strip().lower()
    hits = [c for c in choices if c == t] or [c for c in choices if t and c.startswith(t)]
    if len(hits) != 1:
        raise FovexpError(f"{field} {text!r}: answer one of {', '.join(choices)} "
                          "(or leave it empty)")
    return hits[0]


def parse_form(answers: dict[str, str | None]) -> dict[str, Any]:
    """The participant form's answers, checked: ``age`` (whole years, 1 to 120), ``sex``
    (:data:`SEX_CHOICES`), ``vision_correction`` (:data:`VISION_CHOICES`); each optional
    (empty or None: not given). Raises :class:`FovexpError` naming the field."""
    unknown = set(answers) - set(FORM_FIELDS)
    if unknown:
        raise FovexpError(f"participant form: unknown field(s) {', '.join(sorted(unknown))}")
    out: dict[str, Any] = dict.fromkeys(FORM_FIELDS)
    age = (answers.get("age") or "").strip()
    if age:
        try:
            years = int(age)
        except ValueError:
            raise FovexpError(f"age {age!r}: a whole number of years (or leave it empty)") \
                from None
        if not 1 <= years <= 120:
            raise FovexpError(f"age {years}: outside 1 to 120")
        out["age"] = years
    sex = answers.get("sex") or ""
    if sex.strip():
        out["sex"] = _choice("sex", sex, SEX_CHOICES)
    vision = answers.get("vision_correction") or ""
    if vision.strip():
        out["vision_correction"] = _choice("vision correction", vision, VISION_CHOICES)
    return out


def ask_form(ask: Callable[[str], str], say: Callable[[str], None]) -> dict[str, Any]:
    """The participant form at a console: each question until its answer is valid or empty
    (Enter skips it). ``ask`` is ``input``; ``say`` prints a line."""
    prompts = {
        "age": "Age in years (Enter to skip): ",
        "sex": f"Sex ({'/'.join(SEX_CHOICES)}; Enter to skip): ",
        "vision_correction": f"Vision correction ({'/'.join(VISION_CHOICES)}; Enter to "
                             "skip): ",
    }
    out: dict[str, Any] = {}
    for field, prompt in prompts.items():
        while True:
            text = ask(prompt)
            try:
                out[field] = parse_form({field: text})[field]
                break
            except FovexpError as exc:
                say(str(exc))
    return out


def checklist_text(items: Iterable[str] = DISPLAY_CHECKLIST) -> str:
    """The display checklist as the confirmation screen shows it."""
    lines = "\n".join(f"- {item}" for item in items)
    return ("Operator: display set-up (docs/EXPERIMENT.md)\n\n" + lines +
            "\n\nC: all confirmed    Escape: quit")


def _duration(seconds: float) -> str:
    if not math.isfinite(seconds):
        return "?"
    s = int(round(seconds))
    return f"{s // 60} min {s % 60:02d} s" if s >= 60 else f"{s} s"


def trial_line(*, position: int, total: int, practice: bool, blanked_fraction: float,
               dropped: int, frames: int, latency_ms: np.ndarray, eta_s: float) -> str:
    """The console line after a trial: ``trial i/N``, the blanked time, dropped frames, the
    gaze-to-flip latency (median and worst, ms) and the time still to go."""
    lat = np.asarray(latency_ms, dtype=float)
    lat = lat[np.isfinite(lat)]
    latency = (f"gaze-to-flip {np.median(lat):.1f} ms (max {lat.max():.1f})" if lat.size
               else "gaze-to-flip n/a")
    kind = "practice " if practice else ""
    return (f"{kind}trial {position}/{total}: blanked {100 * blanked_fraction:.1f} %, "
            f"dropped {dropped}/{frames} frames, {latency}, ETA {_duration(eta_s)}")


def eta_s(trial_seconds: list[float], left: int) -> float:
    """The time ``left`` more trials take at the median trial duration so far (NaN before the
    first)."""
    if not trial_seconds:
        return math.nan
    return float(np.median(trial_seconds)) * left
