"""The rows a session writes for a trial (:mod:`fovexp.experiment.records.rows`), without a window:
the trial row logs what was on screen, the gaze rows carry the trial and attempt only within a
trial, the blanking rows only closed episodes."""

from __future__ import annotations

import pytest

from fovexp import PAPER_TABLE2, load_display
from fovexp.experiment.protocol.spec import load_protocol
from fovexp.experiment.records.logs import GAZE_COLUMNS, TRIAL_COLUMNS
from fovexp.experiment.records.rows import blanking_rows, gaze_items, gaze_row, trial_row
from fovexp.experiment.tasks.trial import Episode, TrialState, ValueAdjuster, Wheel
from fovexp.experiment.trackers.gaze import FixationGeometry, GazeSample

from experiment_helpers import REPO


def test_trial_row_logs_the_value_on_screen() -> None:
    """``final_value`` is the value of the render shown (``shown_value``), not the one the wheel
    asked for last; the parameters are those of the shown value (Table 2 at that blur-rate)."""
    lp = load_protocol(REPO / "protocols" / "validation.yaml")
    _, trials = lp.plan("P01", limit=2, practice=0)
    trial = trials[0]
    adj = lp.spec.adjust
    st = TrialState(ValueAdjuster(adj.range[0], adj.range[1], adj.step, adj.fine_step,
                                  trial.start_value), 120.0)
    st.flip(10.0, False, "")
    st.handle([Wheel(20)])  # asks for 0.4 ...
    st.show(0.3)  # ... but the render of 0.3 is on screen
    st.flip(10.5, True, "outside")
    st.flip(11.0, False, "")
    st.confirm(11.25)
    st.finish(11.3)
    row = trial_row(lp, trial, st, participant="P01", session_id="S", seed=5,
                    tracker="simulated")
    assert set(row) == set(TRIAL_COLUMNS)
    assert st.value == pytest.approx(0.4)
    assert row["final_value"] == row["blur_rate"] == 0.3 and row["start_value"] == 0.0
    f_e, s_k, s_f = PAPER_TABLE2.at(0.3)
    assert row["f_e"] == pytest.approx(f_e)
    if trial.method == "ours":
        assert (row["s_k"], row["s_f"]) == (pytest.approx(s_k), pytest.approx(s_f))
    assert row["response_time_s"] == 1.25 and row["wheel_events"] == 20
    # black from 10.5 to 11.0 of 10.0 .. 11.3
    assert row["blanked_fraction"] == pytest.approx(0.5 / 1.3, abs=1e-5)
    assert (row["session"], row["seed"], row["tracker"]) == ("S", 5, "simulated")


def test_gaze_and_blanking_rows() -> None:
    fix = FixationGeometry(load_display("lg-oled55cx"))
    centre = GazeSample(1, 2, 0.5, 0.5, True, 0.5, 0.5, True)
    lost = GazeSample(3, 4, float("nan"), float("nan"), False, float("nan"), float("nan"),
                      False)
    assert gaze_items(None, [centre], attempt=2) == [(None, None, centre)]
    assert gaze_items(7, [centre, lost], 2) == [(7, 2, centre), (7, 2, lost)]
    row = gaze_row(fix, (7, 2, centre))
    assert len(row) == len(GAZE_COLUMNS) and row[:4] == (7, 2, 1, 2) and row[13] == 0.0
    assert gaze_row(fix, (None, None, lost))[13] is None  # no eccentricity without a position
    eps = [Episode(0.1234567, 0.2, 3, "outside"), Episode(0.5, None, 1, "lost")]
    assert blanking_rows(4, 1, eps) == [(4, 1, 0.123457, 0.2, 3, "outside")]
