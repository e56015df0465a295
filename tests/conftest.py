import os
from collections.abc import Iterator
from pathlib import Path

import pytest

from engine_helpers import sponza  # noqa: F401  (fixture)

# Progress bars (fovexp.progress) off in the tests and the commands they start, whose stderr
# many tests read line for line; tests/test_progress.py and the compile test turn them on.
os.environ.setdefault("FOVEXP_PROGRESS", "0")


@pytest.fixture(scope="session", autouse=True)
def dry_run_scenes(tmp_path_factory) -> Iterator[Path]:
    """The generated scenes at the dry run's resolution (480x270, pinned; about a second), in
    a stimulus folder of this test session's own, named by $FOVEXP_STIMULI for every test and
    every command a test starts: tests never read or write the clone's stimuli/ folder.
    ``$FOVEXP_TEST_STIMULI`` names a folder made beforehand instead (the mutation runs')."""
    from fovexp.stimuli.folder import DRY_RUN_SIZE, ENV_VAR, StimulusSet, generate_scenes

    prepared = os.environ.get("FOVEXP_TEST_STIMULI")
    if prepared:  # benchmarks/mutate.py: made once for its thousands of short test runs
        folder = Path(prepared)
    else:
        folder = tmp_path_factory.mktemp("stimuli")
        generate_scenes(StimulusSet(folder), DRY_RUN_SIZE)
    old = os.environ.get(ENV_VAR)
    os.environ[ENV_VAR] = str(folder)
    yield folder
    if old is None:
        os.environ.pop(ENV_VAR, None)
    else:
        os.environ[ENV_VAR] = old


# The dry-run study (the calibration chain, both validations), made once per test session and
# read by the recovery tests, the impulse-count comparison and the BIDS export's tests (each
# imports experiment_helpers' xvfb_display, which the study's fixtures ask for).
from dry_run_study import dry_run_calibration, dry_run_validations  # noqa: E402, F401, I001
