"""Validation analysis (paper section 6.1) and the sampling-rate estimate (section 6.3) on a
hand-computed data set, checked against scipy on the same numbers."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy import stats

from fovexp import FovexpError
from fovexp.analysis.validation import validate

CONTRAST = {("P1", "s1"): 0.30, ("P1", "s2"): 0.40, ("P2", "s1"): 0.32, ("P2", "s2"): 0.38,
            ("P3", "s1"): 0.28, ("P3", "s2"): 0.44}
OURS = {("P1", "s1"): 0.40, ("P1", "s2"): 0.45, ("P2", "s1"): 0.36, ("P2", "s2"): 0.50,
        ("P3", "s1"): 0.38, ("P3", "s2"): 0.47}


def frame(contrast: dict = CONTRAST, ours: dict = OURS, reps: int = 1) -> pd.DataFrame:
    rows = []
    for method, values in (("contrast", contrast), ("ours", ours)):
        for (p, s), v in values.items():
            for r in range(reps):
                # repetitions spread +-0.01 around the value: their mean is the value
                v_r = v + (0.01 * (-1) ** r if reps > 1 else 0.0)
                rows.append({"participant": p, "image": s, "method": method, "final_value": v_r,
                             "blur_rate": v_r, "adjusted_parameter": "blur_rate"})
    return pd.DataFrame(rows)


def test_scene_summary_by_hand() -> None:
    res = validate(frame(reps=2))
    s = res.summary.set_index(["image", "method"])
    assert s.loc[("s1", "contrast"), "mean"] == pytest.approx(0.30)
    assert s.loc[("s1", "contrast"), "sem"] == pytest.approx(0.02 / np.sqrt(3))  # sd 0.02
    assert s.loc[("s1", "ours"), "mean"] == pytest.approx(0.38)
    assert (s.loc[("s1", "ours"), "n"], s.loc[("s1", "ours"), "n_trials"]) == (3, 6)


def test_paired_tests_by_hand_and_scipy() -> None:
    res = validate(frame())
    t = res.tests.set_index("scope")
    # scene s1: d = 0.10, 0.04, 0.10 -> mean 0.08, sd sqrt(0.0024 / 2), se 0.02, t = 4, df = 2
    s1 = t.loc["s1"]
    assert (s1["n"], s1["df"]) == (3, 2)
    assert s1["t"] == pytest.approx(4.0)
    assert s1["d_z"] == pytest.approx(0.08 / np.sqrt(0.0012))
    assert s1["p"] == pytest.approx(2 * stats.t.sf(4.0, 2))
    assert s1["p"] == pytest.approx(1 - 4.0 / np.sqrt(4.0**2 + 2))  # t(2): p = 1 - t/sqrt(t^2+2)
    assert s1["ci_low"] == pytest.approx(0.08 - stats.t.ppf(0.975, 2) * 0.02)
    # all scenes: six participant x scene pairs
    keys = sorted(CONTRAST)
    ref = stats.ttest_rel([OURS[k] for k in keys], [CONTRAST[k] for k in keys])
    all_ = t.loc["all scenes"]
    assert (all_["n"], all_["df"]) == (6, 5)
    assert all_["t"] == pytest.approx(ref.statistic) and all_["p"] == pytest.approx(ref.pvalue)
    assert all_["mean_diff"] == pytest.approx(0.44 / 6)
    # participant means: P1 0.075, P2 0.08, P3 0.065
    pm = t.loc["participant means"]
    ref = stats.ttest_1samp([0.075, 0.08, 0.065], 0.0)
    assert pm["n"] == 3 and pm["t"] == pytest.approx(ref.statistic)


def test_sampling_rate_reduction_by_hand() -> None:
    res = validate(frame())
    s = res.sampling.set_index("scope")
    # section 6.3: SR_ours / SR_contrast = blur_rate_contrast / blur_rate_ours
    assert s.loc["s1", "sr_ratio"] == pytest.approx(0.30 / 0.38)
    assert s.loc["s1", "reduction_pct"] == pytest.approx(100 * (1 - 0.30 / 0.38))
    assert s.loc["all scenes", "sr_ratio"] == pytest.approx(2.12 / 2.56)


def test_missing_method_cells() -> None:
    ours = dict(OURS)
    del ours[("P3", "s2")]
    res = validate(frame(ours=ours))
    assert res.tests.set_index("scope").loc["all scenes", "n"] == 5
    assert any("1 participant x scene" in n for n in res.notes)
    only = validate(frame(ours={}))
    assert only.tests.empty and only.sampling.empty and "not both present" in only.notes[0]
    with pytest.raises(FovexpError, match="no trials adjusting blur_rate"):
        validate(frame().assign(adjusted_parameter="f_e"))


def test_scenes_come_out_sorted_whatever_the_trials_order() -> None:
    rows = frame()
    res = validate(rows.iloc[::-1].reset_index(drop=True))  # s2 before s1
    assert res.tests["scope"].tolist() == ["all scenes", "participant means", "s1", "s2"]
    assert res.sampling["scope"].tolist() == ["all scenes", "s1", "s2"]


def test_scenes_come_out_sorted_when_the_first_participant_lacks_one() -> None:
    """The per-scene tests in scene order also when the first participant's first scene has
    no pair (P1 lacks ours on s1): the pairs then name s2 before s1."""
    ours = dict(OURS)
    del ours[("P1", "s1")]
    res = validate(frame(ours=ours))
    assert res.tests["scope"].tolist() == ["all scenes", "participant means", "s1", "s2"]
    assert res.tests.set_index("scope").loc["s1", "n"] == 2
