"""The paper's result figures with matplotlib (Agg, no display): the three calibration panels
(section 5.3, Figure "calibration_results"), the per-scene validation plot (section 6.1, Figure
"validation", right) and the sampling-rate reduction bars (section 6.3, Figure
"kernels_density", right). Error bars are SEMs, as in the paper. Each figure is written as PNG
and PDF.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from fovexp.results.calibration import Calibration

from .validation import ValidationResult

# The paper's validation plot: contrast blue, ours orange.
METHOD_COLOURS = {"contrast": "tab:blue", "ours": "tab:orange", "foveated": "tab:gray"}


def _save(fig: Figure, stem: Path) -> list[Path]:
    # A Figure with its own Agg canvas: no pyplot state, no display needed.
    FigureCanvasAgg(fig)
    stem.parent.mkdir(parents=True, exist_ok=True)
    paths = [stem.with_suffix(".png"), stem.with_suffix(".pdf")]
    fig.savefig(paths[0], dpi=150, bbox_inches="tight")
    fig.savefig(paths[1], bbox_inches="tight")
    return paths


def calibration_figure(calib: Calibration, stem: Path) -> list[Path]:
    """Three panels: f_e per blur-rate; s_k against s_f per blur-rate (with the fitted lines);
    the final (s_f, s_k) per blur-rate."""
    fig = Figure(figsize=(12, 3.8))
    ax1, ax2, ax3 = fig.subplots(1, 3)
    fe = calib.fe
    ax1.errorbar(fe["blur_rate"], fe["mean"], yerr=fe["sem"], marker="o", capsize=3)
    ax1.set_xlabel("blur-rate (arcmin/deg)")
    ax1.set_ylabel("$f_e$")
    ax1.set_title("Contrast enhancement $f_e$")
    for i, (br, grp) in enumerate(calib.sk.groupby("blur_rate", sort=True)):
        colour = f"C{i}"
        ax2.errorbar(grp["s_f"], grp["mean"], yerr=grp["sem"], marker="o", capsize=3,
                     color=colour, linestyle="none", label=f"blur-rate {br:g}")
        x = np.linspace(grp["s_f"].min(), grp["s_f"].max(), 50)
        ax2.plot(x, calib.lines[float(br)](x), color=colour, linestyle="--", linewidth=1)
    ax2.set_xlabel("$s_f$")
    ax2.set_ylabel("$s_k$")
    ax2.set_title("Amplitude $s_k$ per $s_f$ (dashed: fit)")
    ax2.legend(fontsize="small")
    sf = calib.sf
    for i, (_, r) in enumerate(sf.iterrows()):
        ax3.errorbar(r["s_f"], r["s_k"], xerr=r["s_f_sem"], yerr=r["s_k_sem"], marker="o",
                     capsize=3, color=f"C{i}", label=f"blur-rate {r['blur_rate']:g}")
    ax3.set_xlabel("final $s_f$")
    ax3.set_ylabel("final $s_k$")
    ax3.set_title("Final $s_k$ and $s_f$")
    ax3.legend(fontsize="small")
    fig.tight_layout()
    return _save(fig, stem)


def validation_figure(result: ValidationResult, stem: Path) -> list[Path]:
    """Mean blur-rate per scene, one line per method, SEM error bars."""
    s = result.summary
    scenes = sorted(s["image"].unique())
    x = np.arange(len(scenes))
    fig = Figure(figsize=(max(5.0, 0.6 * len(scenes) + 2), 3.8))
    ax = fig.subplots()
    for method, grp in s.groupby("method", sort=True):
        grp = grp.set_index("image").reindex(scenes)
        ax.errorbar(x, grp["mean"], yerr=grp["sem"], marker="o", capsize=3, label=str(method),
                    color=METHOD_COLOURS.get(str(method)))
    ax.set_xticks(x)
    ax.set_xticklabels(scenes, rotation=45, ha="right")
    ax.set_xlabel("scene")
    ax.set_ylabel("selected blur-rate (arcmin/deg)")
    ax.set_title(f"{result.experiment}: highest blur-rate without visible foveation")
    ax.legend()
    fig.tight_layout()
    return _save(fig, stem)


def sampling_figure(result: ValidationResult, stem: Path) -> list[Path]:
    """Estimated sampling-rate reduction of ours over contrast, per scene and overall (%)."""
    s = result.sampling
    fig = Figure(figsize=(max(5.0, 0.6 * len(s) + 2), 3.5))
    ax = fig.subplots()
    colours = ["tab:gray" if sc == "all scenes" else "tab:orange" for sc in s["scope"]]
    ax.bar(np.arange(len(s)), s["reduction_pct"], color=colours)
    ax.set_xticks(np.arange(len(s)))
    ax.set_xticklabels(s["scope"], rotation=45, ha="right")
    ax.axhline(0, color="black", linewidth=0.8)
    ax.set_ylabel("sampling-rate reduction (%)")
    ax.set_title(f"{result.experiment}: ours vs contrast (section 6.3)")
    fig.tight_layout()
    return _save(fig, stem)


def latency_figure(latency_ms: dict[str, np.ndarray], stem: Path) -> list[Path]:
    """Box plots of the gaze-to-flip latency per session (whiskers: 5th and 95th percentiles;
    :mod:`fovexp.analysis.latency`)."""
    names = list(latency_ms)
    fig = Figure(figsize=(max(5.0, 0.6 * len(names) + 2), 3.8))
    ax = fig.subplots()
    ax.boxplot([latency_ms[n] for n in names], whis=(5, 95), showfliers=False)
    ax.set_xticks(range(1, len(names) + 1))
    ax.set_xticklabels(names, rotation=60, ha="right", fontsize=7)
    ax.set_ylabel("gaze-to-flip latency (ms)")
    ax.set_title("Newest gaze sample to flip, per session")
    return _save(fig, stem)
