"""The paper's result figures with matplotlib (Agg, no display): the three calibration panels
(section 5.3, Figure "calibration_results"), the per-scene validation plot (section 6.1, Figure
"validation", right) and the sampling-rate reduction bars (section 6.3, Figure
"kernels_density", right), and the gaze-to-flip latency per session. Error bars are SEMs across
participants, as in the paper; each figure says so, with n, under its panels. f_e, s_k and s_f
are dimensionless (their axes say so). Each figure is written as PNG and PDF.

Every figure is laid out by matplotlib's constrained layout, its caption a ``supxlabel`` that
the layout makes room for, long titles and captions wrapped to the figure's width, tick labels
horizontal or vertical (never slanted, whose boxes would cross), and saved as laid out (no
``bbox_inches="tight"``, which would grow the canvas around a text outside it):
:func:`text_problems` finds a text that leaves the canvas or overlaps another, and the tests run
it over every figure the analysis makes.
"""

from __future__ import annotations

import inspect
import textwrap
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.text import Text
from matplotlib.transforms import Bbox

from fovexp.results.calibration import Calibration

from .validation import ValidationResult

# The paper's validation plot: contrast blue, ours orange.
METHOD_COLOURS = {"contrast": "tab:blue", "ours": "tab:orange", "foveated": "tab:gray"}


#: a character's mean width as a fraction of the font size (DejaVu Sans, matplotlib's
#: default; wide enough for capitals and digits): what wrapping a text to a width assumes
CHAR_WIDTH_EM = 0.62
#: a caption's font size (pt): matplotlib's "small" at its default 10 pt
CAPTION_PT = 8.33
#: an axes title's font size (pt): matplotlib's "large"
TITLE_PT = 12.0


def _n_text(n: object) -> str:
    """``n = 4`` or ``n = 3-4`` (participants per point)."""
    vals = sorted({int(v) for v in np.atleast_1d(np.asarray(n, dtype=float)) if np.isfinite(v)})
    if not vals:
        return "n = 0"
    return f"n = {vals[0]}" if len(vals) == 1 else f"n = {vals[0]}-{vals[-1]}"


def _figure(width_in: float, height_in: float) -> Figure:
    return Figure(figsize=(width_in, height_in), layout="constrained")


def _wrap(text: str, width_in: float, size_pt: float) -> str:
    """``text`` broken into lines no wider than ``width_in`` at ``size_pt``."""
    chars = max(10, int(width_in * 72.0 / (CHAR_WIDTH_EM * size_pt)))
    return "\n".join(textwrap.wrap(text, chars)) or text


def _title(ax: object, fig: Figure, text: str, share: float = 1.0) -> None:
    """An axes title wrapped to the axes' share of the figure's width (less its labels)."""
    width = 0.8 * share * fig.get_figwidth()
    ax.set_title(_wrap(text, width, TITLE_PT))  # type: ignore[attr-defined]


def _caption(fig: Figure, text: str) -> None:
    """The figure's caption under its panels, wrapped to its width (the layout keeps room)."""
    fig.supxlabel(_wrap(text, 0.95 * fig.get_figwidth(), CAPTION_PT), fontsize=CAPTION_PT)


def _sem_caption(fig: Figure, n: object, what: str = "participants") -> None:
    _caption(fig, f"Error bars: SEM across {what} ({_n_text(n)} per point).")


def _save(fig: Figure, stem: Path) -> list[Path]:
    # A Figure with its own Agg canvas: no pyplot state, no display needed.
    FigureCanvasAgg(fig)
    stem.parent.mkdir(parents=True, exist_ok=True)
    paths = [stem.with_suffix(".png"), stem.with_suffix(".pdf")]
    fig.savefig(paths[0], dpi=150)
    fig.savefig(paths[1])
    return paths


def _drawn_texts(fig: Figure) -> list[Text]:
    """The texts ``fig`` draws: its own (suptitle, caption), and per axes its titles, axis
    labels, offset texts, the labels of the ticks within its view, its legend's and its own
    texts; those that are visible and not empty."""
    out: list[Text] = list(fig.texts)
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            lo, hi = sorted(axis.get_view_interval())
            eps = 1e-9 * max(1.0, abs(hi - lo))
            for tick in [*axis.get_major_ticks(), *axis.get_minor_ticks()]:
                if lo - eps <= tick.get_loc() <= hi + eps:
                    out += [tick.label1, tick.label2]
            out += [axis.label, axis.get_offset_text()]
        out += [ax.title, ax._left_title, ax._right_title]  # set_title(loc=...)
        legend = ax.get_legend()
        if legend is not None:
            out += [*legend.get_texts(), legend.get_title()]
        out += list(ax.texts)
    seen: set[int] = set()
    texts = []
    for t in out:
        if id(t) in seen or not t.get_visible() or not t.get_text().strip():
            continue
        seen.add(id(t))
        texts.append(t)
    return texts


def text_problems(fig: Figure, tolerance_px: float = 0.5) -> list[str]:
    """What is wrong with the texts of ``fig`` as laid out and drawn: a text whose box leaves
    the canvas, and two texts whose boxes overlap (by more than ``tolerance_px`` each way).
    Empty when there is nothing. Boxes are axis-aligned, exact for the horizontal and vertical
    texts the figures here use."""
    if fig.canvas is None or not isinstance(fig.canvas, FigureCanvasAgg):
        FigureCanvasAgg(fig)
    renderer = fig.canvas.get_renderer()  # type: ignore[attr-defined]
    fig.draw(renderer)  # runs the layout
    canvas = Bbox.from_bounds(0, 0, fig.bbox.width, fig.bbox.height)
    boxes = [(t, t.get_window_extent(renderer)) for t in _drawn_texts(fig)]
    problems = []
    tol = tolerance_px
    for t, b in boxes:
        if (b.x0 < canvas.x0 - tol or b.y0 < canvas.y0 - tol or b.x1 > canvas.x1 + tol
                or b.y1 > canvas.y1 + tol):
            problems.append(f"{t.get_text()!r} leaves the canvas ({b.bounds} vs "
                            f"{canvas.bounds})")
    for i, (t, b) in enumerate(boxes):
        for u, c in boxes[i + 1:]:
            w = min(b.x1, c.x1) - max(b.x0, c.x0)
            h = min(b.y1, c.y1) - max(b.y0, c.y0)
            if w > tol and h > tol:
                problems.append(f"{t.get_text()!r} overlaps {u.get_text()!r}")
    return problems


def calibration_figure(calib: Calibration, stem: Path) -> list[Path]:
    """Three panels: f_e per blur-rate; s_k against s_f per blur-rate (with the fitted lines);
    the final (s_f, s_k) per blur-rate."""
    fig = _figure(12, 4.2)
    ax1, ax2, ax3 = fig.subplots(1, 3)
    fe = calib.fe
    ax1.errorbar(fe["blur_rate"], fe["mean"], yerr=fe["sem"], marker="o", capsize=3)
    ax1.set_xlabel("blur-rate (arcmin/deg)")
    ax1.set_ylabel("$f_e$ (dimensionless)")
    _title(ax1, fig, "Contrast enhancement $f_e$", 1 / 3)
    for i, (br, grp) in enumerate(calib.sk.groupby("blur_rate", sort=True)):
        colour = f"C{i}"
        ax2.errorbar(grp["s_f"], grp["mean"], yerr=grp["sem"], marker="o", capsize=3,
                     color=colour, linestyle="none", label=f"blur-rate {br:g} arcmin/deg")
        x = np.linspace(grp["s_f"].min(), grp["s_f"].max(), 50)
        ax2.plot(x, calib.lines[float(br)](x), color=colour, linestyle="--", linewidth=1)
    ax2.set_xlabel("$s_f$ (dimensionless)")
    ax2.set_ylabel("$s_k$ (dimensionless)")
    _title(ax2, fig, "Amplitude $s_k$ per $s_f$ (dashed: fit)", 1 / 3)
    ax2.legend(fontsize="small")
    sf = calib.sf
    for i, (_, r) in enumerate(sf.iterrows()):
        ax3.errorbar(r["s_f"], r["s_k"], xerr=r["s_f_sem"], yerr=r["s_k_sem"], marker="o",
                     capsize=3, color=f"C{i}",
                     label=f"blur-rate {r['blur_rate']:g} arcmin/deg")
    ax3.set_xlabel("final $s_f$ (dimensionless)")
    ax3.set_ylabel("final $s_k$ (dimensionless)")
    _title(ax3, fig, "Final $s_k$ and $s_f$", 1 / 3)
    ax3.legend(fontsize="small")
    _sem_caption(fig, np.concatenate([fe["n"], calib.sk["n"], sf["n"]]))
    return _save(fig, stem)


def validation_figure(result: ValidationResult, stem: Path) -> list[Path]:
    """Mean blur-rate per scene, one line per method, SEM error bars."""
    s = result.summary
    scenes = sorted(s["image"].unique())
    x = np.arange(len(scenes))
    fig = _figure(max(5.0, 0.45 * len(scenes) + 2), 4.4)
    ax = fig.subplots()
    for method, grp in s.groupby("method", sort=True):
        grp = grp.set_index("image").reindex(scenes)
        ax.errorbar(x, grp["mean"], yerr=grp["sem"], marker="o", capsize=3, label=str(method),
                    color=METHOD_COLOURS.get(str(method)))
    ax.set_xticks(x)
    ax.set_xticklabels(scenes, rotation=90)
    ax.set_xlabel("scene")
    ax.set_ylabel("selected blur-rate (arcmin/deg)")
    _title(ax, fig, f"{result.experiment}: highest blur-rate without visible foveation")
    ax.legend(title="method", fontsize="small")
    _sem_caption(fig, s["n"])
    return _save(fig, stem)


def sampling_figure(result: ValidationResult, stem: Path) -> list[Path]:
    """Estimated sampling-rate reduction of ours over contrast, per scene and overall (%)."""
    s = result.sampling
    fig = _figure(max(5.0, 0.45 * len(s) + 2), 4.2)
    ax = fig.subplots()
    colours = ["tab:gray" if sc == "all scenes" else "tab:orange" for sc in s["scope"]]
    ax.bar(np.arange(len(s)), s["reduction_pct"], color=colours)
    ax.set_xticks(np.arange(len(s)))
    ax.set_xticklabels(s["scope"], rotation=90)
    ax.axhline(0, color="black", linewidth=0.8)
    ax.set_ylabel("sampling-rate reduction (%)")
    _title(ax, fig, f"{result.experiment}: ours vs contrast (section 6.3)")
    _caption(fig, "1 - blur-rate(contrast) / blur-rate(ours), from the means across "
             "participants; no error bars.")
    return _save(fig, stem)


def latency_figure(latency_ms: dict[str, np.ndarray], stem: Path) -> list[Path]:
    """Box plots of the gaze-to-flip latency per session, one row each, labelled horizontally
    (whiskers: 5th and 95th percentiles; :mod:`fovexp.analysis.latency`)."""
    names = list(latency_ms)
    fig = _figure(7.0, max(3.0, 0.28 * len(names) + 2.0))
    ax = fig.subplots()
    # matplotlib 3.10 names it orientation; before, vert=False
    horizontal = ({"orientation": "horizontal"}
                  if "orientation" in inspect.signature(ax.boxplot).parameters
                  else {"vert": False})
    ax.boxplot([latency_ms[n] for n in names], whis=(5, 95), showfliers=False, **horizontal)
    ax.set_yticks(range(1, len(names) + 1))
    ax.set_yticklabels(names, fontsize=7)
    ax.invert_yaxis()  # the first session on top, as in the report's table
    ax.set_ylabel("session (experiment/participant/session)")
    ax.set_xlabel("gaze-to-flip latency (ms)")
    _title(ax, fig, "Newest gaze sample to flip, per session")
    _caption(fig, "Boxes: quartiles and median of the session's frames; whiskers: 5th and 95th "
             "percentiles.")
    return _save(fig, stem)
