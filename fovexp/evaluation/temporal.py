"""Temporal coherence (paper section 6.2, Figure "temporal coherence").

Kaplanyan et al. 2019's procedure, as the paper applies it: the SSIM between consecutive
frames, averaged over a sequence, for full resolution, foveated, contrast-enhanced and ours, at
each blur-rate; and the temporal slices of two pixels (their grey value frame by frame). The
paper's order: foveated > contrast > ours (> full resolution): foveation smooths, the contrast
enhancement brings some change back, the noise more.

A control shows why section 4.4 fixes the impulses for a whole sequence: ``ours-reseeded``
draws new impulses every frame (seed + frame index), and its inter-frame SSIM drops.

SSIM is :func:`fovexp.ssim` (scikit-image's definition, checked against it in the tests) on
the display-encoded grey (BT.601 luma). Frames are streamed: one frame and one previous grey
image per condition are held at a time, whatever the length; each blur-rate is a pass over the
sequence with its own enhancers, whose stage caches keep what does not depend on the frame.

References
----------
.. [tariq] Tariq, T., Tursun, C., Didyk, P. (2022). Noise-based Enhancement for Foveated
   Rendering. ACM Transactions on Graphics 41(4) (SIGGRAPH 2022). doi:10.1145/3528223.3530101
.. [kaplanyan] Kaplanyan, A. S., Sochenov, A., Leimkühler, T., Okunev, M., Goodall, T., Rufo,
   G. (2019). DeepFovea: Neural Reconstruction for Foveated Rendering and Video Compression
   using Learned Statistics of Natural Videos. ACM Transactions on Graphics 38(6).
   doi:10.1145/3355089.3356557
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fovexp import FovexpError, iter_frames, ssim

from .outputs import METHODS3, OutFolder, Setup, grey, pyplot, table_md

#: The conditions: full resolution, the paper's three, and the re-seeded control.
CONDITIONS = ("full", *METHODS3, "ours-reseeded")
#: Default pixels of the temporal slices, normalised (x right, y down): one left of the gaze
#: at mid-height, one right and below it (on the paper's display with a central gaze, about
#: 22 and 27 deg out).
DEFAULT_SLICES: tuple[tuple[float, float], ...] = ((0.25, 0.5), (0.8, 0.7))


class _Running:
    """Mean SSIM between consecutive grey frames."""

    def __init__(self) -> None:
        self.prev: np.ndarray | None = None
        self.values: list[float] = []

    def add(self, g: np.ndarray) -> None:
        if self.prev is not None:
            self.values.append(ssim(self.prev, g))
        self.prev = g

    @property
    def mean(self) -> float:
        return float(np.mean(self.values)) if self.values else float("nan")


@dataclass
class TemporalResult:
    """``ssim``: condition, blur_rate (NaN for full), mean_ssim, n_pairs; ``slices``: frame,
    pixel (index), x_px, y_px, condition, blur_rate, value."""

    ssim: object  # pandas.DataFrame
    slices: object  # pandas.DataFrame
    n_frames: int
    size: tuple[int, int]
    blur_rates: list[float]
    slice_px: list[tuple[int, int]]
    setup_line: str = ""
    notes: list[str] = field(default_factory=list)

    def mean(self, condition: str, blur_rate: float | None = None) -> float:
        df = self.ssim
        sel = df[df["condition"] == condition]  # type: ignore[index]
        if condition != "full":
            sel = sel[sel["blur_rate"] == blur_rate]
        return float(sel["mean_ssim"].iloc[0])

    def order_holds(self, blur_rate: float) -> bool:
        """The paper's order at ``blur_rate``: foveated > contrast > ours."""
        f, c, o = (self.mean(m, blur_rate) for m in METHODS3)
        return f > c > o


def slice_pixels(size: tuple[int, int], slices: Sequence[tuple[float, float]]
                 ) -> list[tuple[int, int]]:
    """Normalised ``(x, y)`` points to pixel ``(x, y)`` of a ``(width, height)`` frame."""
    w, h = size
    return [(min(w - 1, int(x * w)), min(h - 1, int(y * h))) for x, y in slices]


def analyse(source: Path, setup: Setup, blur_rates: Sequence[float],
            slices: Sequence[tuple[float, float]] = DEFAULT_SLICES,
            reseed: bool = True) -> TemporalResult:
    """Inter-frame SSIM per condition and blur-rate, and the slices (module docstring)."""
    import pandas as pd

    rows: list[dict] = []
    slice_rows: list[dict] = []
    n_frames = 0
    size: tuple[int, int] | None = None
    pix: list[tuple[int, int]] = []
    setup_line = ""
    for k, br in enumerate(blur_rates):
        enh = setup.enhancer()
        enh_reseed = setup.enhancer() if reseed else None
        setup_line = setup_line or setup.describe(enh)
        run = {c: _Running() for c in CONDITIONS
               if (c != "full" or k == 0) and (c != "ours-reseeded" or reseed)}
        count, _fps, frames = iter_frames(source)
        n = 0
        for i, (_name, image, _depth) in enumerate(frames):
            h, w = image.shape[:2]
            if size is None:
                size = (w, h)
                pix = slice_pixels(size, slices)
            elif (w, h) != size:
                raise FovexpError(f"{source}: frame {i} is {w}x{h} px, the first "
                                  f"{size[0]}x{size[1]}")
            greys: dict[str, np.ndarray] = {}
            if "full" in run:
                greys["full"] = grey(image)
            enh.set_image(image)
            for m in METHODS3:
                greys[m] = grey(enh.enhance(setup.gaze, setup.params(m, br)).output)
            if enh_reseed is not None:
                enh_reseed.set_image(image)
                res = enh_reseed.enhance(setup.gaze, setup.params("ours", br,
                                                                  seed=setup.seed + 1 + i))
                greys["ours-reseeded"] = grey(res.output)
            for c, g in greys.items():
                run[c].add(g)
                for j, (x, y) in enumerate(pix):
                    slice_rows.append({"frame": i, "pixel": j, "x_px": x, "y_px": y,
                                       "condition": c,
                                       "blur_rate": float("nan") if c == "full" else br,
                                       "value": float(g[y, x])})
            n += 1
        if n < 2:
            raise FovexpError(f"{source}: {n} frame(s); the inter-frame SSIM needs 2 or more")
        n_frames = n
        for c, r in run.items():
            rows.append({"condition": c, "blur_rate": float("nan") if c == "full" else br,
                         "mean_ssim": r.mean, "n_pairs": len(r.values)})
    assert size is not None
    return TemporalResult(pd.DataFrame(rows), pd.DataFrame(slice_rows), n_frames, size,
                          list(blur_rates), pix, setup_line)


COLOURS = {"full": "k", "foveated": "tab:grey", "contrast": "tab:blue", "ours": "tab:orange",
           "ours-reseeded": "tab:red"}


def figure(res: TemporalResult):  # noqa: ANN201
    """Left: mean inter-frame SSIM against blur-rate per condition (full resolution a
    horizontal line). Right: the two slices at the largest blur-rate."""
    plt = pyplot()
    n_sl = len(res.slice_px)
    fig, axes = plt.subplots(1, 1 + n_sl, figsize=(4.2 * (1 + n_sl), 3.3), squeeze=False)
    ax = axes[0][0]
    df = res.ssim
    for c in CONDITIONS:
        sel = df[df["condition"] == c]  # type: ignore[index]
        if sel.empty:
            continue
        if c == "full":
            ax.axhline(float(sel["mean_ssim"].iloc[0]), color=COLOURS[c], ls="--",
                       label="full resolution")
        else:
            ax.plot(sel["blur_rate"], sel["mean_ssim"], "o-", color=COLOURS[c], label=c)
    ax.set_xlabel("blur-rate (arcmin/deg)")
    ax.set_ylabel("mean inter-frame SSIM")
    ax.legend(fontsize=7)
    br = max(res.blur_rates)
    sl = res.slices
    for j, (x, y) in enumerate(res.slice_px):
        ax = axes[0][1 + j]
        for c in CONDITIONS:
            sel = sl[(sl["pixel"] == j) & (sl["condition"] == c)]  # type: ignore[index]
            if c != "full":
                sel = sel[sel["blur_rate"] == br]
            if not sel.empty:
                ax.plot(sel["frame"], sel["value"], color=COLOURS[c], lw=1, label=c)
        ax.set_title(f"pixel ({x}, {y}), blur-rate {br:g}", fontsize=9)
        ax.set_xlabel("frame")
        ax.set_ylabel("grey value")
    fig.suptitle(f"Temporal coherence: {res.n_frames} frames of {res.size[0]}x{res.size[1]} px",
                 fontsize=10)
    fig.tight_layout()
    return fig


def note(res: TemporalResult, source: str) -> str:
    rows = [("full resolution", "-", res.mean("full"), "-")]
    for br in res.blur_rates:
        for c in (*METHODS3, "ours-reseeded"):
            sel = res.ssim[(res.ssim["condition"] == c)  # type: ignore[index]
                           & (res.ssim["blur_rate"] == br)]
            if sel.empty:
                continue
            rows.append((c, br, float(sel["mean_ssim"].iloc[0]),
                         "yes" if c == "ours" and res.order_holds(br) else
                         ("no" if c == "ours" else "")))
    lines = [
        "# Temporal coherence (paper section 6.2)",
        "",
        f"Sequence: {source}, {res.n_frames} frames of {res.size[0]}x{res.size[1]} px. "
        f"{res.setup_line}.",
        "Mean SSIM between consecutive frames (fovexp.ssim: scikit-image's definition, 7 x 7 "
        "window, on the display-encoded BT.601 grey). `ours-reseeded`: ours with new impulses "
        "every frame (seed + frame index), the control for section 4.4's fixed impulses.",
        "",
        table_md(rows, ["condition", "blur-rate", "mean SSIM",
                        "foveated > contrast > ours"]),
        "",
    ]
    for br in res.blur_rates:
        if (res.ssim["condition"] == "ours-reseeded").any():  # type: ignore[index]
            drop = res.mean("ours", br) - res.mean("ours-reseeded", br)
            lines.append(f"- blur-rate {br:g}: re-seeding the impulses every frame lowers ours' "
                         f"mean SSIM by {drop:.4f} ({res.mean('ours', br):.4f} -> "
                         f"{res.mean('ours-reseeded', br):.4f}).")
    lines += ["",
              "Temporal slices (`slices.csv`, right of `temporal.png`): the grey value of "
              + " and ".join(f"pixel ({x}, {y})" for x, y in res.slice_px)
              + " in every frame, per condition.", ""]
    return "\n".join(lines)


def run(source: Path, setup: Setup, blur_rates: Sequence[float], out: Path,
        slices: Sequence[tuple[float, float]] = DEFAULT_SLICES,
        reseed: bool = True) -> TemporalResult:
    """:func:`analyse`, then ``temporal.csv``, ``slices.csv``, ``temporal.png`` and
    ``temporal.md`` into ``out``."""
    res = analyse(source, setup, blur_rates, slices, reseed)
    folder = OutFolder(out)
    folder.csv("temporal.csv", res.ssim)
    folder.csv("slices.csv", res.slices)
    folder.figure("temporal.png", figure(res))
    folder.note("temporal.md", note(res, str(source)))
    return res
