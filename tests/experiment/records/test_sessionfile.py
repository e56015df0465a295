"""The session file (:mod:`fovexp.experiment.records.sessionfile`), without a window: whole, atomic
rewrites; events written at once before the writer thread exists and by it afterwards; the
record of a new session and of each run."""

from __future__ import annotations

import json
import threading
import time
from pathlib import Path

from fovexp.experiment.protocol.spec import load_protocol
from fovexp.experiment.records.sessionfile import (
    SessionFile,
    new_record,
    participant_entry,
    run_entry,
    versions,
)

from experiment_helpers import REPO


def read(path: Path) -> dict:
    return json.loads(path.read_text())


def test_update_and_event_before_and_after_the_writer(tmp_path: Path) -> None:
    f = SessionFile(tmp_path / "session-x.json")
    f.update(state="running", runs=[{}])
    assert read(f.path) == {"state": "running", "runs": [{}]}
    f.event("paused", trial_index=3)  # no writer yet: written at once
    assert read(f.path)["events"][0]["event"] == "paused"
    f.set_in_run("display_thread", {"a": 1}, write=False)
    assert read(f.path)["runs"] == [{}]  # with the next write
    f.start_writer()
    writer_threads = []
    f._writer._snapshot = (lambda snap: lambda: (
        writer_threads.append(threading.current_thread().name), snap())[1])(f._writer._snapshot)
    f.event("rate_deviation", hz=590)
    deadline = time.monotonic() + 5
    while len(read(f.path)["events"]) < 2 and time.monotonic() < deadline:
        time.sleep(0.01)
    assert [e["event"] for e in read(f.path)["events"]] == ["paused", "rate_deviation"]
    assert "fovexp-session-file" in writer_threads  # the event was written by its thread
    assert read(f.path)["runs"] == [{"display_thread": {"a": 1}}]
    f.update(state="completed")  # on the calling thread, after the writer's
    f.stop_writer()
    f.stop_writer()
    assert read(f.path)["state"] == "completed"


def test_new_record_and_run_entries(tmp_path: Path) -> None:
    from fovexp import load_display

    lp = load_protocol(REPO / "protocols" / "validation.yaml")
    rec = new_record(session_id="20260101-000000", participant="P01", protocol=lp,
                     display=load_display(lp.display_name), seed=7, limit_trials=None,
                     practice_trials=2, n_trials=22, started="t0")
    assert rec["protocol_sha256"] == lp.sha256 and rec["protocol"] == lp.text
    assert rec["display"]["name"] == "lg-oled55cx" and rec["plan"]["n_trials"] == 22
    assert (rec["state"], rec["completed"], rec["runs"], rec["events"]) == (
        "running", False, [], [])
    json.dumps(rec)  # all of it serialisable
    run = run_entry(dry_run=True, tracker="simulated", remaining_trials=3, screen=1)
    assert run["pid"] > 0 and run["screen"] == 1 and run["started"]
    assert participant_entry({"age": 30}, None, False, "t") == {"age": 30, "time": "t"}
    assert participant_entry(None, None, True, "t") == {"skipped": "dry run"}
    assert participant_entry(None, "--no-form", False, "t") == {"skipped": "--no-form"}
    assert participant_entry(None, None, False, "t") == {"skipped": "not asked"}
    v = versions()
    assert {"python", "fovexp", "numpy"} <= set(v)
