"""Issue 21: where there is no paired test (one participant; a scene one participant saw; pairs
that all differ by the same amount) the report says why in words and marks the statistics
``n/a``: never ``nan`` in the prose or the test table."""

from __future__ import annotations

import math
import re

import pandas as pd
import pytest

from fovexp.analysis.sections.validation import _validation_md, marked_tests
from fovexp.analysis.validation import TEST_STATISTICS, validate

NAN = re.compile(r"\bnan\b|\binf\b", re.IGNORECASE)


def frame(values: dict[tuple[str, str, str], float]) -> pd.DataFrame:
    """(participant, scene, method) -> selected blur-rate."""
    return pd.DataFrame([{"participant": p, "image": s, "method": m, "final_value": v,
                          "blur_rate": v, "adjusted_parameter": "blur_rate"}
                         for (p, s, m), v in values.items()])


def test_one_participant_says_why_and_shows_no_nan() -> None:
    res = validate(frame({("SIM01", s, m): v for s in ("s1", "s2", "s3")
                          for m, v in (("contrast", 0.30), ("ours", 0.42))}
                         | {("SIM01", "s2", "ours"): 0.50}), "lab")
    assert res.no_test is not None and "one participant (SIM01)" in res.no_test
    assert "at least two" in res.no_test
    # the means stay; no statistic of a single participant, even over three scenes
    t = res.tests.set_index("scope")
    assert t.loc["all scenes", "n"] == 3
    assert t.loc["all scenes", "mean_diff"] == pytest.approx((0.12 + 0.20 + 0.12) / 3)
    assert all(math.isnan(t.loc[s, c]) for s in t.index for c in TEST_STATISTICS)
    md = _validation_md(res, figures=False)
    assert res.no_test in md
    assert not NAN.search(md), NAN.findall(md)
    rows = [ln for ln in md.splitlines() if ln.startswith("| all scenes |")]
    assert rows and rows[0].count("n/a") == len(TEST_STATISTICS)
    assert "\nn/a: one participant: a paired test needs at least two.\n" in md


def test_rows_without_a_test_are_marked_and_explained() -> None:
    """Two participants: s1 seen by both (a test), s2 by one only (one pair), and s3 where
    both differ by exactly the same amount (no variance: t would be infinite)."""
    values = {("P1", "s1", "contrast"): 0.30, ("P1", "s1", "ours"): 0.40,
              ("P2", "s1", "contrast"): 0.32, ("P2", "s1", "ours"): 0.36,
              ("P1", "s2", "contrast"): 0.30, ("P1", "s2", "ours"): 0.35,
              ("P1", "s3", "contrast"): 0.20, ("P1", "s3", "ours"): 0.25,
              ("P2", "s3", "contrast"): 0.30, ("P2", "s3", "ours"): 0.35}
    res = validate(frame(values), "lab")
    assert res.no_test is None
    marked, why = marked_tests(res.tests)
    m = marked.set_index("scope")
    assert isinstance(m.loc["s1", "t"], float) and math.isfinite(m.loc["s1", "t"])
    assert m.loc["s2", "t"] == m.loc["s2", "p"] == m.loc["s2", "df"] == "n/a"
    assert m.loc["s3", "t"] == "n/a" and m.loc["s3", "sd_diff"] == pytest.approx(0.0)
    assert m.loc["s3", "ci_low"] == pytest.approx(0.05)  # finite: kept
    assert why == ["fewer than two pairs, and a paired test needs at least two",
                   "every pair differs by the same amount: no variance to test against"]
    md = _validation_md(res, figures=False)
    assert "All scenes, paired by participant x scene: t(4) = " in md
    assert not NAN.search(md), NAN.findall(md)


def test_no_variance_over_all_scenes_is_said_in_the_prose() -> None:
    values = {(p, "s1", m): v for p in ("P1", "P2")
              for m, v in (("contrast", 0.30 if p == "P1" else 0.20),
                           ("ours", 0.40 if p == "P1" else 0.30))}
    md = _validation_md(validate(frame(values), "lab"), figures=False)
    assert ("All scenes, paired by participant x scene: no test (every pair differs by the "
            "same amount: no variance to test against).") in md
    assert not NAN.search(md), NAN.findall(md)
