"""The forced-choice protocol (``task: 2afc``, issue 30): the shipped validation-2afc, its plan,
and bad blocks refused in one line naming the key; a trials.csv of one task is not appended to
by the other."""

from __future__ import annotations

from pathlib import Path

import pytest

from fovexp import FovexpError
from fovexp.experiment.protocol.forced_choice import degraded_side
from fovexp.experiment.protocol.spec import load_protocol
from fovexp.experiment.records.logs import TRIAL_HEADERS, TrialLog

from experiment_helpers import REPO, edit_protocol, make_workspace

SHIPPED = REPO / "protocols" / "validation-2afc.yaml"


def test_the_shipped_protocol_states_the_validation_by_forced_choice() -> None:
    lp = load_protocol(SHIPPED)
    s = lp.spec
    assert s.task == "2afc" and s.methods == ["foveated", "contrast", "ours"]
    validation = load_protocol(REPO / "protocols" / "validation.yaml").spec
    assert s.images == validation.images and s.parameters == validation.parameters
    fc = s.forced_choice
    assert fc is not None and fc.procedure == "questplus" and fc.trials_per_method == 100
    assert fc.grid_values[0] == 0.05 and fc.grid_values[-1] == 2.0 and len(fc.grid_values) == 25
    # the derived adjust block: the shown blur-rate over the grid
    assert s.adjust.parameter == "blur_rate" and s.adjust.range == (0.0, 2.0)
    seed, trials = lp.plan("P01")
    practice = [t for t in trials if t.practice]
    main = [t for t in trials if not t.practice]
    assert len(practice) == 4 and {t.method for t in practice} == {"foveated"}
    assert len(main) == 300 and all(t.blur_rate is None for t in trials)
    assert {m: sum(t.method == m for t in main) for m in s.methods} == dict.fromkeys(
        s.methods, 100)
    assert [t.index for t in trials] == list(range(304))
    # interleaved: no method's trials bunch at one end
    assert {t.method for t in main[:30]} == set(s.methods)
    assert lp.plan("P01") == (seed, trials)  # a resumed session's plan is the same
    sides = [degraded_side(seed, t.index) for t in main]
    assert 120 < sides.count("left") < 180
    _, short = lp.plan("P01", limit=6, practice=0)  # a pilot: the methods balanced
    assert sorted(t.method for t in short) == sorted(s.methods * 2)


@pytest.mark.parametrize(("change", "message"), [
    ({"forced_choice": None}, "forced_choice: required with task: 2afc"),
    ({"task": "adjust"}, "forced_choice: required with task: 2afc, and only with it"),
    ({"adjust": {"parameter": "f_e", "range": [0, 0.4], "step": 0.02, "fine_step": 0.005}},
     "leave adjust out"),
    ({"forced_choice.grid": {"low": 0.5, "high": 0.1, "n": 5}}, "low 0.5 must be below high"),
    ({"forced_choice.keys": ["left", "left"]}, "keys must differ"),
    ({"forced_choice.procedure": "staircase"}, "forced_choice.procedure"),
    ({"forced_choice.trials_per_method": 0}, "forced_choice.trials_per_method"),
])
def test_bad_forced_choice_blocks_are_refused_in_one_line(tmp_path: Path, change: dict,
                                                           message: str) -> None:
    path = edit_protocol(make_workspace(tmp_path / "ws"), SHIPPED.stem, **change)
    with pytest.raises(FovexpError, match=message) as err:
        load_protocol(path)
    assert str(path) in str(err.value) and "\n" not in str(err.value).strip()


def test_a_trials_csv_of_one_task_is_not_continued_by_the_other(tmp_path: Path) -> None:
    TrialLog(tmp_path / "trials.csv", TRIAL_HEADERS[0])
    with pytest.raises(FovexpError, match="written by another task"):
        TrialLog(tmp_path / "trials.csv", TRIAL_HEADERS[1])
