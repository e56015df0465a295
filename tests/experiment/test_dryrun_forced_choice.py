"""The forced-choice task (``task: 2afc``, issue 30) through the real runner: a dry run of the
shipped validation-2afc (a copy with a 0.3 s presentation, 1 practice and 9 main trials, the
CLI's 480x270 window) killed with SIGKILL after a few trials, then ``--resume``d: no trial lost
or repeated, every row's side, answer and blur-rate as the plan and the procedures say, and the
procedures rebuilt from the logged answers choose exactly what the run without the kill chose
(every logged blur-rate is QUEST+'s choice given the answers before it, the first resumed
trial's included)."""

from __future__ import annotations

import signal
from pathlib import Path

import pytest
import yaml

from fovexp.experiment.protocol.forced_choice import degraded_side
from fovexp.experiment.protocol.spec import load_protocol
from fovexp.experiment.records.logs import TRIAL_HEADERS, read_trials
from fovexp.experiment.tasks.forced_choice import make_procedure
from fovexp.experiment.tasks.procedures import rebuild

from experiment_helpers import (  # noqa: F401
    make_workspace,
    popen_cli,
    run_cli,
    wait_for_trials,
    xvfb_display,
)

pytestmark = [pytest.mark.gui, pytest.mark.slow]

N_MAIN, N_PRACTICE = 9, 1


@pytest.fixture
def ws(tmp_path: Path, xvfb_display) -> Path:  # noqa: F811
    ws = make_workspace(tmp_path / "ws")
    path = ws / "protocols" / "validation-2afc.yaml"
    data = yaml.safe_load(path.read_text())
    data["forced_choice"]["presentation_s"] = 0.3
    path.write_text(yaml.safe_dump(data))
    return ws


def test_killed_forced_choice_session_resumes_where_its_procedures_were(ws: Path) -> None:
    pytest.importorskip("questplus", reason="QUEST+ comes with the [experiment] extra")
    args = ["run", "protocols/validation-2afc.yaml", "--participant", "K01", "--dry-run",
            "--practice", str(N_PRACTICE), "--limit-trials", str(N_MAIN), "--sim-speed", "12"]
    folder = ws / "results" / "validation-2afc" / "K01"
    proc = popen_cli(args, ws)
    try:
        wait_for_trials(proc, folder / "trials.csv", 4, timeout_s=240)
        assert proc.poll() is None, proc.communicate()[1][-2000:]
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    before, _ = read_trials(folder / "trials.csv")
    assert 4 <= len(before) < N_MAIN + N_PRACTICE
    r = run_cli([*args, "--resume"], ws, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]

    header = (folder / "trials.csv").read_text().splitlines()[0].split(",")
    assert tuple(header) == TRIAL_HEADERS[1]
    rows, _ = read_trials(folder / "trials.csv")
    assert [row["trial_index"] for row in rows] == list(range(N_MAIN + N_PRACTICE))
    assert rows[: len(before)] == before  # nothing logged was rewritten
    lp = load_protocol(ws / "protocols" / "validation-2afc.yaml", results_root=ws / "results")
    fc = lp.spec.forced_choice
    seed, plan = lp.plan("K01", N_MAIN, N_PRACTICE)
    assert {row["seed"] for row in rows} == {seed}
    for row in rows:
        trial = plan[row["trial_index"]]
        assert (row["method"], row["image"], row["practice"]) == (trial.method, trial.image,
                                                                  trial.practice)
        assert row["degraded_side"] == degraded_side(seed, trial.index)
        assert row["answer"] in ("left", "right")
        assert row["correct"] == (row["answer"] == row["degraded_side"])
        assert row["blur_rate"] == row["final_value"] == fc.grid_values[row["grid_index"]]
        assert row["presentation_s"] == 0.3 and row["response_time_s"] > 0
    assert all(row["blur_rate"] == fc.grid.high for row in rows if row["practice"])
    main = [row for row in rows if not row["practice"]]
    # Every logged blur-rate is the procedure's choice given the answers before it (rebuild
    # refuses any other), so the resumed run went on exactly as the run without the kill.
    for k, method in enumerate(lp.spec.methods):
        answers = [(row["blur_rate"], row["correct"]) for row in main if row["method"] == method]
        rebuild(make_procedure(fc, k, seed), answers)
    first = rows[len(before)]
    if not first["practice"]:
        k = list(lp.spec.methods).index(first["method"])
        earlier = [(row["blur_rate"], row["correct"]) for row in before
                   if row["method"] == first["method"] and not row["practice"]]
        assert rebuild(make_procedure(fc, k, seed), earlier).next_blur_rate() == (
            first["blur_rate"])
