"""The forced-choice task's answers in ``trials.csv`` (issue 30; docs/LOGS.md).

A forced-choice session writes the documented trial columns (the blur-rate shown in
``blur_rate`` and ``final_value``, the response time in ``response_time_s``, from the response
screen's first flip to the key press; ``start_value`` and ``wheel_events`` empty) and, after
them, :data:`FORCED_CHOICE_COLUMNS`: each row stays the trial's one commit point, and every
reader of ``trials.csv`` reads it (extra columns are allowed and ignored there). This module
reads those columns back beside the rows the loader included (:func:`with_choices`), so the
exclusion rules of :mod:`.loading` hold for the forced-choice analysis too.
"""

from __future__ import annotations

import csv
from pathlib import Path

import pandas as pd

from fovexp import FovexpError

#: the forced-choice columns, after the documented ones: ``task`` (``2afc``), the half that
#: showed the method (``left``/``right``), the half the participant chose, whether that was
#: the degraded one (0/1), the stimulus' time on screen (s), the procedure (``questplus`` or
#: ``constant``) and the blur-rate's index on its grid
FORCED_CHOICE_COLUMNS: tuple[str, ...] = (
    "task", "degraded_side", "answer", "correct", "presentation_s", "procedure", "grid_index",
)
TASK_2AFC = "2afc"
SIDES = ("left", "right")


def choice_fields(path: Path) -> dict[int, dict[str, str]] | None:
    """The forced-choice columns of a ``trials.csv`` by line number, as text; None: it has
    none."""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except OSError as exc:
        raise FovexpError(f"{path}: cannot read: {exc.strerror}") from None
    lines = text.split("\n")
    header = [h.strip() for h in next(csv.reader([lines[0]]), [])]
    if "correct" not in header:
        return None
    idx = {c: header.index(c) for c in FORCED_CHOICE_COLUMNS if c in header}
    out = {}
    for i, line in enumerate(lines[1:], start=2):
        fields = next(csv.reader([line]), [])
        if len(fields) == len(header):
            out[i] = {c: fields[j].strip() for c, j in idx.items()}
    return out


def with_choices(trials: pd.DataFrame) -> pd.DataFrame:
    """The forced-choice rows of ``trials`` (the loader's included trials, with its ``file``
    and ``line`` columns) with :data:`FORCED_CHOICE_COLUMNS` typed (``correct`` bool,
    ``presentation_s`` float, ``grid_index`` int); empty when none is forced-choice."""
    parts = []
    for path, rows in trials.groupby("file", sort=True):
        extra = choice_fields(Path(str(path)))
        if extra is None:
            continue
        part = rows.copy()
        for col in FORCED_CHOICE_COLUMNS:
            part[col] = [extra.get(int(line), {}).get(col, "") for line in part["line"]]
        bad = part[~part["correct"].isin(["0", "1"]) | ~part["answer"].isin(SIDES)
                   | ~part["degraded_side"].isin(SIDES)]
        if len(bad):
            raise FovexpError(f"{path}: line {int(bad['line'].iloc[0])}: a forced-choice row "
                              "needs degraded_side and answer (left/right) and correct (0/1)")
        part["correct"] = part["correct"] == "1"
        part["presentation_s"] = pd.to_numeric(part["presentation_s"], errors="coerce")
        part["grid_index"] = pd.to_numeric(part["grid_index"], errors="coerce")
        parts.append(part)
    if not parts:
        return trials.iloc[0:0].assign(**{c: [] for c in FORCED_CHOICE_COLUMNS})
    return pd.concat(parts, ignore_index=True)


def forced_choice_experiments(trials: pd.DataFrame) -> set[str]:
    """The experiments whose trials are forced-choice (their files carry the answers)."""
    return set(with_choices(trials)["experiment"]) if len(trials) else set()


def typed_choice(fields: dict[str, str]) -> dict[str, object]:
    """One row's forced-choice columns typed (``correct`` bool, ``presentation_s`` float,
    ``grid_index`` int; empty: None)."""
    out: dict[str, object] = {c: (fields.get(c) or None) for c in FORCED_CHOICE_COLUMNS}
    out["correct"] = fields.get("correct") == "1"
    for col, kind in (("presentation_s", float), ("grid_index", int)):
        text = fields.get(col) or ""
        out[col] = kind(text) if text else None
    return out


__all__ = ["FORCED_CHOICE_COLUMNS", "SIDES", "TASK_2AFC", "choice_fields",
           "forced_choice_experiments", "typed_choice", "with_choices"]
