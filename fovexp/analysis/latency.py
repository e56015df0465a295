"""Gaze-to-flip latency and the blanking rule, per session, from the frame logs (docs/LOGS.md).

Paper section 5.1 hides the stimulus "whenever participants' gaze position moved outside a
small circular region with radius 1.25 deg"; how late a frame can react to the gaze is the
time from the newest gaze sample its decision used to its flip. Every frame log names both on
the tracker's clock (:mod:`fovexp.results.frames`), so each session included in the analysis
gets the latency's distribution (median, 95th percentile, maximum), its dropped frames, and a
count of frames drawn with the stimulus against the rule (0 in a valid session).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

from fovexp.results.frames import (
    gaze_to_flip_ms,
    latency_summary,
    read_frame_log,
    unblanked_violations,
)
from fovexp.results.loading import Dataset

#: Paper section 5.1: the blanking radius, and the runner's default gaze timeout (s), used
#: where a session file does not give the protocol's.
DEFAULT_RADIUS_DEG = 1.25
DEFAULT_GAZE_TIMEOUT_S = 0.05
#: An attempt's first frame (no previous flip in the log) may show a sample older than the
#: gaze timeout by up to this many refresh periods: the drawing and the wait for the blank.
FIRST_FRAME_PERIODS = 2.0

COLUMNS = ("experiment", "participant", "session", "tracker", "frames", "with_gaze",
           "median_ms", "p95_ms", "max_ms", "dropped_pct", "rule_violations")


def _session_settings(folder: Path, session: str) -> tuple[float, float, float]:
    """Blanking radius (deg), gaze timeout (s) and refresh rate (Hz) of a session, from its
    session file (the protocol copy, the display check); defaults where it lacks them."""
    radius, timeout, hz = DEFAULT_RADIUS_DEG, DEFAULT_GAZE_TIMEOUT_S, 60.0
    try:
        info = json.loads((folder / f"session-{session}.json").read_text())
    except (OSError, ValueError):
        return radius, timeout, hz
    try:
        fix = (yaml.safe_load(info.get("protocol") or "") or {}).get("fixation") or {}
        radius = float(fix.get("radius_deg", radius))
        timeout = float(fix.get("gaze_timeout_s", timeout))
    except (yaml.YAMLError, AttributeError, TypeError, ValueError):
        pass
    check = info.get("display_check") or {}
    for key in ("refresh_hz", "measured_refresh_hz", "profile_refresh_hz"):
        if isinstance(check.get(key), (int, float)) and check[key] > 0:
            hz = float(check[key])
            break
    return radius, timeout, hz


def session_latency(data: Dataset) -> tuple[pd.DataFrame, dict[str, np.ndarray], list[str]]:
    """Per session included in ``data``: the latency summary (:data:`COLUMNS`), the per-frame
    latencies (ms) by session, and notes (sessions without a frame log, or one written before
    it named the gaze sample)."""
    rows, lat, notes = [], {}, []
    t = data.trials
    if t.empty:
        return pd.DataFrame(columns=list(COLUMNS)), lat, notes
    keys = t.groupby(["experiment", "participant", "session"], sort=True)
    for (exp, pid, sid), grp in keys:
        folder = Path(str(grp["file"].iloc[0])).parent
        path = folder / f"frames-{sid}.csv"
        if not path.exists():
            notes.append(f"{exp}/{pid}: session {sid} has no frame log")
            continue
        frames = read_frame_log(path)
        summary = latency_summary(frames)
        if summary["with_gaze"] == 0:
            notes.append(f"{exp}/{pid}: session {sid}: the frame log names no gaze samples "
                         "(written before the latency columns)")
            continue
        radius, timeout, hz = _session_settings(folder, sid)
        bad = unblanked_violations(frames, radius, timeout, FIRST_FRAME_PERIODS / hz)
        rows.append({"experiment": exp, "participant": pid, "session": sid,
                     "tracker": ", ".join(sorted(set(grp["tracker"].astype(str)))),
                     "frames": summary["frames"], "with_gaze": summary["with_gaze"],
                     "median_ms": summary["median_ms"], "p95_ms": summary["p95_ms"],
                     "max_ms": summary["max_ms"],
                     "dropped_pct": 100 * summary["dropped_fraction"],
                     "rule_violations": len(bad)})
        lat[f"{exp}/{pid}/{sid}"] = gaze_to_flip_ms(frames).dropna().to_numpy()
    return pd.DataFrame(rows, columns=list(COLUMNS)), lat, notes
