"""Gaze-to-flip latency and the blanking rule, per session, from the frame logs (docs/LOGS.md).

Paper section 5.1 hides the stimulus "whenever participants' gaze position moved outside a
small circular region with radius 1.25 deg"; how late a frame can react to the gaze is the
time from the newest gaze sample its decision used to its flip. Every frame log names both on
the tracker's clock, and the decision too (:mod:`fovexp.results.frames`), so each session
included in the analysis gets the latency's distribution (median, 95th percentile, maximum),
the frames' own draw latency (decision to flip), its dropped frames, and a count of frames
drawn with the stimulus against the rule (:class:`fovexp.results.blanking.BlankingRule`,
checked exactly: 0 in a valid session).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

from fovexp.results.blanking import BLANKING_RADIUS_DEG, GAZE_TIMEOUT_S, BlankingRule
from fovexp.results.frames import (
    gaze_to_flip_ms,
    latency_summary,
    read_frame_log,
    unblanked_violations,
    unchecked_ages,
)
from fovexp.results.gating import read_gaze_log, session_gating
from fovexp.results.loading import Dataset

COLUMNS = ("experiment", "participant", "session", "tracker", "frames", "with_gaze",
           "median_ms", "p95_ms", "max_ms", "draw_median_ms", "draw_p95_ms", "dropped_pct",
           "rule_violations")
#: What the gaze log adds (:func:`fovexp.results.gating.session_gating`): the delivery
#: latency, the tracker's cost, the rule against the newest sample measured, and, where the
#: simulated eye's truth is logged, the stimulus time while the eye was outside the window.
GATING_COLUMNS = ("experiment", "participant", "session", "delivery_p50_ms", "delivery_p95_ms",
                  "delivery_max_ms", "tracker_cost_frames", "stamped_violations", "outside_ms",
                  "outside_fraction", "excursion_max_ms")


def _session_rule(folder: Path, session: str) -> BlankingRule:
    """The blanking rule of a session: the radius and gaze timeout of its protocol copy in the
    session file; the rule's defaults where it lacks them."""
    radius, timeout = BLANKING_RADIUS_DEG, GAZE_TIMEOUT_S
    try:
        info = json.loads((folder / f"session-{session}.json").read_text())
        fix = (yaml.safe_load(info.get("protocol") or "") or {}).get("fixation") or {}
        radius = float(fix.get("radius_deg", radius))
        timeout = float(fix.get("gaze_timeout_s", timeout))
    except (OSError, ValueError, yaml.YAMLError, AttributeError, TypeError):
        pass
    return BlankingRule(radius, timeout)


def session_latency(data: Dataset) -> tuple[pd.DataFrame, dict[str, np.ndarray], list[str]]:
    """Per session included in ``data``: the latency summary (:data:`COLUMNS`), the per-frame
    latencies (ms) by session, and notes (sessions without a frame log, one written before it
    named the gaze sample, or before it named the decision: then the first frames' sample age
    cannot be checked)."""
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
        bad = unblanked_violations(frames, _session_rule(folder, sid))
        unchecked = unchecked_ages(frames)
        if unchecked:
            notes.append(f"{exp}/{pid}: session {sid}: the frame log is older than the "
                         f"decision's time (docs/LOGS.md, format version 1): {unchecked} "
                         "first frame(s) of attempts could not be checked for their sample's "
                         "age, the other frames only against the previous flip")
        rows.append({"experiment": exp, "participant": pid, "session": sid,
                     "tracker": ", ".join(sorted(set(grp["tracker"].astype(str)))),
                     "frames": summary["frames"], "with_gaze": summary["with_gaze"],
                     "median_ms": summary["median_ms"], "p95_ms": summary["p95_ms"],
                     "max_ms": summary["max_ms"], "draw_median_ms": summary["draw_median_ms"],
                     "draw_p95_ms": summary["draw_p95_ms"],
                     "dropped_pct": 100 * summary["dropped_fraction"],
                     "rule_violations": len(bad)})
        lat[f"{exp}/{pid}/{sid}"] = gaze_to_flip_ms(frames).dropna().to_numpy()
    return pd.DataFrame(rows, columns=list(COLUMNS)), lat, notes


def session_gating_table(data: Dataset) -> tuple[pd.DataFrame, list[str]]:
    """Per session included in ``data`` with a frame and a gaze log: what the blanking did
    against the eye (:data:`GATING_COLUMNS`, :mod:`fovexp.results.gating`), and notes
    (sessions whose gaze log predates the received times)."""
    rows, notes = [], []
    t = data.trials
    if t.empty:
        return pd.DataFrame(columns=list(GATING_COLUMNS)), notes
    for (exp, pid, sid), grp in t.groupby(["experiment", "participant", "session"], sort=True):
        folder = Path(str(grp["file"].iloc[0])).parent
        fpath, gpath = folder / f"frames-{sid}.csv", folder / f"gaze-{sid}.csv"
        if not (fpath.exists() and gpath.exists()):
            continue
        gaze = read_gaze_log(gpath)
        if gaze["received_system_time_us"].isna().all():
            notes.append(f"{exp}/{pid}: session {sid}: the gaze log is older than the received "
                         "times (docs/LOGS.md): no delivery latency or tracker's cost")
            continue
        fig = session_gating(read_frame_log(fpath), gaze, _session_rule(folder, sid))
        rows.append({"experiment": exp, "participant": pid, "session": sid, **fig})
    return pd.DataFrame(rows, columns=list(GATING_COLUMNS)), notes
