"""Foveated compression (paper section 6.3): how much smaller a foveated frame's JPEG is at the
blur-rate ours allows than at the one contrast enhancement allows.

For each validation scene: the participants' mean blur-rate for ``contrast`` and for ``ours``
(the validation's summary, :func:`fovexp.analysis.validation.validate`), the full-resolution
scene foveated at each (method ``foveated``: what a renderer would transmit; the enhancement
runs after decoding), each encoded as JPEG with Pillow at quality 90 with 4:2:0 chroma
subsampling (Pillow's default at that quality, set explicitly), from the 8-bit image; the file
sizes and the saving ``1 - size_ours / size_contrast`` in %. The paper reports "up to 23 %"
for its scenes.

Which experiment: the paper's blur-rates "were in accordance with user-experiments in Figure
16-right", its validation with 12 impulses per kernel (section 6.3). By default the
experiment is the one whose recorded protocol (``session-*.json``) has ``impulses: 12``, else
one named ``validation-12``; only where the results hold neither does it fall back to the
64-impulse ``validation``, and says so (:func:`pick_experiment`). The note and the command's
output name the experiment used.

The saving depends mostly on the ratio of the two blur-rates, so the analysis also gives it
against the ratio: each scene foveated at r times its contrast blur-rate against at its
contrast blur-rate (:data:`RATIOS`), and at Table 2's pair of blur-rates, 0.34 against 0.57
(:data:`TABLE2_PAIR`, a ratio of 1.68).

The scenes are read from ``--images DIR`` (``<image id>.png`` at the display's resolution:
native 4K for the paper's display) or, without it, from the files the sessions recorded
(``session-<id>.json``, docs/LOGS.md), which a dry run may have scaled down.

References
----------
.. [tariq] Tariq, T., Tursun, C., Didyk, P. (2022). Noise-based Enhancement for Foveated
   Rendering. ACM Transactions on Graphics 41(4) (SIGGRAPH 2022). doi:10.1145/3528223.3530101
"""

from __future__ import annotations

import io
import json
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fovexp import FovexpError, progress_bar, read_image
from fovexp.results.loading import impulse_count

from .outputs import OutFolder, Setup, colour_of, pyplot, table_md

#: JPEG settings (section 6.3: quality 90; the subsampling is this project's stated choice)
JPEG_QUALITY = 90
JPEG_SUBSAMPLING = "4:2:0"


def jpeg_size(image: np.ndarray, quality: int = JPEG_QUALITY) -> int:
    """Bytes of ``image`` (display-encoded, [0, 1]) as an 8-bit JPEG from Pillow, 4:2:0."""
    from PIL import Image

    c = colour_of(image)
    data = np.round(np.clip(c, 0.0, 1.0) * 255.0).astype(np.uint8)
    buf = io.BytesIO()
    Image.fromarray(data).save(buf, format="JPEG", quality=quality, subsampling=JPEG_SUBSAMPLING,
                               optimize=False)
    return buf.tell()


#: The impulse count of the paper's compression experiment (section 6.3: Figure 16 right).
PAPER_IMPULSES = 12
#: Blur-rate ratios of the saving-against-ratio table (ours' blur-rate / contrast's).
RATIOS = (1.0, 1.25, 1.5, 1.75, 2.0, 2.25, 2.5)
#: Table 2's pair: contrast at 0.34, ours at 0.57 (section 5.3's blur-rates).
TABLE2_PAIR = (0.34, 0.57)


def validation_experiments(ds: Any) -> list[str]:
    """The experiments of a dataset whose trials adjust the blur-rate (validations)."""
    t = ds.trials
    return sorted(set(t.loc[t["adjusted_parameter"] == "blur_rate", "experiment"]))


@dataclass(frozen=True)
class Choice:
    """The experiment whose blur-rates are used, its impulse count (None: not recorded), why
    it was chosen, and a warning when it is not the paper's 12-impulse experiment by
    default."""

    experiment: str
    impulses: int | None
    why: str
    warning: str = ""


def pick_experiment(results: Path, experiments: list[str], requested: str | None) -> Choice:
    """The paper's 12-impulse experiment unless ``requested`` names one (module docstring)."""
    if requested is not None:
        n = impulse_count(results, requested)
        return Choice(requested, n, "asked for (--experiment)")
    counts = {e: impulse_count(results, e) for e in experiments}
    twelve = [e for e, n in counts.items() if n == PAPER_IMPULSES]
    if twelve:
        name = "validation-12" if "validation-12" in twelve else twelve[0]
        return Choice(name, PAPER_IMPULSES, "the paper's 12-impulse experiment (section 6.3, "
                      "Figure 16 right), by its recorded protocol")
    if "validation-12" in experiments and counts["validation-12"] is None:
        return Choice("validation-12", None, "the paper's 12-impulse experiment (section "
                      "6.3, Figure 16 right), by its name: no protocol copy recorded")
    if "validation" in experiments:
        n = counts["validation"]
        return Choice("validation", n, "a fallback", warning=(
            "compression: these results hold no 12-impulse validation (the paper's "
            "experiment, section 6.3, Figure 16 right); using experiment validation ("
            f"{n if n is not None else 'unrecorded'} impulses per kernel) instead"))
    raise FovexpError(f"{results}: no validation experiment (none adjusts the blur-rate; "
                      f"experiments: {', '.join(experiments) or 'none'}); name one with "
                      "--experiment")


def participant_means(ds: Any, experiment: str, results: Path):  # noqa: ANN201 (DataFrame)
    """Per scene, the participants' mean blur-rate for contrast and for ours: a DataFrame
    indexed by image with columns ``contrast``, ``ours`` and ``n`` (participants)."""
    from fovexp.analysis.validation import validate

    trials = ds.experiment(experiment)
    if trials.empty:
        raise FovexpError(f"{results}: no trials of experiment {experiment!r} (experiments: "
                          f"{', '.join(ds.experiments) or 'none'})")
    summary = validate(trials, experiment).summary
    means = summary.pivot(index="image", columns="method", values="mean")
    if not {"contrast", "ours"} <= set(means.columns):
        raise FovexpError(f"{experiment}: needs trials of both contrast and ours (has "
                          f"{', '.join(map(str, means.columns))})")
    counts = summary.pivot(index="image", columns="method", values="n")
    out = means[["contrast", "ours"]].dropna().copy()
    out["n"] = counts.loc[out.index, ["contrast", "ours"]].min(axis=1)
    return out


def recorded_files(results: Path, experiment: str) -> dict[str, Path]:
    """Image id -> the file the sessions of ``experiment`` recorded for it (the latest
    session's), from ``session-*.json``'s ``stimuli`` (docs/LOGS.md)."""
    found: dict[str, tuple[str, Path]] = {}
    root = results / experiment if (results / experiment).is_dir() else results
    for path in sorted(root.rglob("session-*.json")):
        try:
            info = json.loads(path.read_text())
        except (OSError, ValueError):
            continue
        stim = info.get("stimuli") if isinstance(info, dict) else None
        if not isinstance(stim, dict) or not isinstance(stim.get("images"), dict):
            continue
        folder = Path(str(stim.get("folder", "")))
        for image_id, entry in stim["images"].items():
            if isinstance(entry, dict) and entry.get("path"):
                p = Path(str(entry["path"]))
                p = p if p.is_absolute() else folder / p
                key = path.name
                if image_id not in found or key >= found[image_id][0]:
                    found[image_id] = (key, p)
    return {k: v[1] for k, v in found.items()}


def scene_files(ids: list[str], results: Path, experiment: str,
                images: Path | None) -> dict[str, Path]:
    """Each scene's file: ``images/<id>.*`` when ``images`` is given, else as recorded."""
    if images is not None:
        if not images.is_dir():
            raise FovexpError(f"--images {images}: not a folder")
        out = {}
        for i in ids:
            cands = sorted(images.glob(f"{i}.*"))
            if not cands:
                raise FovexpError(f"--images {images}: no file for scene {i} ({i}.png)")
            out[i] = cands[0]
        return out
    rec = recorded_files(results, experiment)
    missing = [i for i in ids if i not in rec or not rec[i].is_file()]
    if missing:
        raise FovexpError(f"scene(s) {', '.join(missing)}: no readable file recorded by the "
                          f"sessions; give the scenes' folder with --images DIR")
    return {i: rec[i] for i in ids}


@dataclass
class CompressionResult:
    """``table``: image, blur_rate_contrast, blur_rate_ours, n, bytes_contrast, bytes_ours,
    saving_pct, width, height; ``ratios``: image, ratio, blur_rate_base, blur_rate,
    bytes_base, bytes, saving_pct (each scene at ratio x its contrast blur-rate against at
    its contrast blur-rate); ``table2``: image, blur_rate_contrast, blur_rate_ours,
    bytes_contrast, bytes_ours, saving_pct at :data:`TABLE2_PAIR`."""

    table: object  # pandas.DataFrame
    experiment: str
    quality: int
    setup_line: str = ""
    notes: list[str] = field(default_factory=list)
    choice: Choice | None = None
    ratios: object = None  # pandas.DataFrame
    table2: object = None  # pandas.DataFrame
    pair: tuple[float, float] | None = TABLE2_PAIR

    @property
    def max_saving_pct(self) -> float:
        return float(self.table["saving_pct"].max())  # type: ignore[index]

    def ratio_summary(self) -> list[tuple[float, float, float, float]]:
        """Per ratio: (ratio, mean, smallest, largest saving in %) over the scenes."""
        df = self.ratios
        if df is None or df.empty:  # type: ignore[attr-defined]
            return []
        g = df.groupby("ratio")["saving_pct"]  # type: ignore[attr-defined]
        return [(float(r), float(g.mean()[r]), float(g.min()[r]), float(g.max()[r]))
                for r in g.mean().index]

    def experiment_line(self) -> str:
        c = self.choice
        if c is None:
            return f"experiment {self.experiment}"
        n = f"{c.impulses} impulses per kernel" if c.impulses is not None else (
            "impulses per kernel not recorded")
        return f"experiment {c.experiment} ({n}; {c.why})"


def _saving_pct(bytes_base: int, bytes_other: int) -> float:
    return 100.0 * (1.0 - bytes_other / bytes_base)


class _Sizes:
    """JPEG bytes of one scene foveated at each blur-rate asked (each rate encoded once)."""

    def __init__(self, enh: Any, setup: Setup, image: np.ndarray, quality: int) -> None:
        self.enh, self.setup, self.quality = enh, setup, quality
        enh.set_image(image)
        self.cache: dict[float, int] = {}

    def at(self, blur_rate: float) -> int:
        key = round(float(blur_rate), 12)
        if key not in self.cache:
            out = self.enh.enhance(self.setup.gaze, self.setup.params("foveated", key)).output
            self.cache[key] = jpeg_size(out, self.quality)
        return self.cache[key]


def analyse(results: Path, setup: Setup, experiment: str | None = None,
            images: Path | None = None, quality: int = JPEG_QUALITY,
            ratios: tuple[float, ...] = RATIOS,
            pair: tuple[float, float] | None = TABLE2_PAIR) -> CompressionResult:
    """Per scene, the JPEG saving of ours over contrast at the participants' blur-rates of
    the chosen experiment, against the blur-rate ratio, and at Table 2's pair (module
    docstring). ``experiment`` None: the paper's 12-impulse experiment
    (:func:`pick_experiment`; a fallback from it is a warning, one line)."""
    import pandas as pd

    from fovexp.results.loading import load_results

    ds = load_results(results)
    choice = pick_experiment(results, validation_experiments(ds), experiment)
    means = participant_means(ds, choice.experiment, results)
    files = scene_files(list(means.index), results, choice.experiment, images)
    if choice.warning:  # said once the input is known good, before the scenes are encoded
        warnings.warn(choice.warning, UserWarning, stacklevel=2)
    enh = setup.enhancer()
    rows, ratio_rows, pair_rows, notes = [], [], [], []
    for image_id, m in progress_bar(means.iterrows(), total=len(means),
                                    desc="fovexp evaluate compression", unit="scene"):
        img = read_image(files[str(image_id)])
        h, w = img.shape[:2]
        if (w, h) != (setup.display.width_px, setup.display.height_px):
            notes.append(f"{image_id}: {w}x{h} px, not the display's native "
                         f"{setup.display.width_px}x{setup.display.height_px}")
        sizes = _Sizes(enh, setup, img, quality)
        base = float(m["contrast"])
        rows.append({"image": image_id, "blur_rate_contrast": base,
                     "blur_rate_ours": float(m["ours"]), "n": int(m["n"]),
                     "bytes_contrast": sizes.at(base), "bytes_ours": sizes.at(m["ours"]),
                     "saving_pct": _saving_pct(sizes.at(base), sizes.at(m["ours"])),
                     "width": w, "height": h})
        ratio_rows += [{"image": image_id, "ratio": r, "blur_rate_base": base,
                        "blur_rate": r * base, "bytes_base": sizes.at(base),
                        "bytes": sizes.at(r * base),
                        "saving_pct": _saving_pct(sizes.at(base), sizes.at(r * base))}
                       for r in ratios]
        if pair is not None:
            lo, hi = pair
            pair_rows.append({"image": image_id, "blur_rate_contrast": lo,
                              "blur_rate_ours": hi, "bytes_contrast": sizes.at(lo),
                              "bytes_ours": sizes.at(hi),
                              "saving_pct": _saving_pct(sizes.at(lo), sizes.at(hi))})
    return CompressionResult(pd.DataFrame(rows), choice.experiment, quality,
                             setup.describe(enh), notes, choice, pd.DataFrame(ratio_rows),
                             pd.DataFrame(pair_rows), pair)


def figure(res: CompressionResult):  # noqa: ANN201
    """Left: the saving per scene at the experiment's blur-rates. Right: the saving against
    the blur-rate ratio (mean over scenes, the range shaded), the experiment's mean ratio and
    Table 2's pair marked."""
    plt = pyplot()
    df = res.table
    summary = res.ratio_summary()
    fig, axes = plt.subplots(1, 2 if summary else 1, squeeze=False,
                             figsize=(max(5.0, 0.6 * len(df) + 2) + (4.5 if summary else 0),  # type: ignore[arg-type]
                                      3.3))
    ax = axes[0][0]
    x = np.arange(len(df))  # type: ignore[arg-type]
    ax.bar(x, df["saving_pct"], color="tab:orange")  # type: ignore[index]
    ax.set_xticks(x, df["image"], rotation=45, ha="right", fontsize=8)  # type: ignore[index]
    ax.set_ylabel("JPEG size saved by ours (%)")
    ax.axhline(23.0, color="k", ls="--", lw=0.8, label="paper: up to 23 %")
    ax.legend(fontsize=8)
    ax.set_title(f"Foveated JPEG (quality {res.quality}, {JPEG_SUBSAMPLING}), {res.experiment}",
                 fontsize=9)
    if summary:
        ax = axes[0][1]
        r, mean, lo, hi = (np.array(v) for v in zip(*summary, strict=True))
        ax.plot(r, mean, "o-", color="tab:orange", label="mean over scenes")
        ax.fill_between(r, lo, hi, color="tab:orange", alpha=0.2, label="range")
        ax.axvline(mean_ratio(res), color="tab:blue", ls=":", lw=1,
                   label=f"{res.experiment}: {mean_ratio(res):.2f}")
        if res.pair is not None:
            ax.plot([res.pair[1] / res.pair[0]], [float(res.table2["saving_pct"].mean())],  # type: ignore[index]
                    "s", color="k", label=f"Table 2: {res.pair[0]:g} -> {res.pair[1]:g}")
        ax.axhline(23.0, color="k", ls="--", lw=0.8)
        ax.set_xlabel("blur-rate ratio (ours / contrast)")
        ax.set_ylabel("JPEG size saved (%)")
        ax.legend(fontsize=7)
    fig.tight_layout()
    return fig


def mean_ratio(res: CompressionResult) -> float:
    """The experiment's mean blur-rate ratio over the scenes (ours / contrast)."""
    t = res.table
    return float((t["blur_rate_ours"] / t["blur_rate_contrast"]).mean())  # type: ignore[index]


def ratio_lines(res: CompressionResult) -> list[str]:
    """The saving against the blur-rate ratio as a plain-text table, and the result at Table
    2's pair (the command's output)."""
    lines = ["JPEG saving against the blur-rate ratio (each scene foveated at ratio x its "
             "contrast blur-rate, against at its contrast blur-rate):",
             f"  {'ratio':>6}  {'mean %':>7}  {'min %':>7}  {'max %':>7}"]
    lines += [f"  {r:6.2f}  {m:7.1f}  {lo:7.1f}  {hi:7.1f}" for r, m, lo, hi in
              res.ratio_summary()]
    lines.append(f"  {res.experiment}'s own blur-rates: ratio {mean_ratio(res):.2f} on "
                 f"average, saving mean {res.table['saving_pct'].mean():.1f} %, largest "  # type: ignore[index]
                 f"{res.max_saving_pct:.1f} %")
    lines += [pair_line(res)] if res.pair is not None else []
    return lines


def pair_line(res: CompressionResult) -> str:
    """The saving at Table 2's pair of blur-rates, over the scenes."""
    assert res.pair is not None
    s = res.table2["saving_pct"]  # type: ignore[index]
    lo, hi = res.pair
    return (f"Table 2's pair, contrast at {lo:g} and ours at {hi:g} (ratio {hi / lo:.2f}): "
            f"saving mean {s.mean():.1f} %, {s.min():.1f} to {s.max():.1f} % over "
            f"{len(s)} scene(s)")


def note(res: CompressionResult, results: Path) -> str:
    """The Markdown note: the experiment used (and why), the saving per scene, against the
    blur-rate ratio, and at Table 2's pair."""
    df = res.table
    rows = [(r.image, r.blur_rate_contrast, r.blur_rate_ours, r.bytes_contrast, r.bytes_ours,
             f"{r.saving_pct:.1f}") for r in df.itertuples()]  # type: ignore[attr-defined]
    warning = res.choice.warning if res.choice is not None else ""
    lines = [
        "# Foveated compression (paper section 6.3)",
        "",
        f"Blur-rates: the participants' means in {results}, {res.experiment_line()}."
        + ("" if res.choice is not None and res.choice.impulses == 12 else
           " The paper used its 12-impulse experiment (Figure 16 right)."),
        "",
        *([f"**Warning**: {warning}.", ""] if warning else []),
        f"{res.setup_line}. Each scene foveated (method foveated) at the contrast and at "
        f"ours' blur-rate, encoded by Pillow as JPEG quality {res.quality}, {JPEG_SUBSAMPLING} "
        "chroma subsampling, 8-bit.",
        "",
        table_md(rows, ["scene", "blur-rate contrast", "blur-rate ours", "bytes contrast",
                        "bytes ours", "saving %"]),
        "",
        f"Saving of ours over contrast: mean {df['saving_pct'].mean():.1f} %, largest "  # type: ignore[index]
        f"{res.max_saving_pct:.1f} % (the paper: up to 23 %), at a blur-rate ratio of "
        f"{mean_ratio(res):.2f} on average.",
        "",
    ]
    summary = res.ratio_summary()
    if summary:
        lines += ["The saving depends on the ratio of the two blur-rates: each scene foveated at "
                  "ratio x its contrast blur-rate, against at its contrast blur-rate "
                  "(`compression-ratios.csv`):", "",
                  table_md([(f"{r:.2f}", f"{m:.1f}", f"{lo:.1f}", f"{hi:.1f}")
                            for r, m, lo, hi in summary],
                           ["ratio", "mean saving %", "smallest %", "largest %"]), ""]
    if res.pair is not None:
        lines += [pair_line(res) + " (`compression-table2.csv`).", ""]
    lines += [f"- note: {n}" for n in res.notes]
    return "\n".join(lines) + "\n"


def run(results: Path, setup: Setup, out: Path, experiment: str | None = None,
        images: Path | None = None, quality: int = JPEG_QUALITY,
        ratios: tuple[float, ...] = RATIOS,
        pair: tuple[float, float] | None = TABLE2_PAIR) -> CompressionResult:
    """:func:`analyse`, then ``compression.csv``, ``compression-ratios.csv``,
    ``compression-table2.csv``, ``compression.png`` and ``compression.md`` into ``out``."""
    res = analyse(results, setup, experiment, images, quality, ratios, pair)
    folder = OutFolder(out)
    folder.csv("compression.csv", res.table)
    folder.csv("compression-ratios.csv", res.ratios)
    folder.csv("compression-table2.csv", res.table2)
    folder.figure("compression.png", figure(res))
    folder.note("compression.md", note(res, results))
    return res
