"""The log format's values (fovexp.results.format; docs/LOGS.md): formatting, typed parsing
with its reasons, the participant-ID rule, and the torn-row byte count, field by field."""

from __future__ import annotations

import pytest

from fovexp.results.format import (
    REQUIRED_VALUES,
    TRIAL_COLUMNS,
    format_line,
    format_value,
    is_participant_id,
    parse_value,
    read_trials_file,
)


def test_format_value_and_line():
    assert [format_value(v) for v in (None, True, False, 0.1, float("nan"), 7, "a")] == [
        "", "1", "0", "0.1", "", "7", "a"]
    assert format_value(1 / 3) == repr(1 / 3)  # round-trip floats
    assert format_line(["a,b", 1.5, None, True]) == '"a,b",1.5,,1\n'


@pytest.mark.parametrize("text,ok", [
    ("P01", True), ("a" * 32, True), ("a" * 33, False), ("", False), ("P 01", False),
    ("P01\n", False), ("x-y_Z9", True), ("CON", False), ("com7", False), ("lpt0", False),
    ("com10", True), ("lpt10", True), ("com9", False), ("lpt9", False), ("com0", False),
    ("nul", False), ("aux1", True), (5, False),
])
def test_the_participant_id_rule(text, ok):
    assert is_participant_id(text) is ok


def test_parse_value_types_each_column_and_says_why_not():
    assert parse_value("blur_rate", " 0.34 ") == 0.34
    assert parse_value("f_e", "") is None  # optional
    assert parse_value("trial_index", "12") == 12
    assert parse_value("practice", "TRUE") is True and parse_value("practice", "0") is False
    assert parse_value("practice", "true") is True and parse_value("practice", "False") is False
    assert parse_value("participant", "P01") == "P01"
    assert parse_value("method", "ours") == "ours"
    assert parse_value("adjusted_parameter", "s_k") == "s_k"
    assert parse_value("timestamp", "2024-05-01T09:00:15") == "2024-05-01T09:00:15"
    assert parse_value("timestamp", "2024-05-01 09:00:15.25+02:00") is not None
    assert parse_value("tracker", "anything") == "anything"
    cases = [
        ("final_value", "", "is empty but required"), ("blur_rate", "x", "is not a number"),
        ("blur_rate", "inf", "is not a finite number"),
        ("s_k", "nan", "is not a finite number"), ("seed", "1.5", "is not an integer"),
        ("practice", "2", "is not 0 or 1"), ("participant", "CON", "valid participant ID"),
        ("method", "magic", "is not a method"),
        ("adjusted_parameter", "gamma", "is not an adjustable parameter"),
        ("timestamp", "yesterday", "is not an ISO 8601 time"),
        ("timestamp", "2024-05-01T09:00:15 ", None),
    ]
    for column, text, reason in cases:
        if reason is None:
            parse_value(column, text)  # surrounding blanks are stripped
            continue
        with pytest.raises(ValueError, match=reason):
            parse_value(column, text)
    assert set(REQUIRED_VALUES) <= set(TRIAL_COLUMNS) and "f_e" not in REQUIRED_VALUES


def test_the_valid_part_is_counted_in_bytes(tmp_path):
    """good_len: the bytes of the header and the complete rows (where a resumed run cuts the
    file), blank lines included; a torn last row is not counted."""
    import numpy as np

    from analysis_fixtures import SHA, Noise, Truth, simulate_rows, write_trials

    rows = simulate_rows("calibration-fe", "P01", "20240501-090000", np.random.default_rng(0),
                         Truth(), Noise(), practice=0)[:3]
    path = write_trials(tmp_path / "p", rows)
    data = path.read_bytes()
    whole = read_trials_file(path)
    assert whole.good_len == len(data) and len(whole.rows) == 3 and whole.lines == [2, 3, 4]
    assert whole.rows[0]["protocol_sha256"] == SHA
    path.write_bytes(data + b"\n" + data.splitlines(keepends=True)[1][:40])
    with pytest.warns(UserWarning, match="line 6: torn last row dropped") as rec:
        torn = read_trials_file(path)
    assert rec[0].filename == __file__  # the warning points at the caller
    assert torn.good_len == len(data) + 1 and torn.torn_line == 6 and len(torn.rows) == 3
    assert read_trials_file(tmp_path / "none.csv").rows == []


def _rows(n: int = 2) -> list[dict]:
    import numpy as np

    from analysis_fixtures import Noise, Truth, simulate_rows

    return simulate_rows("calibration-fe", "P01", "20240501-090000", np.random.default_rng(0),
                         Truth(), Noise(), practice=0)[:n]


def test_blank_lines_torn_headers_and_bad_bytes(tmp_path):
    """Blank lines are skipped and counted in the valid part (one at the very end without its
    newline is not: a resumed run cuts it); rows after a blank line are read; a header cut
    short is a torn header (warned, no rows), a whole header lacking columns names them; a
    header that is not UTF-8, or a folder, is one error naming the file; the warning points
    at the caller."""
    from fovexp import FovexpError

    from analysis_fixtures import write_trials

    path = write_trials(tmp_path / "p", _rows())
    data = path.read_bytes()
    head, first, second = data.splitlines(keepends=True)
    path.write_bytes(head + first + b"\n" + second + b"  ")
    got = read_trials_file(path)
    assert len(got.rows) == 2 and got.lines == [2, 4]
    assert got.good_len == len(data) + 1
    path.write_bytes(head[:30])
    with pytest.warns(UserWarning, match="line 1: torn header dropped") as rec:
        torn = read_trials_file(path)
    assert rec[0].filename == __file__
    assert torn.torn == "torn header" and torn.missing == [] and torn.rows == []
    for text in (b"participant,session\nP01,x\n", b"participant,session\nP01,x"):
        path.write_bytes(text)  # a row, with and without its final newline
        short = read_trials_file(path)
        assert short.torn is None and "experiment" in short.missing and short.rows == []
        assert short.extra == []
    path.write_bytes(b"\xff\xfeparticipant\n")
    with pytest.raises(FovexpError, match="line 1: not UTF-8 text"):
        read_trials_file(path)
    with pytest.raises(FovexpError, match="cannot read"):
        read_trials_file(tmp_path)
