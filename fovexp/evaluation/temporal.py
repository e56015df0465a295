"""Temporal coherence (paper section 6.2, Figure "temporal coherence").

Kaplanyan et al. 2019's procedure, as the paper applies it: the SSIM between consecutive
frames, averaged over a sequence, for full resolution, foveated, contrast-enhanced and ours, at
each blur-rate; and the temporal slices of two pixels (their grey value frame by frame). The
paper's order: foveated > contrast > ours (> full resolution): foveation smooths, the contrast
enhancement brings some change back, the noise more.

A control shows why section 4.4 fixes the impulses for a whole sequence: ``ours-reseeded``
draws new impulses every frame (seed + frame index), and its inter-frame SSIM drops.

SSIM is :func:`fovexp.ssim` (scikit-image's default definition: a 7 x 7 uniform window, sample
covariances; checked against it in the tests) on the display-encoded grey (BT.601 luma), and,
beside it, the standard SSIM of Wang et al. 2004 (:func:`standard_ssim`: an 11 x 11 Gaussian
window of sigma 1.5 px, population covariances). The paper does not say which it used. Where
two conditions differ by less than the two variants differ from each other, their order is
not established by the measure, and the note flags it (:func:`close_margins`). Frames are
streamed: one frame and one previous grey
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
.. [wang] Wang, Z., Bovik, A. C., Sheikh, H. R., Simoncelli, E. P. (2004). Image Quality
   Assessment: From Error Visibility to Structural Similarity. IEEE Trans. Image Processing
   13(4), 600-612. doi:10.1109/TIP.2003.819861
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fovexp import FovexpError, iter_frames, progress_bar, ssim

from .outputs import METHODS3, OutFolder, Setup, grey, pyplot, table_md

#: The conditions: full resolution, the paper's three, and the re-seeded control.
CONDITIONS = ("full", *METHODS3, "ours-reseeded")
#: Default pixels of the temporal slices, normalised (x right, y down): one left of the gaze
#: at mid-height, one right and below it (on the paper's display with a central gaze, about
#: 22 and 27 deg out).
DEFAULT_SLICES: tuple[tuple[float, float], ...] = ((0.25, 0.5), (0.8, 0.7))
#: The SSIM variants: fovexp's (:func:`fovexp.ssim`) and the standard one
#: (:func:`standard_ssim`).
VARIANTS = ("fovexp", "standard")
#: Pairs of conditions in the paper's order (section 6.2: foveated > contrast > ours > full
#: resolution) whose margins are compared with the difference between the SSIM variants.
ORDERED_PAIRS = (("foveated", "contrast"), ("contrast", "ours"), ("ours", "full"))


def standard_ssim(a: np.ndarray, b: np.ndarray, data_range: float = 1.0) -> float:
    """Wang et al. 2004's SSIM as published: an 11 x 11 Gaussian window of sigma 1.5 px,
    population (not sample) covariances, K1 = 0.01, K2 = 0.03, the map averaged without its
    5 px border. It is scikit-image's ``structural_similarity(gaussian_weights=True,
    sigma=1.5, use_sample_covariance=False)``, called here."""
    from skimage.metrics import structural_similarity

    return float(structural_similarity(np.asarray(a, np.float64), np.asarray(b, np.float64),
                                       data_range=data_range, gaussian_weights=True, sigma=1.5,
                                       use_sample_covariance=False))


class _Running:
    """The SSIM between each frame and the one before it (section 6.2), under both variants."""

    def __init__(self) -> None:
        self.prev: np.ndarray | None = None
        self.values: dict[str, list[float]] = {v: [] for v in VARIANTS}

    def add(self, g: np.ndarray) -> None:
        if self.prev is not None:
            self.values["fovexp"].append(ssim(self.prev, g))
            self.values["standard"].append(standard_ssim(self.prev, g))
        self.prev = g

    def mean(self, variant: str = "fovexp") -> float:
        v = self.values[variant]
        return float(np.mean(v)) if v else float("nan")


#: The column of each SSIM variant's mean in :attr:`TemporalResult.ssim`.
MEAN_COLUMN = {"fovexp": "mean_ssim", "standard": "mean_ssim_standard"}


@dataclass
class TemporalResult:
    """``ssim``: condition, blur_rate (NaN for full), mean_ssim (fovexp's SSIM),
    mean_ssim_standard (Wang et al. 2004's), n_pairs; ``pairs``: condition, blur_rate, pair
    (k: frames k and k + 1), ssim, ssim_standard; ``slices``: frame, pixel (index), x_px,
    y_px, condition, blur_rate, value."""

    ssim: object  # pandas.DataFrame
    slices: object  # pandas.DataFrame
    n_frames: int
    size: tuple[int, int]
    blur_rates: list[float]
    slice_px: list[tuple[int, int]]
    setup_line: str = ""
    notes: list[str] = field(default_factory=list)
    pairs: object = None  # pandas.DataFrame

    def mean(self, condition: str, blur_rate: float | None = None,
             variant: str = "fovexp") -> float:
        df = self.ssim
        sel = df[df["condition"] == condition]  # type: ignore[index]
        if condition != "full":
            sel = sel[sel["blur_rate"] == blur_rate]
        return float(sel[MEAN_COLUMN[variant]].iloc[0])

    def order_holds(self, blur_rate: float, variant: str = "fovexp") -> bool:
        """The paper's order at ``blur_rate``: foveated > contrast > ours."""
        f, c, o = (self.mean(m, blur_rate, variant) for m in METHODS3)
        return f > c > o


@dataclass(frozen=True)
class Margin:
    """The margin ``a - b`` between two conditions' mean SSIM under each variant, and the
    difference between the variants (the larger of the two conditions')."""

    a: str
    b: str
    blur_rate: float
    margin: float
    margin_standard: float
    variant_gap: float

    @property
    def close(self) -> bool:
        """The margin is smaller than the difference between the SSIM variants."""
        return abs(self.margin) < self.variant_gap


def margins(res: TemporalResult, blur_rate: float) -> list[Margin]:
    """The margins of :data:`ORDERED_PAIRS` at ``blur_rate`` (conditions present only)."""
    have = set(res.ssim["condition"])  # type: ignore[index]
    out = []
    for a, b in ORDERED_PAIRS:
        if not {a, b} <= have:
            continue
        m = {v: (res.mean(a, blur_rate, v), res.mean(b, blur_rate, v)) for v in VARIANTS}
        gap = max(abs(m["fovexp"][0] - m["standard"][0]), abs(m["fovexp"][1] - m["standard"][1]))
        out.append(Margin(a, b, blur_rate, m["fovexp"][0] - m["fovexp"][1],
                          m["standard"][0] - m["standard"][1], gap))
    return out


def close_margins(res: TemporalResult) -> list[str]:
    """One line per margin (section 6.2's order) smaller than the difference between the two
    SSIM variants: such an order is not established by the measure."""
    lines = []
    for br in res.blur_rates:
        for m in margins(res, br):
            if m.close:
                lines.append(
                    f"blur-rate {br:g}: {m.a} - {m.b} = {m.margin:+.4f} under fovexp's SSIM "
                    f"({m.margin_standard:+.4f} under the standard SSIM) is smaller than the "
                    f"difference between the two SSIM variants ({m.variant_gap:.4f}): the "
                    f"order of {m.a} and {m.b} is within the choice of SSIM")
    return lines


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
    pair_rows: list[dict] = []
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
        frames = progress_bar(frames, total=count, unit="frame",
                              desc=f"fovexp evaluate temporal, blur-rate {br:g}")
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
            rate = float("nan") if c == "full" else br
            rows.append({"condition": c, "blur_rate": rate, "mean_ssim": r.mean("fovexp"),
                         "mean_ssim_standard": r.mean("standard"),
                         "n_pairs": len(r.values["fovexp"])})
            pair_rows += [{"condition": c, "blur_rate": rate, "pair": k, "ssim": v,
                           "ssim_standard": w}
                          for k, (v, w) in enumerate(zip(*r.values.values(), strict=True))]
    assert size is not None
    return TemporalResult(pd.DataFrame(rows), pd.DataFrame(slice_rows), n_frames, size,
                          list(blur_rates), pix, setup_line, pairs=pd.DataFrame(pair_rows))


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


def _order_cell(res: TemporalResult, condition: str, blur_rate: float) -> str:
    """"yes"/"no" per SSIM variant in the row of ``ours``: does the paper's order hold."""
    if condition != "ours":
        return ""
    return " / ".join("yes" if res.order_holds(blur_rate, v) else "no" for v in VARIANTS)


def note(res: TemporalResult, source: str) -> str:
    """The Markdown note: both SSIM variants per condition, the paper's order under each, the
    margins within the variants' difference, the re-seeding control."""
    rows = [("full resolution", "-", res.mean("full"), res.mean("full", variant="standard"),
             "-")]
    for br in res.blur_rates:
        for c in (*METHODS3, "ours-reseeded"):
            sel = res.ssim[(res.ssim["condition"] == c)  # type: ignore[index]
                           & (res.ssim["blur_rate"] == br)]
            if sel.empty:
                continue
            rows.append((c, br, float(sel["mean_ssim"].iloc[0]),
                         float(sel["mean_ssim_standard"].iloc[0]), _order_cell(res, c, br)))
    close = close_margins(res)
    lines = [
        "# Temporal coherence (paper section 6.2)",
        "",
        f"Sequence: {source}, {res.n_frames} frames of {res.size[0]}x{res.size[1]} px. "
        f"{res.setup_line}.",
        "Mean SSIM between consecutive frames on the display-encoded BT.601 grey, under two "
        "variants (the paper does not say which it used): fovexp's (fovexp.ssim: "
        "scikit-image's default, 7 x 7 uniform window, sample covariances) and the standard "
        "SSIM (Wang et al. 2004: 11 x 11 Gaussian window, sigma 1.5 px, population "
        "covariances). `ours-reseeded`: ours with new impulses every frame (seed + frame "
        "index), the control for section 4.4's fixed impulses.",
        "",
        table_md(rows, ["condition", "blur-rate", "mean SSIM (fovexp)",
                        "mean SSIM (standard)", "foveated > contrast > ours (fovexp / standard)"]),
        "",
    ]
    if close:
        lines += ["Margins smaller than the difference between the two SSIM variants (the order "
                  "of these conditions depends on the choice of SSIM):", ""]
        lines += [f"- {c}." for c in close]
    else:
        lines.append("Every margin between neighbours in the paper's order (foveated, "
                     "contrast, ours, full resolution) is larger in size than the difference "
                     "between the two SSIM variants.")
    lines.append("")
    for br in res.blur_rates:
        if (res.ssim["condition"] == "ours-reseeded").any():  # type: ignore[index]
            drop = res.mean("ours", br) - res.mean("ours-reseeded", br)
            lines.append(f"- blur-rate {br:g}: re-seeding the impulses every frame lowers ours' "
                         f"mean SSIM by {drop:.4f} ({res.mean('ours', br):.4f} -> "
                         f"{res.mean('ours-reseeded', br):.4f}).")
    lines += ["",
              "Temporal slices (`slices.csv`, right of `temporal.png`): the grey value of "
              + " and ".join(f"pixel ({x}, {y})" for x, y in res.slice_px)
              + " in every frame, per condition. Each pair's SSIM under both variants: "
              "`pairs.csv`.", ""]
    return "\n".join(lines)


def run(source: Path, setup: Setup, blur_rates: Sequence[float], out: Path,
        slices: Sequence[tuple[float, float]] = DEFAULT_SLICES,
        reseed: bool = True) -> TemporalResult:
    """:func:`analyse`, then ``temporal.csv``, ``slices.csv``, ``pairs.csv``, ``temporal.png``
    and ``temporal.md`` into ``out``; a margin within the SSIM variants' difference is also a
    warning (:func:`close_margins`)."""
    res = analyse(source, setup, blur_rates, slices, reseed)
    folder = OutFolder(out)
    folder.csv("temporal.csv", res.ssim)
    folder.csv("slices.csv", res.slices)
    folder.csv("pairs.csv", res.pairs)
    folder.figure("temporal.png", figure(res))
    folder.note("temporal.md", note(res, str(source)))
    close = close_margins(res)
    if close:
        warnings.warn(f"temporal: {len(close)} margin(s) of the paper's order are smaller than "
                      "the difference between fovexp's and the standard SSIM (listed in "
                      f"{out / 'temporal.md'}), the first: {close[0]}", UserWarning,
                      stacklevel=2)
    return res
