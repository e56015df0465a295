"""What the gaze-contingent blanking did against the eye, from a session's gaze and frame logs
(issue 28; docs/EXPERIMENT.md, "Gaze truth").

The runner proves from its frame log that each stimulus frame was decided on a valid sample
inside the window, the sample it had (:func:`fovexp.results.frames.unblanked_violations`).
Three measures go further, all on the tracker's system clock:

- **delivery latency**: when the runner received each sample (``received_system_time_us``)
  minus when the tracker measured it (``system_time_us``);
- **the tracker's cost**: stimulus frames decided while a sample already measured, but not yet
  received, was outside the window or invalid (:func:`tracker_cost_frames`); and, as an
  independent check of the rule, the stimulus frames the newest sample *measured* before the
  decision would have blanked (:func:`stamped_violations`: 0 when delivery is instant);
- **the eye's truth** (dry runs, where the simulated eye's true eccentricity is logged,
  ``true_ecc_deg``): the time the stimulus was on screen while the eye was outside the window,
  the flips taken as when the light changed (:func:`stimulus_outside`), per trial and per
  excursion of the eye out of the window (:func:`excursion_exposure`).

Thresholds a lab can read these against: a display change less than about 6 ms after a saccade
ends goes unnoticed (McConkie and Loschky 2002), and, for the blur Loschky and Wolverton (2007)
tested, a change up to 60 ms after a saccade is not more detectable.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from fovexp import FovexpError

from .blanking import BlankingRule
from .format import GAZE_COLUMNS
from .frames import read_complete_lines

#: McConkie and Loschky (2002): a change this soon after a saccade's end goes unnoticed (ms).
UNNOTICED_AFTER_SACCADE_MS = 6.0
#: Loschky and Wolverton (2007): a blur change up to this long after a saccade is not more
#: detectable (ms).
BLUR_TOLERATED_AFTER_SACCADE_MS = 60.0

_GAZE_INT = ("trial_index", "attempt", "device_time_us", "system_time_us",
             "received_system_time_us")


def read_gaze_log(path: str | Path) -> pd.DataFrame:
    """A gaze log (``gaze-<session>.csv``), typed, in the order written; a torn last line is
    dropped, columns missing from an older log are added empty. Raises :class:`FovexpError`
    naming the file when it cannot be read as one."""
    path = Path(path)
    raw = read_complete_lines(path, "a gaze log")
    if "system_time_us" not in raw:
        raise FovexpError(f"{path}: not a gaze log (no system_time_us column)")
    out = pd.DataFrame(index=raw.index)
    for col in GAZE_COLUMNS:
        s = raw[col] if col in raw else pd.Series("", index=raw.index)
        if col in ("left_valid", "right_valid", "valid"):
            out[col] = s.isin(("1", "True", "true"))
            continue
        num = pd.to_numeric(s, errors="coerce")
        out[col] = num.round().astype("Int64") if col in _GAZE_INT else num
    return out


def delivery_latency_ms(gaze: pd.DataFrame) -> np.ndarray:
    """Each sample's delivery latency (ms): received minus measured; samples without a
    received time (logs written before it existed) are left out."""
    rec = gaze["received_system_time_us"].astype("Float64")
    sys_ = gaze["system_time_us"].astype("Float64")
    d = (rec - sys_).dropna()
    return d.to_numpy(dtype=float) / 1e3


def _ecc(gaze: pd.DataFrame) -> np.ndarray:
    """Each sample's eccentricity (deg), NaN for an invalid one (the rule's reading)."""
    ecc = gaze["eccentricity_deg"].to_numpy(dtype=float)
    return np.where(gaze["valid"].to_numpy(dtype=bool), ecc, np.nan)


def _bad(gaze: pd.DataFrame, rule: BlankingRule) -> np.ndarray:
    """Samples the rule would blank on, however fresh (invalid, or outside the radius)."""
    return ~rule.inside(_ecc(gaze))


def _stimulus_frames(frames: pd.DataFrame) -> pd.DataFrame:
    shown = frames[(frames["blanked"] == 0) & frames["decide_system_time_us"].notna()]
    return shown


def tracker_cost_frames(frames: pd.DataFrame, gaze: pd.DataFrame,
                        rule: BlankingRule | None = None) -> int:
    """Stimulus frames decided while a sample already measured (stamped at or before the
    decision) but not yet received (received after it) was outside the window or invalid:
    frames the delivery latency let through, whatever the runner did."""
    rule = rule or BlankingRule()
    shown = _stimulus_frames(frames)
    g = gaze[gaze["received_system_time_us"].notna()]
    if shown.empty or g.empty:
        return 0
    bad = _bad(g, rule)
    start = g["system_time_us"].to_numpy(dtype=np.int64)[bad]
    end = g["received_system_time_us"].to_numpy(dtype=np.int64)[bad]
    keep = end > start
    start, end = np.sort(start[keep]), np.sort(end[keep])
    d = shown["decide_system_time_us"].to_numpy(dtype=np.int64)
    # a bad sample is pending at d when start <= d < end
    pending = np.searchsorted(start, d, side="right") - np.searchsorted(end, d, side="right")
    return int(np.count_nonzero(pending > 0))


def stamped_violations(frames: pd.DataFrame, gaze: pd.DataFrame,
                       rule: BlankingRule | None = None) -> int:
    """The rule checked against the newest sample *measured* at or before each stimulus frame's
    decision (not the newest received, which the frame log names): stimulus frames that sample
    would have blanked (too old, invalid, outside). 0 when samples reach the runner as they
    are measured; above 0, the tracker's delivery latency's cost."""
    rule = rule or BlankingRule()
    shown = _stimulus_frames(frames)
    if shown.empty or gaze.empty:
        return 0
    order = np.argsort(gaze["system_time_us"].to_numpy(dtype=np.int64), kind="stable")
    g = gaze.iloc[order]
    stamps = g["system_time_us"].to_numpy(dtype=np.int64)
    ecc = _ecc(g)
    d = shown["decide_system_time_us"].to_numpy(dtype=np.int64)
    k = np.searchsorted(stamps, d, side="right") - 1
    kk = np.clip(k, 0, None)
    allowed = (k >= 0) & rule.allows(d - stamps[kk], ecc[kk])
    return int(np.count_nonzero(~allowed))


def _outside_cumulative(gaze: pd.DataFrame, radius_deg: float
                        ) -> tuple[np.ndarray, np.ndarray] | None:
    """The cumulative time (us) the true eye spent outside the window, at each sample's time
    (the truth held from one sample to the next)."""
    g = gaze[gaze["true_ecc_deg"].notna()]
    if g.empty:
        return None
    t = g["system_time_us"].to_numpy(dtype=np.float64)
    order = np.argsort(t, kind="stable")
    t = t[order]
    out = (g["true_ecc_deg"].to_numpy(dtype=float)[order] > radius_deg).astype(np.float64)
    cum = np.concatenate([[0.0], np.cumsum(out[:-1] * np.diff(t))])
    return t, cum


def _frame_spans(frames: pd.DataFrame) -> pd.DataFrame:
    """Each frame's time on screen (us, tracker clock): from its flip to the next frame's flip
    in the same attempt; the attempt's last frame for the attempt's median interval."""
    f = frames[frames["flip_system_time_us"].notna()].copy()
    f = f.sort_values(["trial_index", "attempt", "frame"])
    flip = f["flip_system_time_us"].astype("Float64")
    nxt = flip.groupby([f["trial_index"], f["attempt"]]).shift(-1)
    period = flip.groupby([f["trial_index"], f["attempt"]]).transform(
        lambda s: s.diff().median())
    f["start_us"] = flip.astype(float)
    f["end_us"] = nxt.fillna(flip + period).astype(float)
    return f


def stimulus_outside(frames: pd.DataFrame, gaze: pd.DataFrame,
                     rule: BlankingRule | None = None) -> pd.DataFrame:
    """Per trial and attempt: the stimulus time on screen (ms), and the part of it while the
    eye's truth was outside the window (``outside_ms``, ``outside_fraction``). Empty when the
    gaze log carries no truth (a real tracker)."""
    rule = rule or BlankingRule()
    cols = ["trial_index", "attempt", "stimulus_ms", "outside_ms", "outside_fraction"]
    cum = _outside_cumulative(gaze, rule.radius_deg)
    if cum is None or frames.empty:
        return pd.DataFrame(columns=cols)
    t, c = cum
    f = _frame_spans(frames)
    f = f[f["blanked"] == 0]
    if f.empty:
        return pd.DataFrame(columns=cols)
    a, b = f["start_us"].to_numpy(), f["end_us"].to_numpy()
    f = f.assign(stim=(b - a) / 1e3, out=(np.interp(b, t, c) - np.interp(a, t, c)) / 1e3)
    per = f.groupby(["trial_index", "attempt"], sort=True)[["stim", "out"]].sum()
    per = per.reset_index().rename(columns={"stim": "stimulus_ms", "out": "outside_ms"})
    per["outside_fraction"] = per["outside_ms"] / per["stimulus_ms"].where(
        per["stimulus_ms"] > 0)
    return per[cols]


def excursion_exposure(frames: pd.DataFrame, gaze: pd.DataFrame,
                       rule: BlankingRule | None = None) -> np.ndarray:
    """For each excursion of the true eye out of the window during an attempt (from the sample
    it is first outside to the sample it is back): the stimulus time on screen after it left
    (ms). This is the stricter of the two marks a saccade offers: the eye leaves the window
    before its saccade lands."""
    rule = rule or BlankingRule()
    g = gaze[gaze["true_ecc_deg"].notna() & gaze["trial_index"].notna()]
    if g.empty or frames.empty:
        return np.zeros(0)
    f = _frame_spans(frames)
    f = f[f["blanked"] == 0]
    a, b = f["start_us"].to_numpy(), f["end_us"].to_numpy()
    out = []
    for _, gg in g.groupby(["trial_index", "attempt"], sort=True):
        t = gg["system_time_us"].to_numpy(dtype=np.float64)
        o = gg["true_ecc_deg"].to_numpy(dtype=float) > rule.radius_deg
        edges = np.flatnonzero(np.diff(np.concatenate([[0], o.astype(np.int8), [0]])))
        for s, e in zip(edges[::2], edges[1::2], strict=True):
            t0 = t[s]
            t1 = t[e] if e < len(t) else t[-1]
            overlap = np.clip(np.minimum(b, t1) - np.maximum(a, t0), 0, None)
            out.append(float(overlap.sum()) / 1e3)
    return np.asarray(out)


def session_gating(frames: pd.DataFrame, gaze: pd.DataFrame,
                   rule: BlankingRule | None = None) -> dict[str, float]:
    """One session's figures: delivery latency (p50, p95, max ms), the tracker's cost (frames),
    the stamped-sample check (frames), and where the truth is logged the stimulus time
    outside the window (ms and fraction of the stimulus time) and the largest exposure of one
    excursion (ms)."""
    rule = rule or BlankingRule()
    lat = delivery_latency_ms(gaze)
    nan = float("nan")
    out = {
        "delivery_p50_ms": float(np.median(lat)) if lat.size else nan,
        "delivery_p95_ms": float(np.percentile(lat, 95)) if lat.size else nan,
        "delivery_max_ms": float(lat.max()) if lat.size else nan,
        "tracker_cost_frames": float(tracker_cost_frames(frames, gaze, rule)),
        "stamped_violations": float(stamped_violations(frames, gaze, rule)),
        "outside_ms": nan, "outside_fraction": nan, "excursion_max_ms": nan,
    }
    per = stimulus_outside(frames, gaze, rule)
    if len(per):
        stim, outside = float(per["stimulus_ms"].sum()), float(per["outside_ms"].sum())
        out.update(outside_ms=outside, outside_fraction=outside / stim if stim else nan)
        ex = excursion_exposure(frames, gaze, rule)
        out["excursion_max_ms"] = float(ex.max()) if ex.size else 0.0
    return out


__all__ = ["BLUR_TOLERATED_AFTER_SACCADE_MS", "UNNOTICED_AFTER_SACCADE_MS",
           "delivery_latency_ms", "excursion_exposure", "read_gaze_log", "session_gating",
           "stamped_violations", "stimulus_outside", "tracker_cost_frames"]
