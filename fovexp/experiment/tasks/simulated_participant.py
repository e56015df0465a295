"""A simulated participant for dry runs: turns the wheel towards a ground-truth value.

The ground truth is configurable per parameter and per blur-rate (a :class:`fovexp.ParameterTable`
for f_e, s_k and s_f, an optional s_k-versus-s_f slope for the amplitude experiment of paper
section 5.2, and a blur-rate per method for the validation of section 6.1), with a noise sd per
parameter: each trial's personal target is the truth plus Gaussian noise, clipped to the range.
The analysis' recovery test dry-runs such participants and checks that it recovers the truth.

Behaviour: a reaction time, a run of coarse notches towards the target that overshoots it by a
step or a few, a short pause, fine notches (modifier held) back to the target, a dwell, Enter.
All times are divided by ``speed`` so that CI runs a whole protocol in minutes.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from fovexp import PAPER_TABLE2, ParameterTable, read_yaml, validation_error

from .trial import InputEvent, Key, Wheel


class SimTruth(BaseModel):
    """Ground truth of a simulated participant (YAML with these keys; all optional)."""

    model_config = ConfigDict(extra="forbid")
    table: ParameterTable = PAPER_TABLE2
    #: s_k truth in calibration-sk: table s_k + sk_slope * (s_f - table s_f), per blur-rate
    sk_slope: float = -1.5
    #: highest invisible blur-rate per method (validation)
    validation_blur_rate: dict[str, float] = Field(
        default_factory=lambda: {"foveated": 0.25, "contrast": 0.4, "ours": 0.6})
    #: the forced-choice observer (issue 30, :mod:`.simulated_observer`): its thresholds are
    #: ``validation_blur_rate``'s, at 75 % correct; the Weibull's shape (on blur-rate) and the
    #: lapse rate, per method (a method not named: 3.0 and 0.02)
    forced_choice_slope: dict[str, float] = Field(default_factory=dict)
    forced_choice_lapse: dict[str, float] = Field(default_factory=dict)
    #: participant noise sd per parameter
    noise_sd: dict[str, float] = Field(
        default_factory=lambda: {"f_e": 0.02, "s_k": 1.5, "s_f": 0.25, "blur_rate": 0.04})
    #: a rehearsal's participant: each trial confirmed two wheel steps from its start value,
    #: so a trial renders a handful of steps (``--sim-truth quick``: a 4K rehearsal on a CPU
    #: in minutes, not tens of minutes; its values mean nothing)
    quick: bool = False

    @classmethod
    def named(cls, name: str) -> SimTruth:
        """``--sim-truth``'s value: ``quick`` (:attr:`quick`), else a YAML file's path."""
        return cls(quick=True) if name == "quick" else cls.load(name)

    def value(self, parameter: str, method: str, blur_rate: float | None,
              s_f: float | None) -> float:
        """The noise-free truth for a trial."""
        if parameter == "blur_rate":
            return float(self.validation_blur_rate.get(method, 0.4))
        assert blur_rate is not None
        f_e, s_k, s_f_t = self.table.at(blur_rate)
        if parameter == "f_e":
            return f_e
        if parameter == "s_f":
            return s_f_t
        if s_f is None:
            return s_k
        return s_k + self.sk_slope * (s_f - s_f_t)

    @classmethod
    def load(cls, path: str | Path) -> SimTruth:
        path = Path(path)
        data = read_yaml(path, "simulated-participant truth") or {}
        try:
            return cls.model_validate(data)
        except ValidationError as exc:
            raise validation_error(f"simulated-participant truth {path}", exc) from None


class SimulatedParticipant:
    """Produces wheel notches and Enter for one trial at a time (see the module docstring)."""

    def __init__(self, truth: SimTruth, seed: int, speed: float = 1.0,
                 noise_scale: float = 1.0) -> None:
        self.truth = truth
        self.rng = np.random.default_rng(seed)
        self.speed = speed
        self.noise_scale = noise_scale
        self.target = 0.0
        self.log: list[dict[str, Any]] = []

    def begin(self, parameter: str, method: str, blur_rate: float | None, s_f: float | None,
              lo: float, hi: float, step: float, fine_step: float,
              start: float | None = None) -> float:
        """Start a trial (its value at ``start``); returns this trial's personal target."""
        rng = self.rng
        true = self.truth.value(parameter, method, blur_rate, s_f)
        sd = self.truth.noise_sd.get(parameter, 0.0) * self.noise_scale
        if self.truth.quick and start is not None:
            true, sd = start + 2 * step * (1 if start + 2 * step <= hi else -1), 0.0
        self.target = float(np.clip(true + rng.normal(0.0, sd) if sd > 0 else true, lo, hi))
        self.lo, self.hi, self.step, self.fine_step = lo, hi, step, fine_step
        self.phase = "react"
        self.next_t = rng.uniform(0.4, 1.0) / self.speed
        self.overshoot = int(rng.integers(1, 4)) * step
        if self.truth.quick:  # one coarse step past: the fewest renders that still adjust
            self.overshoot = step
        self.notches = 0
        self.log.append({"truth": true, "target": self.target})
        return self.target

    def poll(self, t: float, value: float, visible: bool) -> list[InputEvent]:
        """Events to send at trial time ``t`` (s) given the value on screen."""
        if t < self.next_t:
            return []
        rng = self.rng
        if not visible:
            # Cannot judge a black screen: wait for the stimulus to come back.
            self.next_t = t + 0.1 / self.speed
            return []
        if self.notches > 2000:
            return [Key("return")]
        err = self.target - value
        if self.phase == "react":
            self.phase = "coarse"
            self.direction = 1 if err >= 0 else -1
        if self.phase == "coarse":
            # Keep turning until past the target by the overshoot (or the range ends).
            past = (value - self.target) * self.direction
            at_end = value >= self.hi if self.direction > 0 else value <= self.lo
            if past >= self.overshoot - 1e-12 or at_end:
                self.phase = "fine"
                self.next_t = t + rng.uniform(0.2, 0.5) / self.speed
                return []
            self.notches += 1
            self.next_t = t + rng.uniform(0.05, 0.11) / self.speed
            return [Wheel(self.direction, fine=False)]
        if self.phase == "fine":
            if abs(err) <= self.fine_step / 2 + 1e-12 or (
                    value >= self.hi and err > 0) or (value <= self.lo and err < 0):
                self.phase = "dwell"
                self.next_t = t + rng.uniform(0.3, 1.0) / self.speed
                return []
            self.notches += 1
            self.next_t = t + rng.uniform(0.06, 0.15) / self.speed
            return [Wheel(1 if err > 0 else -1, fine=True)]
        return [Key("return")]
