"""The frame log (``frames-<session>.csv``, docs/LOGS.md) as data: what every stimulus frame
showed and what drove it.

Each frame names the newest gaze sample its blanking decision used (``gaze_system_time_us``,
``gaze_ecc_deg``), the decision (``decide_system_time_us``) and its flip
(``flip_system_time_us``), all on the tracker's system clock: flip minus sample is the frame's
gaze-to-flip latency, flip minus decision its draw latency, and decision minus sample the age
the blanking rule of paper section 5.1 limits (:mod:`fovexp.results.blanking`, the rule's one
definition), so the rule is checked from the log alone, exactly, for every frame. Logs written
before a column existed read with it empty (docs/LOGS.md, "Format versions").
"""

from __future__ import annotations

import io
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from fovexp import FovexpError

from .blanking import BlankingRule
from .format import FRAME_COLUMNS

#: Integer columns of the frame log (nullable: empty fields are missing values).
FRAME_INT_COLUMNS = ("trial_index", "attempt", "frame", "dropped", "blanked",
                     "gaze_system_time_us", "flip_system_time_us", "decide_system_time_us",
                     "attempt_start_system_time_us")


def read_complete_lines(path: Path, what: str) -> pd.DataFrame:
    """A batch log's complete lines as strings (a torn last line, a kill mid-write, dropped);
    :class:`FovexpError` naming the file when it cannot be read as ``what``."""
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise FovexpError(f"{path}: cannot read: {exc.strerror}") from None
    data = data[: data.rfind(b"\n") + 1]  # complete lines only
    try:
        return pd.read_csv(io.BytesIO(data), dtype=str, keep_default_na=False)
    except (ValueError, pd.errors.ParserError) as exc:
        raise FovexpError(f"{path}: not {what} ({exc})") from None


def read_frame_log(path: str | Path) -> pd.DataFrame:
    """A frame log, typed, one row per frame; a torn last line (a kill mid-write) is dropped.
    Columns missing from an older log are added empty. Raises :class:`FovexpError` naming the
    file when it cannot be read as one."""
    path = Path(path)
    frame = read_complete_lines(path, "a frame log")
    missing = [c for c in ("trial_index", "attempt", "frame", "blanked") if c not in frame]
    if missing:
        raise FovexpError(f"{path}: not a frame log (no {', '.join(missing)} column)")
    out = pd.DataFrame(index=frame.index)
    for col in FRAME_COLUMNS:
        raw = frame[col] if col in frame else pd.Series("", index=frame.index)
        num = pd.to_numeric(raw, errors="coerce")  # empty fields: missing
        out[col] = num.round().astype("Int64") if col in FRAME_INT_COLUMNS else num
    return out


def _us(frames: pd.DataFrame, column: str) -> pd.Series:
    """A time column as float microseconds (NaN where empty, or where a table lacks it)."""
    if column not in frames:
        return pd.Series(np.nan, index=frames.index)
    return pd.to_numeric(frames[column], errors="coerce").astype(float)


def gaze_to_flip_ms(frames: pd.DataFrame) -> pd.Series:
    """Per frame: the flip's time minus that of the newest gaze sample its decision used (ms),
    on the tracker's clock; missing where a frame had no sample."""
    return (_us(frames, "flip_system_time_us") - _us(frames, "gaze_system_time_us")) / 1e3


def draw_latency_ms(frames: pd.DataFrame) -> pd.Series:
    """Per frame: the flip's time minus the decision's (ms, tracker clock): how long the
    frame took from its blanking decision to the screen; missing in logs older than the
    decision's column."""
    return (_us(frames, "flip_system_time_us") - _us(frames, "decide_system_time_us")) / 1e3


def decision_age_us(frames: pd.DataFrame) -> pd.Series:
    """Per frame: the deciding sample's age when the frame was decided (us, tracker clock):
    what the blanking rule limits (:meth:`BlankingRule.fresh`); missing without a sample, or
    in logs older than the decision's column."""
    return _us(frames, "decide_system_time_us") - _us(frames, "gaze_system_time_us")


def latency_summary(frames: pd.DataFrame) -> dict[str, float]:
    """``frames`` (all frames), ``with_gaze`` (frames whose decision had a sample), the
    gaze-to-flip latency's ``median_ms``, ``p95_ms``, ``max_ms``, the draw latency's
    ``draw_median_ms``, ``draw_p95_ms``, ``draw_max_ms`` (NaN without any), and the share of
    ``dropped`` frames."""
    lat = gaze_to_flip_ms(frames).dropna().to_numpy()
    draw = draw_latency_ms(frames).dropna().to_numpy()
    n = len(frames)

    def stats(v: np.ndarray, prefix: str) -> dict[str, float]:
        nan = float("nan")
        return {f"{prefix}median_ms": float(np.median(v)) if v.size else nan,
                f"{prefix}p95_ms": float(np.percentile(v, 95)) if v.size else nan,
                f"{prefix}max_ms": float(v.max()) if v.size else nan}

    return {
        "frames": n,
        "with_gaze": int(lat.size),
        **stats(lat, ""),
        **stats(draw, "draw_"),
        "dropped_fraction": float(frames["dropped"].fillna(0).mean()) if n else float("nan"),
    }


def unblanked_violations(frames: pd.DataFrame, rule: BlankingRule | None = None,
                         ) -> pd.DataFrame:
    """Frames drawn with the stimulus (``blanked`` 0) that the blanking rule
    (:class:`fovexp.results.blanking.BlankingRule`, default the paper's) forbids: without a
    valid gaze sample (``gaze_ecc_deg`` empty), with one farther than the radius from the
    cross, or with one older than the gaze timeout when the frame was decided
    (``decide_system_time_us`` minus ``gaze_system_time_us``): exact, for every frame, the
    first of an attempt included. Empty when the log keeps the rule.

    A log older than the decision's column (version 1, docs/LOGS.md) has no decision time: a
    frame's is then bounded below by the previous flip (a frame is decided after it), so a
    sample older than the previous flip minus the timeout breaks the rule for certain and is
    flagged; a first frame cannot be checked for its sample's age (:func:`unchecked_ages`)."""
    rule = rule or BlankingRule()
    f = frames.sort_values(["trial_index", "attempt", "frame"])
    age = decision_age_us(f)
    prev_flip = _us(f, "flip_system_time_us").groupby(
        [f["trial_index"], f["attempt"]]).shift(1)
    # version 1: the age at the previous flip, no more than the age at the decision
    age = age.where(age.notna(), prev_flip - _us(f, "gaze_system_time_us"))
    ecc = f["gaze_ecc_deg"].astype(float)
    old_log = _us(f, "decide_system_time_us").isna() & prev_flip.isna()
    allowed = pd.Series(rule.allows(age.to_numpy(), ecc.to_numpy()), index=f.index)
    # an unknowable age (a version-1 first frame) is not a violation; a missing sample is
    allowed |= old_log & f["gaze_system_time_us"].notna() & np.asarray(rule.inside(ecc))
    bad = (f["blanked"] == 0).fillna(True) & ~allowed
    return f[bad]


def unchecked_ages(frames: pd.DataFrame) -> int:
    """Stimulus frames whose sample's age at the decision the log cannot bound: the first
    frames of attempts in logs older than the decision's column (0 for current logs)."""
    prev_flip = frames.sort_values(["trial_index", "attempt", "frame"]).groupby(
        ["trial_index", "attempt"])["flip_system_time_us"].shift(1)
    prev_flip = prev_flip.reindex(frames.index)
    return int(((frames["blanked"] == 0) & _us(frames, "decide_system_time_us").isna()
                & prev_flip.isna() & frames["gaze_system_time_us"].notna()).sum())


def trial_quality(frames: pd.DataFrame) -> pd.DataFrame:
    """Per trial (``trial_index``; its last attempt, the one whose answer the trial log holds):
    ``frames``, ``dropped_fraction`` and the gaze-to-flip latency's 95th percentile
    ``latency_p95_ms`` (NaN without gaze samples): what the exclusion rules on a trial's frame
    timing read (:mod:`fovexp.results.loading`, R12 and R13)."""
    if frames.empty:
        return pd.DataFrame(columns=["trial_index", "frames", "dropped_fraction",
                                     "latency_p95_ms"])
    last = frames.groupby("trial_index")["attempt"].transform("max")
    f = frames[frames["attempt"] == last].assign(latency_ms=gaze_to_flip_ms(frames))
    out = f.groupby("trial_index").agg(
        frames=("frame", "size"),
        dropped_fraction=("dropped", lambda d: float(d.fillna(0).mean())),
        latency_p95_ms=("latency_ms", lambda v: float(np.nanpercentile(v, 95))
                        if v.notna().any() else float("nan")),
    )
    return out.reset_index()


#: slack on the Enter time recomputed from the trial log: ``response_time_s`` is rounded to
#: 1 us (0.1 ms in logs before issue 18), the flip times to 1 us; a frame flipped this close
#: to the press may be either side of it
ENTER_SLACK_S = 1e-4


def final_value_violations(frames: pd.DataFrame, trials: Iterable[Mapping[str, Any]],
                           value_tol: float = 1e-9) -> pd.DataFrame:
    """Trials whose frames contradict their row in the trial log: what is logged must be what
    was on screen (docs/LOGS.md). For each trial row (``trial_index``, ``start_value``,
    ``final_value``, ``response_time_s``), the frames of its last attempt (the confirmed one):
    the first shows ``start_value``; Enter went down ``response_time_s`` after the first flip;
    the last stimulus frame (not blanked) flipped at or before that press shows
    ``final_value`` (the start value when every frame until then was black): a render that
    reached the screen after the press, before the poll that saw it, is not the answer.
    Frames flipped between the press and that poll are in the log (the loop leaves at the
    poll). A frame flipped within :data:`ENTER_SLACK_S` of the press (the logs' rounding) may
    count on either side. ``frames`` is one session's frame log (:func:`read_frame_log`),
    ``trials`` that session's rows. Returns one row per violation (``trial_index``,
    ``attempt``, ``problem``); empty when the logs keep the rule."""
    out: list[dict[str, Any]] = []
    for r in trials:
        i = int(r["trial_index"])
        f = frames[frames["trial_index"] == i]
        if f.empty:
            out.append({"trial_index": i, "attempt": None, "problem": "no frames"})
            continue
        attempt = int(f["attempt"].max())
        f = f[f["attempt"] == attempt].sort_values("frame")
        t = f["flip_time_s"].to_numpy(float)
        values = f["value"].to_numpy(float)
        shown = (f["blanked"] == 0).fillna(False).to_numpy(bool)

        problems = []
        start = float(r["start_value"])
        if not abs(values[0] - start) <= value_tol:
            problems.append(f"first frame shows {values[0]:g}, start_value is {start:g}")
        enter_s = t[0] + float(r["response_time_s"])
        final = float(r["final_value"])
        if not (t <= enter_s + ENTER_SLACK_S).any():
            problems.append("no frame before Enter")
        else:
            # the value seen at the press, with the frames just either side of it
            seen = {float(values[shown & (t <= edge)][-1]) if (shown & (t <= edge)).any()
                    else start for edge in (enter_s - ENTER_SLACK_S, enter_s + ENTER_SLACK_S)}
            if not any(abs(v - final) <= value_tol for v in seen):
                shows = " or ".join(f"{v:g}" for v in sorted(seen))
                problems.append(f"the last stimulus frame before Enter shows {shows}, "
                                f"final_value is {final:g}")
        out += [{"trial_index": i, "attempt": attempt, "problem": p} for p in problems]
    return pd.DataFrame(out, columns=["trial_index", "attempt", "problem"])


__all__ = ["ENTER_SLACK_S", "FRAME_INT_COLUMNS", "decision_age_us", "draw_latency_ms",
           "final_value_violations", "gaze_to_flip_ms", "latency_summary", "read_frame_log",
           "trial_quality", "unblanked_violations", "unchecked_ages"]
