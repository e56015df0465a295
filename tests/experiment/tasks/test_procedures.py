"""The forced-choice task's procedures (:mod:`fovexp.experiment.tasks.procedures`), their
rebuild from logged answers, and the simulated observer
(:mod:`fovexp.experiment.tasks.simulated_observer`)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fovexp import FovexpError
from fovexp.experiment.tasks.procedures import (
    ConstantStimuli,
    QuestPlusArrays,
    geometric_grid,
    interleaved_methods,
    rebuild,
)
from fovexp.experiment.tasks.simulated_observer import SimulatedObserver
from fovexp.experiment.tasks.simulated_participant import SimTruth
from fovexp.results.psychometric import (
    log10_scale_for,
    log10_threshold_at,
    proportion_correct,
)

GRID = geometric_grid(0.05, 2.0, 25)
SLOPES = (1.0, 2.0, 3.0, 5.0)


def _run(proc, observer: SimulatedObserver, method: str, n: int) -> list[tuple[float, bool]]:
    log = []
    for _ in range(n):
        b = proc.next_blur_rate()
        correct = observer.answer(method, b, "left") == "left"
        proc.update(b, correct)
        log.append((b, correct))
    return log


def test_the_weibull_at_its_scale_is_80_3_percent_and_75_percent_converts_back() -> None:
    """questplus' "threshold" is the 80.3 %-correct point with a 0.02 lapse (CHECKED.md)."""
    assert float(proportion_correct(0.0, 0.0, 3.0, 0.02)) == pytest.approx(0.80342, abs=1e-5)
    t = log10_scale_for(math.log10(0.4), 0.75, 3.0, 0.02)
    assert float(proportion_correct(math.log10(0.4), t, 3.0, 0.02)) == pytest.approx(0.75)
    assert float(log10_threshold_at(0.75, t, 3.0, 0.02)) == pytest.approx(math.log10(0.4))
    assert math.isnan(float(log10_threshold_at(0.99, 0.0, 3.0, 0.02)))  # above 1 - lapse
    with pytest.raises(ValueError, match="between the guess rate"):
        log10_scale_for(0.0, 0.4, 3.0, 0.02)


def test_the_grid_is_geometric_and_refuses_nonsense() -> None:
    assert GRID[0] == 0.05 and GRID[-1] == 2.0 and len(GRID) == 25
    ratios = np.diff(np.log(GRID))
    assert np.allclose(ratios, ratios[0], rtol=1e-3)
    with pytest.raises(ValueError, match="0 < low < high"):
        geometric_grid(0.0, 1.0, 5)


def test_the_numpy_twin_chooses_what_questplus_chooses() -> None:
    """QuestPlusArrays (simulations) and QuestPlus (the task, on questplus) agree trial by trial,
    with a fixed lapse and with the lapse a parameter."""
    pytest.importorskip("questplus", reason="questplus comes with the [experiment] extra")
    from fovexp.experiment.tasks.procedures import QuestPlus

    for lapses in ((0.02,), (0.0, 0.04)):
        ref, twin = QuestPlus(GRID, SLOPES, lapses), QuestPlusArrays(GRID, SLOPES, lapses)
        obs = SimulatedObserver(SimTruth(), seed=5)
        for _ in range(15):
            b = ref.next_blur_rate()
            assert twin.next_blur_rate() == b
            correct = obs.answer("contrast", b, "right") == "right"
            ref.update(b, correct)
            twin.update(b, correct)
        assert 0.05 <= ref.estimate()["threshold_arcmin_per_deg"] <= 2.0


def test_questplus_rebuilt_from_its_log_chooses_the_same_next_blur_rate() -> None:
    """The resume rule: a fresh procedure fed the logged answers is where the old one was."""
    pytest.importorskip("questplus", reason="questplus comes with the [experiment] extra")
    from fovexp.experiment.tasks.procedures import QuestPlus

    proc = QuestPlus(GRID, SLOPES, (0.02,))
    log = _run(proc, SimulatedObserver(SimTruth(), seed=2), "ours", 12)
    again = rebuild(QuestPlus(GRID, SLOPES, (0.02,)), log)
    assert again.next_blur_rate() == proc.next_blur_rate()
    assert again.n_trials == 12


def test_rebuild_refuses_a_log_the_procedure_would_not_have_made() -> None:
    proc = QuestPlusArrays(GRID, SLOPES, (0.02,))
    log = _run(proc, SimulatedObserver(SimTruth(), seed=2), "ours", 4)
    wrong = [log[0], (GRID[0] if log[1][0] != GRID[0] else GRID[1], log[1][1])]
    with pytest.raises(FovexpError, match="answer 2 was at blur-rate .* the log is not this"):
        rebuild(QuestPlusArrays(GRID, SLOPES, (0.02,)), wrong)
    with pytest.raises(FovexpError, match="not on the procedure's grid"):
        QuestPlusArrays(GRID, SLOPES, (0.02,)).update(0.123456789, True)


def test_questplus_converges_near_the_observers_threshold() -> None:
    truth = SimTruth(validation_blur_rate={"ours": 0.6})
    proc = QuestPlusArrays(GRID, SLOPES, (0.02,))
    log = _run(proc, SimulatedObserver(truth, seed=11), "ours", 80)
    late = [b for b, _ in log[40:]]
    # QUEST+ places trials around the steep part: within a factor 2 of the 75 % point
    assert 0.3 < float(np.median(late)) < 1.2


def test_constant_stimuli_shows_each_level_equally_and_rebuilds() -> None:
    levels = (0.1, 0.2, 0.4, 0.8)
    proc = ConstantStimuli(levels, 12, seed=3)
    log = _run(proc, SimulatedObserver(SimTruth(), seed=1), "contrast", 12)
    assert sorted(b for b, _ in log) == sorted(levels * 3)
    again = rebuild(ConstantStimuli(levels, 12, seed=3), log[:7])
    assert again.next_blur_rate() == log[7][0]


def test_methods_are_interleaved_each_equally_often() -> None:
    order = interleaved_methods(["foveated", "contrast", "ours"], 10, seed=4)
    assert len(order) == 30 and {m: order.count(m) for m in set(order)} == {
        "foveated": 10, "contrast": 10, "ours": 10}
    assert order != sorted(order)
    assert order == interleaved_methods(["foveated", "contrast", "ours"], 10, seed=4)


def test_the_observer_answers_from_its_function() -> None:
    """75 % correct at the truth's blur-rate, chance without foveation, near 1 - lapse far
    above."""
    truth = SimTruth(validation_blur_rate={"ours": 0.5}, forced_choice_lapse={"ours": 0.04})
    obs = SimulatedObserver(truth, seed=9)
    assert obs.p_correct("ours", 0.5) == pytest.approx(0.75)
    assert obs.p_correct("ours", 0.0) == 0.5
    assert obs.p_correct("ours", 5.0) == pytest.approx(0.96, abs=1e-3)
    n = 4000
    hits = sum(obs.answer("ours", 0.5, "right") == "right" for _ in range(n))
    assert abs(hits / n - 0.75) < 4 * math.sqrt(0.75 * 0.25 / n)
    assert 0.3 <= obs.response_time_s() <= 0.9
