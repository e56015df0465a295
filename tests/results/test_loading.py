"""Loading and validation of trial logs: each exclusion rule of docs/ANALYSIS.md (R1-R13), and the
clear errors for empty folders, non-numeric values and corrupt rows."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from fovexp import FovexpError
from fovexp.results.loading import COLUMNS, load_results, read_trials_file

from analysis_fixtures import SHA, Noise, Truth, session_id, simulate_rows, write_trials


def rows(exp: str = "calibration-fe", pid: str = "P01", k: int = 0, seed: int = 0,
         sha: str = SHA, practice: int = 2) -> list[dict]:
    return simulate_rows(exp, pid, session_id(k), np.random.default_rng(seed), Truth(), Noise(),
                         practice=practice, sha=sha)


def rules(ds) -> list[str]:
    return [e.rule for e in ds.exclusions if e.rule != "note"]


def test_clean_file_loads_typed(tmp_path: Path) -> None:
    write_trials(tmp_path / "calibration-fe" / "P01", rows())
    ds = load_results(tmp_path)
    t = ds.trials
    assert len(t) == 15  # 3 blur-rates x 5 images; the 2 practice trials are out (R4)
    assert rules(ds) == ["R4 practice"]
    assert t["final_value"].dtype == float and t["trial_index"].dtype == "Int64"
    assert not t["practice"].any()
    assert list(t.columns[: len(COLUMNS)]) == list(COLUMNS)


def test_torn_last_row_dropped_with_warning(tmp_path: Path) -> None:
    path = write_trials(tmp_path / "calibration-fe" / "P01", rows())
    text = path.read_text()
    path.write_text(text[: len(text) - 40])  # cut the last row mid-write
    with pytest.warns(UserWarning, match="torn last row"):
        ds = load_results(tmp_path)
    assert len(ds.trials) == 14
    torn = [e for e in ds.exclusions if e.rule == "R1 torn last row"]
    assert len(torn) == 1 and str(path) in torn[0].file and "line 18" in torn[0].detail


def test_torn_last_row_unparsable_value(tmp_path: Path) -> None:
    path = write_trials(tmp_path / "calibration-fe" / "P01", rows())
    lines = path.read_text().splitlines()
    fields = lines[-1].split(",")
    fields[COLUMNS.index("final_value")] = "0.1x"
    path.write_text("\n".join([*lines[:-1], ",".join(fields)]) + "\n")
    with pytest.warns(UserWarning, match="final_value"):
        ds = load_results(tmp_path)
    assert len(ds.trials) == 14


def test_torn_last_row_without_newline_or_short(tmp_path: Path) -> None:
    path = write_trials(tmp_path / "calibration-fe" / "P01", rows())
    text = path.read_text()
    path.write_text(text[:-1])  # every value parses, but the final newline never came
    with pytest.warns(UserWarning, match="no final newline"):
        assert len(load_results(tmp_path).trials) == 14
    lines = text.splitlines()
    path.write_text("\n".join([*lines[:-1], ",".join(lines[-1].split(",")[:10])]) + "\n")
    with pytest.warns(UserWarning, match="10 fields, expected 24"):
        assert len(load_results(tmp_path).trials) == 14


@pytest.mark.parametrize("column,value,problem", [
    ("blur_rate", "abc", "is not a number"),
    ("final_value", "", "is empty but required"),
    ("trial_index", "1.5", "is not an integer"),
    ("practice", "2", "is not 0 or 1"),
    ("participant", "P 01", "participant ID"),
    ("method", "noise", "is not a method"),
    ("final_value", "nan", "finite"),
])
def test_corrupt_middle_row_is_an_error(tmp_path: Path, column: str, value: str,
                                        problem: str) -> None:
    path = write_trials(tmp_path / "calibration-fe" / "P01", rows())
    lines = path.read_text().splitlines()
    fields = lines[3].split(",")
    fields[COLUMNS.index(column)] = value
    lines[3] = ",".join(fields)
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(FovexpError) as err:
        load_results(tmp_path)
    msg = str(err.value)
    assert str(path) in msg and "line 4" in msg and column in msg and problem in msg


def test_wrong_field_count_middle_row_is_an_error(tmp_path: Path) -> None:
    path = write_trials(tmp_path / "calibration-fe" / "P01", rows())
    lines = path.read_text().splitlines()
    lines[5] = lines[5] + ",extra"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(FovexpError, match=r"line 6: 25 fields, expected 24"):
        load_results(tmp_path)


def test_empty_and_missing_folders(tmp_path: Path) -> None:
    with pytest.raises(FovexpError, match="no trials.csv found"):
        load_results(tmp_path)
    with pytest.raises(FovexpError, match="no such folder"):
        load_results(tmp_path / "nope")


def test_header_only_and_empty_files(tmp_path: Path) -> None:
    write_trials(tmp_path / "validation" / "P01", [])
    (tmp_path / "validation" / "P02").mkdir()
    (tmp_path / "validation" / "P02" / "trials.csv").write_text("")
    with pytest.raises(FovexpError, match="no usable trials in 2 trials.csv"):
        load_results(tmp_path)


def test_missing_column_excludes_file(tmp_path: Path) -> None:
    write_trials(tmp_path / "calibration-fe" / "P01", rows())
    cols = tuple(c for c in COLUMNS if c != "seed")
    write_trials(tmp_path / "calibration-fe" / "P02", rows(pid="P02", k=1), columns=cols)
    ds = load_results(tmp_path)
    assert set(ds.trials["participant"]) == {"P01"}
    miss = [e for e in ds.exclusions if e.rule == "R3 missing columns"]
    assert len(miss) == 1 and "seed" in miss[0].detail and "P02" in miss[0].file
    assert miss[0].n_trials == 17
    # only such files: a clear error
    with pytest.raises(FovexpError, match="header lacks seed"):
        load_results(tmp_path / "calibration-fe" / "P02")


def test_duplicated_trials(tmp_path: Path) -> None:
    r = rows(practice=0)
    copy = dict(r[3])
    conflict = dict(r[4], final_value=0.39)
    path = write_trials(tmp_path / "calibration-fe" / "P01", [*r, copy, conflict])
    ds = load_results(tmp_path)
    assert len(ds.trials) == 15
    dups = [e for e in ds.exclusions if e.rule == "R5 duplicated trial"]
    assert len(dups) == 2
    assert any("identical copies merged" in e.detail for e in dups)
    assert any("different values" in e.detail and "line 18" in e.detail for e in dups)
    kept = ds.trials.loc[ds.trials["trial_index"] == r[4]["trial_index"], "final_value"]
    assert kept.tolist() == [0.39]  # the last one written
    assert str(path) in dups[0].file


def test_wrong_parameter_excluded(tmp_path: Path) -> None:
    r = rows(practice=0)
    r[0] = dict(r[0], adjusted_parameter="s_k")
    write_trials(tmp_path / "calibration-fe" / "P01", r)
    ds = load_results(tmp_path)
    assert len(ds.trials) == 14 and "R6 wrong parameter" in rules(ds)


def test_mixed_protocol_versions(tmp_path: Path) -> None:
    for p in range(3):
        write_trials(tmp_path / "calibration-fe" / f"P0{p}", rows(pid=f"P0{p}", k=p, seed=p))
    write_trials(tmp_path / "calibration-fe" / "P09", rows(pid="P09", k=9, sha="b" * 64))
    ds = load_results(tmp_path)
    assert set(ds.trials["participant"]) == {"P00", "P01", "P02"}
    mixed = [e for e in ds.exclusions if e.rule == "R9 mixed protocol versions"]
    assert len(mixed) == 1 and mixed[0].participant == "P09" and mixed[0].n_trials == 15
    assert "bbbbbbbbbbbb" in mixed[0].detail
    chosen = load_results(tmp_path, protocol={"calibration-fe": "bbbb"})
    assert set(chosen.trials["participant"]) == {"P09"}
    with pytest.raises(FovexpError, match="matches 0"):
        load_results(tmp_path, protocol={"calibration-fe": "c"})


def test_dry_runs_beside_real_sessions(tmp_path: Path) -> None:
    """R8: three dry runs (another protocol version) beside two real participants: the dry runs
    are left out before R9, so they cannot outvote the real sessions' protocol version."""
    for k, pid in enumerate(("SIM01", "SIM02", "SIM03")):
        write_trials(tmp_path / "calibration-fe" / pid, rows(pid=pid, k=k, sha="d" * 64))
    only_dry = load_results(tmp_path)
    assert len(only_dry.trials) == 45 and "R8 simulated sessions" not in rules(only_dry)
    assert any("simulated gaze" in n for n in only_dry.notes)
    # a participant's aborted session alone does not push the dry runs out (R10 drops it)
    aborted = [dict(r, tracker="tobii") for r in rows(pid="P09", k=9)][:6]
    write_trials(tmp_path / "calibration-fe" / "P09", aborted, completed=False)
    assert sorted(load_results(tmp_path).trials["participant"].unique()) == [
        "SIM01", "SIM02", "SIM03"]
    for k, pid in enumerate(("P01", "P02"), start=3):
        real = [dict(r, tracker="tobii") for r in rows(pid=pid, k=k)]
        write_trials(tmp_path / "calibration-fe" / pid, real)
    ds = load_results(tmp_path)
    assert sorted(ds.trials["participant"].unique()) == ["P01", "P02"]
    assert (ds.trials["tracker"] == "tobii").all()
    dry = [e for e in ds.exclusions if e.rule == "R8 simulated sessions"]
    assert sorted(e.participant for e in dry) == ["SIM01", "SIM02", "SIM03"]
    assert sum(e.n_trials for e in dry) == 45
    assert "R9 mixed protocol versions" not in rules(ds)


def test_incomplete_session_from_json(tmp_path: Path) -> None:
    write_trials(tmp_path / "calibration-fe" / "P01", rows())
    write_trials(tmp_path / "calibration-fe" / "P02", rows(pid="P02", k=1), completed=False)
    ds = load_results(tmp_path)
    assert set(ds.trials["participant"]) == {"P01"}
    inc = [e for e in ds.exclusions if e.rule == "R10 incomplete session"]
    assert len(inc) == 1 and "not completed" in inc[0].detail and inc[0].n_trials == 15
    kept = load_results(tmp_path, include_incomplete=True)
    assert set(kept.trials["participant"]) == {"P01", "P02"}
    assert "R10 incomplete session" in rules(kept)


def test_incomplete_session_from_trial_count(tmp_path: Path) -> None:
    write_trials(tmp_path / "calibration-fe" / "P01", rows(), completed=None)
    write_trials(tmp_path / "calibration-fe" / "P02", rows(pid="P02", k=1)[:10], completed=None)
    ds = load_results(tmp_path)
    assert set(ds.trials["participant"]) == {"P01"}
    inc = [e for e in ds.exclusions if e.rule == "R10 incomplete session"]
    assert "8 trials, fewer than the 15" in inc[0].detail


def test_session_json_completed_overrides_count(tmp_path: Path) -> None:
    # a completed session may have fewer trials (e.g. a shorter protocol run): JSON wins
    write_trials(tmp_path / "calibration-fe" / "P01", rows())
    write_trials(tmp_path / "calibration-fe" / "P02", rows(pid="P02", k=1)[:10])
    ds = load_results(tmp_path)
    assert set(ds.trials["participant"]) == {"P01", "P02"}


def test_session_json_state_spellings(tmp_path: Path) -> None:
    folder = tmp_path / "calibration-fe" / "P01"
    write_trials(folder, rows(), completed=None)
    write_trials(tmp_path / "calibration-fe" / "P02", rows(pid="P02", k=1), completed=None)
    (folder / f"session-{session_id(0)}.json").write_text(json.dumps({"state": "aborted"}))
    ds = load_results(tmp_path)
    assert set(ds.trials["participant"]) == {"P02"}


def test_resumed_session_appends(tmp_path: Path) -> None:
    # --resume appends to the same file with the same session ID: one complete session
    r = rows()
    folder = tmp_path / "calibration-fe" / "P01"
    write_trials(folder, r[:9], completed=False)
    write_trials(folder, r[9:], completed=True, append=True)
    ds = load_results(tmp_path)
    assert len(ds.trials) == 15 and ds.trials["session"].nunique() == 1


def test_read_trials_file_reports_extra_columns(tmp_path: Path) -> None:
    path = write_trials(tmp_path / "x" / "P01", rows(), columns=(*COLUMNS, "note"))
    frame, excl = read_trials_file(path)
    assert len(frame) == 17
    assert any("extra columns ignored: note" in e.detail for e in excl)


def test_participant_folder_mismatch_is_noted(tmp_path: Path) -> None:
    write_trials(tmp_path / "calibration-fe" / "someone", rows())
    ds = load_results(tmp_path)
    assert any("folder name 'someone'" in n for n in ds.notes)


def test_runner_writer_round_trip(tmp_path: Path) -> None:
    """Rows written by the runner's own TrialLog (and its session JSON) load unchanged."""
    logs = pytest.importorskip("fovexp.experiment.records.logs")
    folder = tmp_path / "calibration-fe" / "P01"
    r = rows()
    log = logs.TrialLog(folder / "trials.csv")
    for row in r:
        log.append({**row, "practice": bool(row["practice"])})
    logs.write_json_atomic(folder / f"session-{session_id(0)}.json",
                           {"session": session_id(0), "state": "completed", "completed": True})
    ds = load_results(tmp_path)
    assert len(ds.trials) == 15
    main = [x for x in r if not x["practice"]]
    got = ds.trials.sort_values("trial_index")
    assert got["final_value"].tolist() == [x["final_value"] for x in main]
    assert got["s_k"].isna().all()  # empty in the log, NaN here
    # a session the runner marked incomplete is excluded (R10)
    logs.write_json_atomic(folder / f"session-{session_id(0)}.json",
                           {"session": session_id(0), "state": "interrupted", "completed": False})
    write_trials(tmp_path / "calibration-fe" / "P02", rows(pid="P02", k=1))
    ds = load_results(tmp_path)
    assert set(ds.trials["participant"]) == {"P02"}


def _as(rows_: list[dict], **kw) -> list[dict]:
    return [dict(r, **kw) for r in rows_]


def test_mouse_pilots_left_out_unless_asked(tmp_path: Path) -> None:
    """R7: mouse-gaze sessions are pilots: left out beside a tracked participant, an error
    naming --include-pilots when nothing else is left, kept with include_pilots."""
    write_trials(tmp_path / "calibration-fe" / "P01", _as(rows(pid="P01"), tracker="tobii"))
    write_trials(tmp_path / "calibration-fe" / "M01",
                 _as(rows(pid="M01", k=1, seed=1), tracker="mouse"))
    ds = load_results(tmp_path)
    assert set(ds.trials["participant"]) == {"P01"}
    pilots = [e for e in ds.exclusions if e.rule == "R7 pilot sessions"]
    assert len(pilots) == 1 and pilots[0].participant == "M01" and pilots[0].n_trials == 15
    kept = load_results(tmp_path, include_pilots=True)
    assert set(kept.trials["participant"]) == {"P01", "M01"}
    only = tmp_path / "only-pilots"
    write_trials(only / "calibration-fe" / "M01", _as(rows(pid="M01"), tracker="mouse"))
    with pytest.raises(FovexpError, match="--include-pilots keeps them"):
        load_results(only)
    assert len(load_results(only, include_pilots=True).trials) == 15


def _frame_log(folder: Path, session: str, trials: dict[int, dict]) -> None:
    """A frame log: per trial ``n`` frames at 120 Hz, ``dropped`` of them dropped, each with a
    gaze sample ``latency_ms`` before its flip (a retried first attempt with bad frames too,
    which the trial's answer did not come from)."""
    from fovexp.results.format import FRAME_COLUMNS

    lines = [",".join(FRAME_COLUMNS)]
    t_us = 10**9
    for idx, spec in trials.items():
        for attempt in (0, 1):
            for k in range(spec["n"]):
                t_us += 8333
                bad = attempt == 0  # the abandoned attempt: every frame late and dropped
                lat = 500.0 if bad else spec["latency_ms"]
                dropped = int(bad or k < spec["dropped"])
                row = {"trial_index": idx, "attempt": attempt, "frame": k,
                       "flip_time_s": t_us / 1e6, "interval_s": 0.00833, "dropped": dropped,
                       "blanked": 0, "value": 0.1, "gaze_system_time_us": int(t_us - 1e3 * lat),
                       "gaze_ecc_deg": 0.3, "flip_system_time_us": t_us}
                lines.append(",".join(str(row.get(c, "")) for c in FRAME_COLUMNS))
    (folder / f"frames-{session}.csv").write_text("\n".join(lines) + "\n")


def test_trial_quality_rules(tmp_path: Path) -> None:
    """R11-R13: a participant's trials blanked too long, with too many dropped frames or too
    late a gaze-to-flip latency are excluded, with the stated thresholds; the attempt the answer
    did not come from does not count; dry runs are not judged by them."""
    from fovexp.results.limits import TrialLimits

    rs = _as(rows(pid="P01"), tracker="tobii")
    main = [r for r in rs if not r["practice"]]
    main[0]["blanked_fraction"] = 0.8  # R11
    folder = tmp_path / "calibration-fe" / "P01"
    write_trials(folder, rs)
    good = {"n": 100, "dropped": 1, "latency_ms": 12.0}
    spec = {r["trial_index"]: dict(good) for r in rs}
    spec[main[1]["trial_index"]]["dropped"] = 10  # R12: 10 % dropped
    spec[main[2]["trial_index"]]["latency_ms"] = 80.0  # R13
    _frame_log(folder, rs[0]["session"], spec)
    ds = load_results(tmp_path)
    got = {e.rule: e.n_trials for e in ds.exclusions if e.rule.startswith(("R11", "R12", "R13"))}
    assert got == {"R11 blanking": 1, "R12 dropped frames": 1, "R13 latency": 1}
    assert len(ds.trials) == 12
    # looser thresholds keep them all
    loose = TrialLimits(max_blanked_fraction=0.9, max_dropped_fraction=0.2,
                        max_latency_p95_ms=100.0)
    assert len(load_results(tmp_path, limits=loose).trials) == 15
    # the same logs from a dry run: not judged (its frame timing is the machine's)
    sim = tmp_path / "sim"
    write_trials(sim / "calibration-fe" / "P01", _as(rs, tracker="simulated"))
    _frame_log(sim / "calibration-fe" / "P01", rs[0]["session"], spec)
    assert len(load_results(sim).trials) == 15


def test_trial_quality_without_frame_log_is_noted(tmp_path: Path) -> None:
    write_trials(tmp_path / "calibration-fe" / "P01", _as(rows(pid="P01"), tracker="tobii"))
    ds = load_results(tmp_path)
    assert len(ds.trials) == 15
    assert any("no frame log: rules R12 and R13 not applied" in n for n in ds.notes)


# --- the details of the exclusion records (issue 19: the mutation runs' survivors)

def test_the_records_of_r1_r5_and_an_empty_file(tmp_path: Path) -> None:
    """R1 counts one trial; R5 names the trial index, the copies beyond the first and the
    experiment; a header-only file is noted as having no trials (a file with rows is not)."""
    r = rows(practice=0)
    path = write_trials(tmp_path / "calibration-fe" / "P01", [*r, dict(r[3])])
    text = path.read_text()
    path.write_text(text[: len(text) - 40])
    with pytest.warns(UserWarning):
        ds = load_results(tmp_path)
    torn = [e for e in ds.exclusions if e.rule == "R1 torn last row"]
    assert [e.n_trials for e in torn] == [1]
    write_trials(tmp_path / "calibration-fe" / "P01", [*r, dict(r[3]), dict(r[3])])
    ds = load_results(tmp_path)
    (dup,) = [e for e in ds.exclusions if e.rule == "R5 duplicated trial"]
    assert dup.detail.startswith(f"trial_index {r[3]['trial_index']} appears 3 times")
    assert (dup.n_trials, dup.experiment, dup.participant) == (2, "calibration-fe", "P01")
    assert not [e for e in ds.exclusions if e.detail == "no trials"]
    (tmp_path / "calibration-fe" / "P02").mkdir()
    (tmp_path / "calibration-fe" / "P02" / "trials.csv").write_text(",".join(COLUMNS) + "\n")
    ds = load_results(tmp_path)
    assert [e.rule for e in ds.exclusions if e.detail == "no trials"] == ["note"]


def test_each_experiment_apart_and_typed_columns(tmp_path: Path) -> None:
    """Dataset.experiment gives one experiment's trials; parameters left empty by an
    experiment (s_f in calibration-fe) are float columns of NaN, not objects."""
    write_trials(tmp_path / "calibration-fe" / "P01", rows(practice=0))
    write_trials(tmp_path / "calibration-sf" / "P01", rows("calibration-sf", k=1, practice=0))
    ds = load_results(tmp_path)
    fe = ds.experiment("calibration-fe")
    assert len(fe) == 15 and (fe["experiment"] == "calibration-fe").all()
    assert ds.experiments == ["calibration-fe", "calibration-sf"]
    for col in ("f_e", "s_k", "s_f", "blur_rate", "final_value"):
        assert ds.trials[col].dtype == np.float64, col
    assert fe["s_f"].isna().all()


def test_a_session_file_that_is_not_json_is_no_state(tmp_path: Path) -> None:
    write_trials(tmp_path / "calibration-fe" / "P01", rows())
    write_trials(tmp_path / "calibration-fe" / "P02", rows(pid="P02", k=1)[:8], completed=None)
    (tmp_path / "calibration-fe" / "P02" / f"session-{session_id(1)}.json").write_text("{not")
    ds = load_results(tmp_path)  # the state unknown: judged by its trial count (R10)
    assert set(ds.trials["participant"]) == {"P01"}
    kept = load_results(tmp_path, include_incomplete=True)
    r10 = [e for e in kept.exclusions if e.rule == "R10 incomplete session"]
    assert len(r10) == 1 and r10[0].n_trials == 0 and "kept" in r10[0].detail


def test_r9_names_the_versions_by_twelve_characters(tmp_path: Path) -> None:
    write_trials(tmp_path / "calibration-fe" / "P01", rows(sha="a" * 64))
    write_trials(tmp_path / "calibration-fe" / "P02", rows(pid="P02", k=1, sha="b" * 64))
    with pytest.raises(FovexpError, match=r"matches 0 of the logged versions "
                                          r"\(a{12}, b{12}\)$"):
        load_results(tmp_path, protocol={"calibration-fe": "c"})


def test_the_frame_rules_check_every_session_and_the_error_names_the_first_reason(
        tmp_path: Path) -> None:
    """A session without a frame log does not stop the others' from being checked (R12);
    with no trial left, the error names the first exclusion's file and reason."""
    first = tmp_path / "calibration-fe" / "P01"  # sorted first: no frame log
    write_trials(first, _as(rows(pid="P01"), tracker="tobii"))
    second = tmp_path / "calibration-fe" / "P02"
    rs = _as(rows(pid="P02", k=1), tracker="tobii")
    write_trials(second, rs)
    spec = {r["trial_index"]: {"n": 100, "dropped": 20, "latency_ms": 12.0} for r in rs}
    _frame_log(second, rs[0]["session"], spec)
    ds = load_results(tmp_path)
    assert set(ds.trials["participant"]) == {"P01"}
    assert [e.participant for e in ds.exclusions if e.rule == "R12 dropped frames"] == ["P02"]
    only = tmp_path / "only"  # P01: practice only (R4); P02: the wrong parameter (R6)
    write_trials(only / "calibration-fe" / "P01", [dict(r, practice=1) for r in rows()])
    write_trials(only / "calibration-fe" / "P02",
                 [dict(r, adjusted_parameter="s_k") for r in rows(pid="P02", practice=0)])
    with pytest.raises(FovexpError, match=r"no trials left .*\(e\.g\. \S*P01\S*: practice "
                                          r"trial\)$"):
        load_results(only)


def test_r9_takes_the_experiments_in_name_order_whatever_their_folders(tmp_path: Path) -> None:
    """The experiments come from the files' own column, not their folders: folders sorted the
    other way round (a/ holds calibration-sk, b/ calibration-fe) still give R9's exclusions,
    and its first error, in experiment order."""
    for folder, exp in (("a", "calibration-sk"), ("b", "calibration-fe")):
        for p in range(2):
            write_trials(tmp_path / folder / f"P0{p}", rows(exp, f"P0{p}", k=p, seed=p))
        write_trials(tmp_path / folder / "P09", rows(exp, "P09", k=9, sha="b" * 64))
    ds = load_results(tmp_path)
    mixed = [e.experiment for e in ds.exclusions if e.rule == "R9 mixed protocol versions"]
    assert mixed == ["calibration-fe", "calibration-sk"]
    with pytest.raises(FovexpError, match="^experiment calibration-fe: protocol 'c' matches 0"):
        load_results(tmp_path, protocol={"calibration-fe": "c", "calibration-sk": "c"})
