"""R13's default threshold from the latency budget (:mod:`fovexp.results.limits`): the main
sequence and a minimum-jerk profile give known exit-to-landing times, and the default is the
budget of the design saccade, rounded."""

from __future__ import annotations

import pytest

from fovexp.results.limits import (
    DESIGN_SACCADE_DEG,
    DISPLAY_LATENCY_MS,
    POST_SACCADIC_MS,
    SAMPLE_INTERVAL_MS,
    TrialLimits,
    exit_to_landing_ms,
    latency_budget_ms,
)


def test_exit_to_landing_follows_the_main_sequence() -> None:
    # a 2.5 deg saccade crosses 1.25 deg at half its amplitude: half way through its
    # 2.2 x 2.5 + 21 = 26.5 ms (the minimum-jerk profile is symmetric)
    assert exit_to_landing_ms(2.5) == pytest.approx(26.5 / 2, abs=1e-6)
    assert exit_to_landing_ms(1.0) == 0.0  # lands inside the window
    times = [exit_to_landing_ms(a) for a in (2, 5, 10, 20)]
    assert times == sorted(times)
    assert times == pytest.approx([11.0, 20.5, 31.4, 51.6], abs=0.05)
    # a wider window leaves less time
    assert exit_to_landing_ms(5, radius_deg=2.0) < exit_to_landing_ms(5)


def test_the_r13_default_is_the_budget_of_the_design_saccade() -> None:
    budget = latency_budget_ms()
    assert budget == pytest.approx(exit_to_landing_ms(DESIGN_SACCADE_DEG) + POST_SACCADIC_MS
                                   - SAMPLE_INTERVAL_MS - DISPLAY_LATENCY_MS)
    assert TrialLimits().max_latency_p95_ms == round(budget) == 20
    # a slower display leaves less for the computer
    assert latency_budget_ms(display_ms=15) == pytest.approx(budget - 10)
    assert "exceeds 20 ms" in TrialLimits().rules()["R13 latency"]
