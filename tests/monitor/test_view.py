"""What ``fovexp monitor`` reads from a results folder (fovexp.monitor.view): running, stopped
and finished sessions; the trial on screen judged by the analysis' own rules; damaged files
shown as far as they go, with what was skipped named; session keys that cannot leave the
results folder."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest

from fovexp import FovexpError
from fovexp.monitor.view import ResultsView, parse_key
from fovexp.results.limits import R11, R12, R13, TrialLimits

from monitor_helpers import live, session_file, trial_row, trials_text, write_live_file

SID = "20261124-101010"


@pytest.fixture()
def root(tmp_path: Path) -> Path:
    r = tmp_path / "results"
    r.mkdir()
    return r


def _folder(root: Path, exp: str = "calibration-sk", pid: str = "P01") -> Path:
    return root / exp / pid


def test_a_running_session_and_its_trial_judged(root: Path) -> None:
    f = _folder(root)
    session_file(f, SID)
    write_live_file(f, live(SID, blanked=0.62, dropped=3, frames=300, p95=75.0))
    view = ResultsView(root)
    (s,) = view.sessions()
    assert (s["status"], s["state"], s["position"], s["total"]) == ("running", "trial", 3, 10)
    v = view.session(s["key"])
    t = v["trial"]
    # R11 and R13 broken, R12 not (1 % of the frames dropped)
    assert t["flagged"] == [R11, R13]
    assert t["rules"][R11] == {"value": 0.62, "limit": 0.5, "unit": "fraction",
                               "exceeded": True}
    assert t["rules"][R12]["value"] == pytest.approx(0.01) and not t["rules"][R12]["exceeded"]
    assert v["rules_apply"] is False and v["dry_run"] is True  # a dry run's are not applied
    assert v["gaze"]["x_deg"] == [0.1, None, 0.3] and v["eta_s"] == 95.0
    assert v["tracker"]["quality"]["accuracy_deg"] == 0.4 and v["skipped"] == []
    # the analysis' thresholds, as fovexp analyze --max-... would set them
    strict = ResultsView(root, limits=TrialLimits(max_dropped_fraction=0.005))
    assert strict.session(s["key"])["trial"]["flagged"] == [R11, R12, R13]


def test_a_participants_session_is_judged_for_real(root: Path) -> None:
    f = _folder(root, pid="P02")
    session_file(f, SID, dry_run=False)
    write_live_file(f, live(SID, dry_run=False))
    v = ResultsView(root).session(f"calibration-sk/P02/{SID}")
    assert v["rules_apply"] is True and v["trial"]["flagged"] == []


def test_a_runner_that_stops_writing_is_shown_as_stopped(root: Path) -> None:
    f = _folder(root)
    session_file(f, SID)
    write_live_file(f, live(SID, seq=1))
    view = ResultsView(root, stale_after_s=0.3)
    key = f"calibration-sk/P01/{SID}"
    assert view.session(key)["status"] == "running"
    time.sleep(0.4)
    v = view.session(key)
    assert v["status"] == "stopped" and "no update" in v["why"]
    assert v["trial"]["position"] == 3  # the last state it wrote is still shown
    write_live_file(f, live(SID, seq=2))  # it writes again
    assert view.session(key)["status"] == "running"


def test_an_old_status_file_seen_first_is_stopped_at_once(root: Path) -> None:
    f = _folder(root)
    session_file(f, SID)
    write_live_file(f, live(SID, updated=time.time() - 3600))
    assert ResultsView(root).sessions()[0]["status"] == "stopped"


def test_a_runner_killed_on_this_machine_is_stopped_at_once(root: Path) -> None:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()  # a pid that no longer exists
    f = _folder(root)
    session_file(f, SID)
    write_live_file(f, live(SID, pid=proc.pid))
    v = ResultsView(root).session(f"calibration-sk/P01/{SID}")
    assert v["status"] == "stopped" and "process is gone" in v["why"]
    # on another machine (a shared results folder) the pid means nothing: not judged by it
    write_live_file(f, live(SID, pid=proc.pid, host="another-machine"))
    assert ResultsView(root).session(f"calibration-sk/P01/{SID}")["status"] == "running"


def test_finished_sessions_and_the_report_link(root: Path, tmp_path: Path) -> None:
    for i, (sid, ended) in enumerate([("20261124-090000", "2026-11-24T09:30:00+00:00"),
                                      ("20261124-100000", "2026-11-24T10:30:00+00:00")]):
        f = _folder(root, pid=f"P0{i + 1}")
        session_file(f, sid, state="completed", ended=ended, n_completed=10)
        write_live_file(f, live(sid, state="completed", trial=None))
    f = _folder(root, exp="validation", pid="P09")
    session_file(f, SID)  # running, but no status file (killed before its first write)
    report = tmp_path / "report"
    report.mkdir()
    (report / "report.html").write_text("<html></html>")
    view = ResultsView(root, report=report)
    s = view.sessions()
    assert [(x["participant"], x["status"]) for x in s] == [
        ("P09", "stopped"), ("P02", "finished"), ("P01", "finished")]
    assert "no live status file" in s[0]["why"]
    v = view.session(s[1]["key"])
    assert v["report"]["url"] == "/report/report.html"
    # the report was written now, after these sessions ended
    assert v["report"]["note"] is None
    session_file(_folder(root, pid="P02"), "20261124-100000", state="completed",
                 ended="2099-01-01T00:00:00+00:00")
    time.sleep(1.1)  # the session file's cache and the scan
    assert "older than this session" in view.session(s[1]["key"])["report"]["note"]
    assert ResultsView(root).session(s[1]["key"])["report"] is None  # no --report


def test_damaged_files_show_what_they_can_and_say_what_was_skipped(root: Path) -> None:
    f = _folder(root)
    session_file(f, SID)
    rows = [trial_row(SID, i, blanked_fraction=0.7 if i == 2 else 0.01) for i in range(4)]
    text = trials_text(rows).splitlines(keepends=True)
    text[2] = text[2].replace(",ours,", ",nonsense,")  # a corrupt row in the middle
    (f / "trials.csv").write_text("".join(text) + text[-1][:30])  # and a torn last one
    data = live(SID)
    data["gaze"] = {"t": [0, 1], "x_deg": [0.1], "y_deg": [0.1]}  # arrays of unequal length
    data["attempts"] = [data["attempts"][0], "junk", {"frames": 3}]
    write_live_file(f, data)
    v = ResultsView(root).session(f"calibration-sk/P01/{SID}")
    assert [t["index"] for t in v["trials"]] == [0, 2, 3]
    assert v["trials"][1]["flagged"] == [R11]
    skipped = "\n".join(v["skipped"])
    assert "trials.csv line 3: column method" in skipped
    assert "trials.csv line 6: no final newline" in skipped
    assert "gaze arrays" in skipped and "attempt 1: not an object" in skipped
    assert "attempt 2: no trial index" in skipped
    assert v["gaze"] is None and len(v["attempts"]) == 1 and v["trial"]["position"] == 3
    # a status file that is not one: named, the session still listed from its session file
    (f / f"live-{SID}.json").write_text('{"format": "fovexp-live/1", "st')
    v = ResultsView(root).session(f"calibration-sk/P01/{SID}")
    assert any(f"live-{SID}.json: not JSON" in x for x in v["skipped"])
    assert v["status"] == "stopped" and v["trial"] is None and len(v["trials"]) == 3
    (f / f"session-{SID}.json").write_bytes(b"\x00\x01")
    v = ResultsView(root).session(f"calibration-sk/P01/{SID}")
    assert any(f"session-{SID}.json: not JSON" in x for x in v["skipped"])


@pytest.mark.parametrize("key", [
    "../x/y", "a/b", "a/../b/c", "/etc/P01/x", "exp/CON/s", "exp/P01/s/extra", "exp/P01/..",
    "exp/P 01/s", "..%2f/P01/s", "", "exp//s", ".hidden/P01/s",
])
def test_keys_that_are_not_a_session_are_refused(key: str) -> None:
    assert parse_key(key) is None


def test_a_session_must_lie_inside_the_results_folder(root: Path, tmp_path: Path) -> None:
    outside = tmp_path / "elsewhere" / "P01"
    session_file(outside, SID)
    write_live_file(outside, live(SID))
    (root / "calibration-sk").symlink_to(tmp_path / "elsewhere", target_is_directory=True)
    view = ResultsView(root)
    key = f"calibration-sk/P01/{SID}"
    assert key in view.refs()  # found by the scan through the link ...
    assert view.resolve(key) is None and view.session(key) is None  # ... and refused
    assert view.resolve(f"calibration-sk/P01/{SID[:-1]}9") is None  # unknown session
    with pytest.raises(FovexpError, match="no such results folder"):
        ResultsView(tmp_path / "nothing")


def test_the_snapshot_views_the_latest_running_session(root: Path) -> None:
    for pid, age in (("P01", 2.0), ("P02", 0.0)):
        f = _folder(root, pid=pid)
        session_file(f, SID)
        write_live_file(f, live(SID, updated=time.time() - age))
    snap = ResultsView(root).snapshot(None)
    assert snap["view"]["participant"] == "P02" and len(snap["sessions"]) == 2
    assert ResultsView(root).snapshot("nonsense")["view"]["participant"] == "P02"
    assert ResultsView(root).snapshot(f"calibration-sk/P01/{SID}")["view"]["participant"] \
        == "P01"


# -- a session that has ended (issue 32) ----------------------------------------------------------
@pytest.mark.parametrize(("state", "how"), [
    ("completed", "completed"), ("aborted", "quit by the operator"),
    ("interrupted", "interrupted (Ctrl-C or a signal)"),
    ("failed", "crashed (an error; the session file names it)"),
])
def test_an_ended_session_says_how_and_when_and_shows_no_live_rates(root: Path, state: str,
                                                                    how: str) -> None:
    """The last write of a run that ended, from a runner that wrote no ``ended`` yet (a file
    kept from before): its final state and ``since`` say how and when; the rates it wrote
    last (the issue's "671 samples in the last second") and the ETA are not passed on."""
    f = _folder(root)
    ended = time.time() - 30
    session_file(f, SID, state=state, ended="2026-11-24T10:30:00+00:00")
    data = live(SID, state=state, trial=None, since=ended)
    data["gaze"]["samples_last_s"] = 671
    write_live_file(f, data)
    view = ResultsView(root)
    v = view.session(f"calibration-sk/P01/{SID}")
    assert v["status"] == "finished" and v["trial"] is None
    assert v["end"] == {"state": state, "how": how, "time": pytest.approx(ended, abs=1e-3),
                        "at": time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(ended))}
    assert v["gaze"]["samples_last_s"] is None and v["gaze"]["newest_age_s"] is None
    assert v["gaze"]["x_deg"] == [0.1, None, 0.3]  # the last seconds are still shown
    assert v["eta_s"] is None
    (s,) = view.sessions()
    assert s["end"]["how"] == how


def test_the_runners_last_write_says_the_run_ended(root: Path) -> None:
    """The publisher's own last write (``stop``): ``ended``, the final state, no samples per
    second, no ETA; the view says how and when from it."""
    from fovexp import load_display
    from fovexp.experiment.records.live import LivePublisher
    from fovexp.experiment.trackers.gaze import FixationGeometry, GazeSample

    f = _folder(root)
    session_file(f, SID, state="aborted")
    pub = LivePublisher(f, SID, {"participant": "P01"},
                        FixationGeometry(load_display("lg-oled55cx")))
    pub.gaze([(0, 0, GazeSample(i * 1666, i * 1666, 0.5, 0.5, True, 0.5, 0.5, True))
              for i in range(600)])
    pub.set_eta(120.0)
    running = pub.snapshot()
    assert running["ended"] is None and running["gaze"]["samples_last_s"] == 600
    t0 = time.time()
    pub.stop("aborted")
    data = json.loads((f / f"live-{SID}.json").read_text())
    # ``ended`` is written rounded to the millisecond: up to 0.5 ms before t0
    assert data["state"] == "aborted" and t0 - 5e-4 <= data["ended"] <= time.time() + 5e-4
    assert data["gaze"]["samples_last_s"] is None and data["eta_s"] is None
    assert data["gaze"]["t"]  # the last seconds of gaze are kept
    v = ResultsView(root).session(f"calibration-sk/P01/{SID}")
    assert v["status"] == "finished"
    assert (v["end"]["how"], v["end"]["time"]) == ("quit by the operator", data["ended"])


def test_a_session_file_alone_says_how_it_ended(root: Path) -> None:
    """No status file (a run from before it had one): the session file's state and ISO end."""
    f = _folder(root)
    session_file(f, SID, state="interrupted", ended="2026-11-24T10:30:00+00:00")
    end = ResultsView(root).session(f"calibration-sk/P01/{SID}")["end"]
    assert end["how"].startswith("interrupted") and end["time"] == 1795516200.0
