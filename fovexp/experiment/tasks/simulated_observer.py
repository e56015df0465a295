"""A simulated observer for the forced-choice task's dry runs and tests (issue 30, section 2):
it answers from a known psychometric function per method.

The function is :mod:`fovexp.results.psychometric`'s Weibull on blur-rate with the guess rate
0.5. Its threshold at 75 % correct is the truth's highest invisible blur-rate for the method
(``SimTruth.validation_blur_rate``, where an adjustment participant aims its wheel), so that a
participant simulated in both tasks has one truth; its shape and lapse rate are the truth's
``forced_choice_slope`` and ``forced_choice_lapse``. The gaze stays as the simulated eye gives
it; the observer answers after a response time drawn from its own stream.
"""

from __future__ import annotations

import math

import numpy as np

from fovexp.results.psychometric import (
    GUESS_RATE_2AFC,
    THRESHOLD_PC,
    log10_scale_for,
    proportion_correct,
)

from .procedures import Procedure, interleaved_methods
from .simulated_participant import SimTruth

DEFAULT_SLOPE = 3.0
DEFAULT_LAPSE = 0.02


class SimulatedObserver:
    """Answers left or right (module docstring); ``speed`` divides its response times."""

    def __init__(self, truth: SimTruth, seed: int, speed: float = 1.0) -> None:
        self.truth = truth
        self.rng = np.random.default_rng(seed)
        self.speed = speed

    def function(self, method: str) -> tuple[float, float, float]:
        """The method's (log10 Weibull scale, slope, lapse) of
        :func:`fovexp.results.psychometric.proportion_correct`."""
        slope = float(self.truth.forced_choice_slope.get(method, DEFAULT_SLOPE))
        lapse = float(self.truth.forced_choice_lapse.get(method, DEFAULT_LAPSE))
        threshold = self.truth.value("blur_rate", method, None, None)
        return log10_scale_for(math.log10(threshold), THRESHOLD_PC, slope, lapse), slope, lapse

    def p_correct(self, method: str, blur_rate_arcmin_per_deg: float) -> float:
        """The probability of a correct answer for ``method`` at this blur-rate."""
        if blur_rate_arcmin_per_deg <= 0:
            return GUESS_RATE_2AFC  # no foveation: the halves are the same
        t, slope, lapse = self.function(method)
        return float(proportion_correct(math.log10(blur_rate_arcmin_per_deg), t, slope, lapse))

    def answer(self, method: str, blur_rate_arcmin_per_deg: float, degraded_side: str) -> str:
        """``left`` or ``right``: the degraded side with the function's probability."""
        if self.rng.random() < self.p_correct(method, blur_rate_arcmin_per_deg):
            return degraded_side
        return "left" if degraded_side == "right" else "right"

    def response_time_s(self) -> float:
        """How long after the response screen appears the observer answers (s)."""
        return float(self.rng.uniform(0.3, 0.9)) / self.speed




def simulate_answers(truth: SimTruth, procedures: dict[str, Procedure],
                     trials_per_method: int, seed: int) -> list[dict[str, object]]:
    """A whole forced-choice session without a window: the methods interleaved at random
    (:func:`.procedures.interleaved_methods`), each trial's blur-rate from its method's
    procedure, the degraded side at random, the observer's answer. One row per trial
    (method, blur_rate, degraded_side, answer, correct): the answers of a dry run, in seconds
    for many participants (the recovery study, benchmarks/FORCED_CHOICE.md)."""
    observer = SimulatedObserver(truth, seed)
    rng = np.random.default_rng([seed, 1])
    rows: list[dict[str, object]] = []
    for method in interleaved_methods(list(procedures), trials_per_method, seed):
        proc = procedures[method]
        blur_rate = proc.next_blur_rate()
        side = "left" if rng.random() < 0.5 else "right"
        answer = observer.answer(method, blur_rate, side)
        proc.update(blur_rate, answer == side)
        rows.append({"method": method, "blur_rate": blur_rate, "degraded_side": side,
                     "answer": answer, "correct": answer == side})
    return rows


__all__ = ["SimulatedObserver", "simulate_answers"]
