"""The gaze-to-flip latency and blanking section (paper section 5.1; the frame logs)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from .. import figures as figs
from ..latency import session_gating_table, session_latency
from .common import md_table, write_csv

if TYPE_CHECKING:
    from ..state import Analysis


def latency_section(ana: Analysis) -> list[str]:
    """The gaze-to-flip latency per session (:mod:`fovexp.analysis.latency`)."""
    table, lat, notes = session_latency(ana.data)
    write_csv(table, ana.tables / "latency.csv", ana.files)
    parts = ["## Gaze-to-flip latency and blanking (section 5.1)\n",
             "Per session, from its frame log: the time from the newest gaze sample a frame's "
             "blanking decision used to the frame's flip, on the tracker's clock (median, 95th "
             "percentile, maximum); the frame's own draw latency, from its decision to its flip "
             "(`draw_median_ms`, `draw_p95_ms`); the dropped frames; and the frames drawn with "
             "the stimulus although, when the frame was decided, the newest sample was older "
             "than the gaze timeout, invalid, or outside the blanking radius "
             "(`rule_violations`, checked exactly for every frame: 0 in a valid session).\n"]
    if len(table):
        parts.append(md_table(table, 2, units={"n": "participants"}))
        if ana.figures and lat:
            ana.files += figs.latency_figure(lat, ana.fig_dir / "latency")
            parts.append("![Gaze-to-flip latency](figures/latency.png)\n")
    else:
        parts.append("No frame log with gaze samples.\n")
    parts += [f"Note: {n}\n" for n in notes]
    parts += gating_part(ana)
    return ["\n".join(parts)]


def gating_part(ana: Analysis) -> list[str]:
    """What the blanking did against the eye, per session (:mod:`fovexp.results.gating`)."""
    table, notes = session_gating_table(ana.data)
    write_csv(table, ana.tables / "gating.csv", ana.files)
    parts = ["### The blanking against the eye (issue 28)\n",
             "From the gaze log's received times: the tracker's delivery latency (received "
             "minus measured; `delivery_*_ms`); the stimulus frames decided while a sample "
             "already measured but not yet received was outside the window or invalid "
             "(`tracker_cost_frames`: what the latency let through); the rule checked against "
             "the newest sample *measured* before each decision (`stamped_violations`: 0 when "
             "delivery is instant). Where the simulated eye's truth is logged (dry runs): the "
             "stimulus time on screen while the eye was outside the window (`outside_ms`, and "
             "as a fraction of the stimulus time), and the longest of it after one excursion "
             "of the eye (`excursion_max_ms`; compare 6 ms, McConkie and Loschky 2002, and "
             "60 ms, Loschky and Wolverton 2007, docs/EXPERIMENT.md).\n"]
    if len(table):
        parts.append(md_table(table, 2))
    else:
        parts.append("No session with a frame log and a gaze log with received times.\n")
    parts += [f"Note: {n}\n" for n in notes]
    return parts
