"""Hypothesis profiles of the stress tests (issue 10, section 3).

``ci`` (the default): few examples per property, no deadline, derandomised, so that CI is
reproducible and the whole of tests/stress runs in well under two minutes on two cores.
``long``: 200 examples per property (about 3000 in all), random, for ``./dev stress``
(which records its result in benchmarks/STRESS.md). ``dev``: the ``ci`` counts, random.

The profile is chosen by ``--hypothesis-profile NAME`` (hypothesis's own option), else by
``$FOVEXP_HYPOTHESIS_PROFILE``, else ``long`` when the run selects ``-m stress_long``, else
``ci``. Every test under tests/stress is marked ``stress`` and ``stress_long``, so
``pytest tests/stress -m stress_long`` is the long mode and ``-m "not stress"`` leaves them out.
NumPy's RuntimeWarnings (overflow, division by zero, invalid values) fail a stress test: each
is a numerical defect, whatever the value that comes out.
"""

from __future__ import annotations

import os

import pytest
from hypothesis import HealthCheck, settings

PROFILE_ENV = "FOVEXP_HYPOTHESIS_PROFILE"
_COMMON = dict(
    deadline=None,  # a first call may compile a kernel; speed is measured by benchmarks
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    print_blob=True,
)
#: examples per property: ``ci`` and ``long`` (properties that cost more take a fraction,
#: :func:`examples`)
CI_EXAMPLES = 12
LONG_EXAMPLES = 200
settings.register_profile("ci", max_examples=CI_EXAMPLES, derandomize=True, database=None,
                          **_COMMON)
settings.register_profile("dev", max_examples=CI_EXAMPLES, **_COMMON)
settings.register_profile("long", max_examples=LONG_EXAMPLES, **_COMMON)


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "stress: a property test of tests/stress")
    config.addinivalue_line(
        "markers", "stress_long: selects the long hypothesis profile (pytest -m stress_long)")
    if config.getoption("hypothesis_profile", None):
        return  # hypothesis's own option has loaded it
    name = os.environ.get(PROFILE_ENV)
    if not name:
        name = "long" if "stress_long" in (config.option.markexpr or "") else "ci"
    settings.load_profile(name)


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    here = os.path.dirname(__file__)
    for item in items:
        if str(item.path).startswith(here + os.sep):
            item.add_marker(pytest.mark.stress)
            item.add_marker(pytest.mark.stress_long)
            # overflow, division by zero, invalid operations: a numerical defect to find
            item.add_marker(pytest.mark.filterwarnings("error::RuntimeWarning"))


def pytest_report_header(config: pytest.Config) -> str:
    s = settings.default
    return (f"stress: hypothesis profile {settings.get_current_profile_name()!r} "
            f"({s.max_examples} examples per property, derandomize={s.derandomize})")
