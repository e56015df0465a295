"""The forced-choice protocol's settings (``task: 2afc``, issue 30) and its plan.

A forced-choice protocol has the adjustment protocol's keys (display, images, methods, the
parameters from Table 2, fixation, tracker, practice, breaks) and, instead of ``adjust``, a
``forced_choice`` block: the presentation time, the trials per method, the procedure and its
blur-rate grid (arcmin/deg), feedback. Its ``adjust`` block, which the rest of the runner reads
for the shown parameter, is derived from it: the blur-rate over ``[0, the grid's top]``.

The plan (:func:`forced_choice_plan`): the practice trials first, at the grid's top blur-rate
(easy: the participant learns what to look for) with the practice methods; then each method
``trials_per_method`` times interleaved in a seeded random order, each trial on an image drawn
from the protocol's images. A trial's blur-rate is the procedure's at run time
(``Trial.blur_rate`` None); its degraded side is drawn from the session seed and the trial's
position, so a resumed session shows each trial on the same side.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from fovexp import check_parameter


class GridSpec(BaseModel):
    """A geometric grid of blur-rates: ``n`` values from ``low`` to ``high`` (arcmin/deg)."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    low: float = Field(gt=0)
    high: float = Field(gt=0)
    n: int = Field(ge=2, le=200)

    @model_validator(mode="after")
    def _check(self) -> GridSpec:
        if not self.low < self.high:
            raise ValueError(f"low {self.low} must be below high {self.high}")
        check_parameter("blur_rate", self.high)
        return self


class ForcedChoiceSpec(BaseModel):
    """The ``forced_choice`` block of a ``task: 2afc`` protocol (module docstring)."""

    model_config = ConfigDict(extra="forbid", frozen=True)
    #: the stimulus' time on screen per trial (s), then the blank response screen
    presentation_s: float = Field(default=1.5, gt=0, le=30)
    trials_per_method: int = Field(ge=1, le=1000)
    procedure: Literal["questplus", "constant"] = "questplus"
    #: QUEST+'s stimulus and threshold domain; the constant stimuli's levels
    grid: GridSpec
    #: QUEST+'s Weibull shapes (on blur-rate)
    slopes: list[float] = Field(default_factory=lambda: [1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0],
                                min_length=1)
    #: the lapse rate: fixed (one value) or a parameter of QUEST+ (several)
    lapse_rates: list[float] = Field(default_factory=lambda: [0.02], min_length=1)
    #: the answer keys: the left half, the right half
    keys: tuple[str, str] = ("left", "right")
    #: after each answer, "correct" or "wrong" for this long (s); 0: no feedback
    feedback_s: float = Field(default=0.0, ge=0, le=5)

    @model_validator(mode="after")
    def _check(self) -> ForcedChoiceSpec:
        for v in self.slopes:
            if not 0 < v <= 50:
                raise ValueError(f"slopes: {v} is not in (0, 50]")
        for v in self.lapse_rates:
            if not 0 <= v < 0.5:
                raise ValueError(f"lapse_rates: {v} is not in [0, 0.5)")
        if self.keys[0] == self.keys[1]:
            raise ValueError("keys: the left and right keys must differ")
        return self

    @property
    def grid_values(self) -> tuple[float, ...]:
        """The grid's blur-rates (arcmin/deg)."""
        return geometric_grid(self.grid.low, self.grid.high, self.grid.n)


def geometric_grid(low_arcmin_per_deg: float, high_arcmin_per_deg: float,
                   n: int) -> tuple[float, ...]:
    """``n`` blur-rates from ``low`` to ``high`` equally spaced in log (the Weibull's own axis:
    the function is a shift on log blur-rate, so equal log steps resolve every threshold
    alike). Rounded to 6 decimals, so that a protocol's grid reads the same on every machine."""
    if not 0 < low_arcmin_per_deg < high_arcmin_per_deg or n < 2:
        raise ValueError(f"a blur-rate grid needs 0 < low < high and n >= 2, not "
                         f"{low_arcmin_per_deg}, {high_arcmin_per_deg}, {n}")
    out = np.geomspace(low_arcmin_per_deg, high_arcmin_per_deg, n)
    return tuple(round(float(v), 6) for v in out)


def interleaved_methods(methods: Sequence[str], trials_per_method: int,
                        seed: int) -> list[str]:
    """The methods of a session's trials: each ``trials_per_method`` times, interleaved in an
    order drawn from ``seed`` (so that no method's trials cluster in time: fatigue and learning
    spread over all methods alike)."""
    pool = np.repeat(np.arange(len(methods)), trials_per_method)
    return [methods[int(i)] for i in np.random.default_rng(seed).permutation(pool)]


def derived_adjust(data: dict[str, Any]) -> dict[str, Any]:
    """A ``task: 2afc`` protocol's ``adjust`` block (module docstring), from its raw
    ``forced_choice`` block; unchanged where ``adjust`` is given (then the validation says
    what is wrong) or the block is not a mapping."""
    fc = data.get("forced_choice")
    grid = fc.get("grid") if isinstance(fc, dict) else None
    if "adjust" in data or not isinstance(grid, dict):
        return data
    high = grid.get("high")
    if not isinstance(high, int | float) or high <= 0:
        return data
    # the shown value is the blur-rate; its range holds every trial's (steps are never used)
    return {**data, "adjust": {"parameter": "blur_rate", "range": [0.0, float(high)],
                               "step": float(high), "fine_step": float(high),
                               "start": float(high)}}


def degraded_side(seed: int, position: int) -> str:
    """The half a trial shows the method on (``left``/``right``), from the session seed and
    the trial's position in the full plan."""
    return "left" if np.random.default_rng([seed, position, 2]).random() < 0.5 else "right"


def forced_choice_plan(methods: list[str], practice_methods: list[str] | None,
                       images: list[str], fc: ForcedChoiceSpec, seed: int, n_practice: int,
                       limit: int | None) -> list[tuple[bool, str, str]]:
    """(practice, method, image) per trial of the plan (module docstring); ``limit`` (a pilot,
    a dry run) plans ``limit`` main trials with the methods as equal as they can be: each
    method ``ceil(limit / methods)`` times, interleaved, the first ``limit`` kept."""
    rng = np.random.default_rng([seed, 1])
    pm = practice_methods or methods
    out = [(True, pm[int(rng.integers(len(pm)))], images[int(rng.integers(len(images)))])
           for _ in range(n_practice)]
    per_method = fc.trials_per_method
    if limit is not None:
        per_method = min(per_method, -(-limit // len(methods)))
    main = interleaved_methods(methods, per_method, seed)
    if limit is not None:
        main = main[:limit]
    irng = np.random.default_rng([seed, 3])
    out += [(False, m, images[int(irng.integers(len(images)))]) for m in main]
    return out


__all__ = ["ForcedChoiceSpec", "GridSpec", "degraded_side", "derived_adjust",
           "forced_choice_plan", "geometric_grid", "interleaved_methods"]
