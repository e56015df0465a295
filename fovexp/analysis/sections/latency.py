"""The gaze-to-flip latency and blanking section (paper section 5.1; the frame logs)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from .. import figures as figs
from ..latency import session_latency
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
    return ["\n".join(parts)]
