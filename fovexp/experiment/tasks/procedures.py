"""The adaptive procedures of the forced-choice task (issue 30), without a window: which
blur-rate each method's next trial shows, and the procedure's state rebuilt from the logged
answers after a crash.

Two procedures, one per method, interleaved at random (:func:`interleaved_methods`):

- :class:`QuestPlus`: QUEST+ (Watson 2017, J. Vis. 17(3):10) through the ``questplus`` package
  (PsychoPy's dependency, which its ``QuestPlusHandler`` wraps) over a stated grid of
  blur-rates, a Weibull function on log10 blur-rate (:mod:`fovexp.results.psychometric`), the
  guess rate 0.5, the lapse rate fixed or a parameter. The next blur-rate is the one that
  minimises the expected entropy of the posterior (``min_entropy``: deterministic, so a replay
  gives the same choices).
- :class:`ConstantStimuli`: the method of constant stimuli, each stated level equally often in
  a seeded random order.

State is never saved: :func:`rebuild` replays the logged ``(blur-rate, correct)`` pairs into a
fresh procedure. The replay is exact because the blur-rates come from the grid and are logged
as round-trip floats (``trials.csv``; ../shared/CHECKED.md: a rounded intensity would not be
found in questplus' likelihood table), and because each logged blur-rate is checked against the
procedure's own choice at that point (a log from another protocol is refused, not followed).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Protocol

import numpy as np

from fovexp import FovexpError
from fovexp.results.psychometric import GUESS_RATE_2AFC, THRESHOLD_PC, log10_threshold_at

from ..protocol.forced_choice import geometric_grid, interleaved_methods

CORRECT, INCORRECT = "Correct", "Incorrect"


class Procedure(Protocol):
    """What the task asks of a procedure: the next blur-rate, and each answer."""

    n_trials: int

    def next_blur_rate(self) -> float: ...

    def update(self, blur_rate_arcmin_per_deg: float, correct: bool) -> None: ...


def _grid_index(grid: Sequence[float], blur_rate: float, what: str) -> int:
    """The index of ``blur_rate`` in ``grid`` (exact equality: logged values round-trip)."""
    for i, v in enumerate(grid):
        if v == blur_rate:
            return i
    raise FovexpError(f"{what}: blur-rate {blur_rate!r} arcmin/deg is not on the procedure's "
                      f"grid ({grid[0]}..{grid[-1]}, {len(grid)} levels)")


class QuestPlus:
    """QUEST+ for one method (module docstring). ``grid_arcmin_per_deg``: the blur-rates it
    may show, and the thresholds it considers (the Weibull's scale ``t`` on the same grid);
    ``slopes``: the Weibull's shapes considered; ``lapse_rates``: one value (fixed) or several
    (the lapse a parameter)."""

    def __init__(self, grid_arcmin_per_deg: Sequence[float], slopes: Sequence[float],
                 lapse_rates: Sequence[float], guess_rate: float = GUESS_RATE_2AFC) -> None:
        try:
            from questplus import QuestPlus as _QuestPlus
        except ImportError:
            raise FovexpError("the forced-choice task's QUEST+ needs the questplus package: "
                              "pip install 'fovexp[experiment]'") from None
        self.grid = tuple(float(v) for v in grid_arcmin_per_deg)
        self.slopes, self.lapse_rates = tuple(slopes), tuple(lapse_rates)
        self.guess_rate = guess_rate
        # the stimulus domain in log10 units: questplus' 'log10' Weibull takes x = log10(b)
        self._x = [math.log10(v) for v in self.grid]
        self._qp = _QuestPlus(
            stim_domain={"intensity": self._x},
            param_domain={"threshold": self._x, "slope": list(self.slopes),
                          "lower_asymptote": [guess_rate], "lapse_rate": list(self.lapse_rates)},
            outcome_domain={"response": [CORRECT, INCORRECT]},
            func="weibull", stim_scale="log10", stim_selection_method="min_entropy",
            param_estimation_method="mean")
        self.n_trials = 0
        self._next: float | None = None

    def next_blur_rate(self) -> float:
        """The blur-rate of this method's next trial (arcmin/deg), a value of the grid."""
        if self._next is None:
            x = self._qp.next_stim["intensity"]
            self._next = self.grid[self._x.index(x)]
        return self._next

    def update(self, blur_rate_arcmin_per_deg: float, correct: bool) -> None:
        """One answer at a blur-rate of the grid."""
        i = _grid_index(self.grid, blur_rate_arcmin_per_deg, "QUEST+")
        self._qp.update(stim={"intensity": self._x[i]},
                        outcome={"response": CORRECT if correct else INCORRECT})
        self.n_trials += 1
        self._next = None

    def estimate(self, pc: float = THRESHOLD_PC) -> dict[str, float]:
        """The posterior means of the parameters, and the blur-rate at ``pc`` correct from them
        (arcmin/deg): the procedure's own running estimate, not the analysis' fit."""
        est = self._qp.param_estimate
        log_t = float(log10_threshold_at(pc, est["threshold"], est["slope"],
                                         est["lapse_rate"], self.guess_rate))
        return {"threshold_arcmin_per_deg": 10.0 ** log_t, "slope": float(est["slope"]),
                "lapse_rate": float(est["lapse_rate"])}


class QuestPlusArrays:
    """:class:`QuestPlus`'s computation in plain NumPy (Watson 2017, eqs. 1-6: the posterior
    after each answer, the expected entropy of the next posterior per stimulus, its minimum),
    about 100x faster than questplus' xarray tables: for simulations of many participants (the
    recovery study, benchmarks/FORCED_CHOICE.md). Tested to choose what questplus chooses."""

    def __init__(self, grid_arcmin_per_deg: Sequence[float], slopes: Sequence[float],
                 lapse_rates: Sequence[float], guess_rate: float = GUESS_RATE_2AFC) -> None:
        from fovexp.results.psychometric import proportion_correct

        self.grid = tuple(float(v) for v in grid_arcmin_per_deg)
        self.guess_rate = guess_rate
        x = np.log10(np.array(self.grid))
        t, s, lam = np.meshgrid(x, np.asarray(slopes, float), np.asarray(lapse_rates, float),
                                indexing="ij")
        self._params = (t.ravel(), s.ravel(), lam.ravel())
        # p(correct | stimulus i, parameters j)
        t_j, s_j, lam_j = (v[None, :] for v in self._params)
        self._p = proportion_correct(x[:, None], t_j, s_j, lam_j)
        self.posterior = np.full(t.size, 1.0 / t.size)  # questplus' default: a uniform prior
        self.n_trials = 0
        self._next: float | None = None

    def next_blur_rate(self) -> float:
        if self._next is None:
            ent = np.zeros(len(self.grid))
            for lik in (self._p, 1.0 - self._p):
                joint = self.posterior[None, :] * lik
                pk = joint.sum(axis=1)
                post = joint / pk[:, None]
                with np.errstate(divide="ignore", invalid="ignore"):
                    h = -np.nansum(post * np.log(post), axis=1)
                ent += pk * h
            self._next = self.grid[int(np.argmin(ent))]
        return self._next

    def update(self, blur_rate_arcmin_per_deg: float, correct: bool) -> None:
        i = _grid_index(self.grid, blur_rate_arcmin_per_deg, "QUEST+")
        self.posterior = self.posterior * (self._p[i] if correct else 1.0 - self._p[i])
        self.posterior /= self.posterior.sum()
        self.n_trials += 1
        self._next = None


class ConstantStimuli:
    """The method of constant stimuli for one method: ``n_trials`` trials over ``levels``
    (arcmin/deg), each level ``n_trials / len(levels)`` times (the first ones once more when it
    does not divide), in an order drawn from ``seed``."""

    def __init__(self, levels_arcmin_per_deg: Sequence[float], n_trials: int, seed: int) -> None:
        self.grid = tuple(float(v) for v in levels_arcmin_per_deg)
        reps = -(-n_trials // len(self.grid))
        order = np.tile(np.arange(len(self.grid)), reps)[:n_trials]
        self.order = [self.grid[int(i)] for i in np.random.default_rng(seed).permutation(order)]
        self.n_trials = 0

    def next_blur_rate(self) -> float:
        # past the planned trials (a protocol that asks for more) the order starts again
        return self.order[self.n_trials % len(self.order)]

    def update(self, blur_rate_arcmin_per_deg: float, correct: bool) -> None:
        _grid_index(self.grid, blur_rate_arcmin_per_deg, "constant stimuli")
        self.n_trials += 1


def rebuild(procedure: Procedure, answers: Iterable[tuple[float, bool]],
            what: str = "the log") -> Procedure:
    """``procedure`` (fresh) after the logged ``answers`` (blur-rate in arcmin/deg, correct),
    in the order they were given. Each logged blur-rate must be the one the procedure chooses
    at that point: a log that does not is from another protocol or seed, and is refused."""
    for k, (blur_rate, correct) in enumerate(answers):
        expected = procedure.next_blur_rate()
        if blur_rate != expected:
            raise FovexpError(f"{what}: answer {k + 1} was at blur-rate {blur_rate!r} arcmin/deg "
                              f"where the procedure chooses {expected!r}: the log is not this "
                              "protocol's (changed grid, procedure or seed?)")
        procedure.update(blur_rate, bool(correct))
    return procedure


__all__ = ["ConstantStimuli", "Procedure", "QuestPlus", "QuestPlusArrays", "geometric_grid",
           "interleaved_methods", "rebuild"]
