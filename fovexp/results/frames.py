"""The frame log (``frames-<session>.csv``, docs/LOGS.md) as data: what every stimulus frame
showed and what drove it.

Each frame names the newest gaze sample its blanking decision used (``gaze_system_time_us``,
``gaze_ecc_deg``) and its flip (``flip_system_time_us``), both on the tracker's system clock:
their difference is the frame's gaze-to-flip latency, and the blanking rule of paper section 5.1
("stimuli are hidden by rendering a black frame whenever participants' gaze position moved
outside a small circular region with radius 1.25 deg") can be checked from the log alone.
Logs written before these columns existed read with them empty.
"""

from __future__ import annotations

import io
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from fovexp import FovexpError

from .format import FRAME_COLUMNS

#: Integer columns of the frame log (nullable: empty fields are missing values).
FRAME_INT_COLUMNS = ("trial_index", "attempt", "frame", "dropped", "blanked",
                     "gaze_system_time_us", "flip_system_time_us")


def read_frame_log(path: str | Path) -> pd.DataFrame:
    """A frame log, typed, one row per frame; a torn last line (a kill mid-write) is dropped.
    Columns missing from an older log are added empty. Raises :class:`FovexpError` naming the
    file when it cannot be read as one."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise FovexpError(f"{path}: cannot read: {exc.strerror}") from None
    data = data[: data.rfind(b"\n") + 1]  # complete lines only
    try:
        frame = pd.read_csv(io.BytesIO(data), dtype=str, keep_default_na=False)
    except (ValueError, pd.errors.ParserError) as exc:
        raise FovexpError(f"{path}: not a frame log ({exc})") from None
    missing = [c for c in ("trial_index", "attempt", "frame", "blanked") if c not in frame]
    if missing:
        raise FovexpError(f"{path}: not a frame log (no {', '.join(missing)} column)")
    out = pd.DataFrame(index=frame.index)
    for col in FRAME_COLUMNS:
        raw = frame[col] if col in frame else pd.Series("", index=frame.index)
        num = pd.to_numeric(raw, errors="coerce")  # empty fields: missing
        out[col] = num.round().astype("Int64") if col in FRAME_INT_COLUMNS else num
    return out


def gaze_to_flip_ms(frames: pd.DataFrame) -> pd.Series:
    """Per frame: the flip's time minus that of the newest gaze sample its decision used (ms),
    on the tracker's clock; missing where a frame had no sample."""
    return (frames["flip_system_time_us"] - frames["gaze_system_time_us"]).astype(float) / 1e3


def latency_summary(frames: pd.DataFrame) -> dict[str, float]:
    """``frames`` (all frames), ``with_gaze`` (frames whose decision had a sample), the
    gaze-to-flip latency's ``median_ms``, ``p95_ms``, ``max_ms`` (NaN without any), and the
    share of ``dropped`` frames."""
    lat = gaze_to_flip_ms(frames).dropna().to_numpy()
    n = len(frames)
    return {
        "frames": n,
        "with_gaze": int(lat.size),
        "median_ms": float(np.median(lat)) if lat.size else float("nan"),
        "p95_ms": float(np.percentile(lat, 95)) if lat.size else float("nan"),
        "max_ms": float(lat.max()) if lat.size else float("nan"),
        "dropped_fraction": float(frames["dropped"].fillna(0).mean()) if n else float("nan"),
    }


def unblanked_violations(frames: pd.DataFrame, radius_deg: float, gaze_timeout_s: float,
                         first_frame_slack_s: float) -> pd.DataFrame:
    """Frames drawn with the stimulus (``blanked`` 0) that the blanking rule forbids: without a
    valid gaze sample (``gaze_ecc_deg`` empty), with one farther than ``radius_deg`` from the
    cross, or with one that was not recent when the frame was decided.

    "Recent" is checked exactly from the log: a frame is decided after the previous frame's
    flip, when its newest sample may be at most ``gaze_timeout_s`` old, so that sample cannot
    be older than the previous flip minus ``gaze_timeout_s``. An attempt's first frame has no
    previous flip in the log; its sample may be at most ``gaze_timeout_s`` plus
    ``first_frame_slack_s`` (drawing and waiting for the vertical blank) older than its own
    flip. Empty when the log keeps the rule."""
    f = frames.sort_values(["trial_index", "attempt", "frame"])
    prev_flip = f.groupby(["trial_index", "attempt"])["flip_system_time_us"].shift(1)
    timeout_us = 1e6 * gaze_timeout_s
    oldest_us = (prev_flip - timeout_us).where(
        prev_flip.notna(), f["flip_system_time_us"] - timeout_us - 1e6 * first_frame_slack_s)
    shown = f["blanked"] == 0
    gaze_us = f["gaze_system_time_us"]
    bad = shown & (f["gaze_ecc_deg"].isna() | (f["gaze_ecc_deg"] > radius_deg)
                   | gaze_us.isna() | (gaze_us.astype(float) < oldest_us.astype(float)))
    return f[bad.fillna(True)]


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


#: slack on the Enter time recomputed from the trial log (``response_time_s`` is rounded to
#: 0.1 ms; the flip times to 1 us)
ENTER_SLACK_S = 1e-4


def final_value_violations(frames: pd.DataFrame, trials: Iterable[Mapping[str, Any]],
                           value_tol: float = 1e-9) -> pd.DataFrame:
    """Trials whose frames contradict their row in the trial log: what is logged must be what
    was on screen (docs/LOGS.md). For each trial row (``trial_index``, ``start_value``,
    ``final_value``, ``response_time_s``), the frames of its last attempt (the confirmed one):
    the first shows ``start_value``; Enter came ``response_time_s`` after the first flip; the
    last frame flipped before Enter shows ``final_value`` (a render still pending at Enter is
    dropped, never shown); and no frame of the attempt was flipped after Enter (from the first
    flip after Enter only the cross is on screen). ``frames`` is one session's frame log
    (:func:`read_frame_log`), ``trials`` that session's rows. Returns one row per violation
    (``trial_index``, ``attempt``, ``problem``); empty when the logs keep the rule."""
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

        problems = []
        if not abs(values[0] - float(r["start_value"])) <= value_tol:
            problems.append(f"first frame shows {values[0]:g}, start_value is "
                            f"{float(r['start_value']):g}")
        enter_s = t[0] + float(r["response_time_s"])
        after = int((t > enter_s + ENTER_SLACK_S).sum())
        if after:
            problems.append(f"{after} frame(s) flipped after Enter")
        before = values[t <= enter_s + ENTER_SLACK_S]
        final = float(r["final_value"])
        if not before.size:
            problems.append("no frame before Enter")
        elif not abs(before[-1] - final) <= value_tol:
            problems.append(f"the last frame before Enter shows {before[-1]:g}, final_value "
                            f"is {final:g}")
        out += [{"trial_index": i, "attempt": attempt, "problem": p} for p in problems]
    return pd.DataFrame(out, columns=["trial_index", "attempt", "problem"])


__all__ = ["ENTER_SLACK_S", "FRAME_INT_COLUMNS", "final_value_violations", "gaze_to_flip_ms",
           "latency_summary", "read_frame_log", "trial_quality", "unblanked_violations"]
