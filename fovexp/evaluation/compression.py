"""Foveated compression (paper section 6.3): how much smaller a foveated frame's JPEG is at the
blur-rate ours allows than at the one contrast enhancement allows.

For each validation scene: the participants' mean blur-rate for ``contrast`` and for ``ours``
(the validation's summary, :func:`fovexp.analysis.validation.validate`), the full-resolution
scene foveated at each (method ``foveated``: what a renderer would transmit; the enhancement
runs after decoding), each encoded as JPEG with Pillow at quality 90 with 4:2:0 chroma
subsampling (Pillow's default at that quality, set explicitly), from the 8-bit image; the file
sizes and the saving ``1 - size_ours / size_contrast`` in %. The paper reports "up to 23 %"
for its scenes.

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
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fovexp import FovexpError, read_image

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


def participant_means(results: Path, experiment: str):  # noqa: ANN201 (DataFrame)
    """Per scene, the participants' mean blur-rate for contrast and for ours: a DataFrame
    indexed by image with columns ``contrast``, ``ours`` and ``n`` (participants)."""
    from fovexp.analysis.validation import validate
    from fovexp.results.loading import load_results

    ds = load_results(results)
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
    saving_pct, width, height."""

    table: object  # pandas.DataFrame
    experiment: str
    quality: int
    setup_line: str = ""
    notes: list[str] = field(default_factory=list)

    @property
    def max_saving_pct(self) -> float:
        return float(self.table["saving_pct"].max())  # type: ignore[index]


def analyse(results: Path, setup: Setup, experiment: str = "validation",
            images: Path | None = None, quality: int = JPEG_QUALITY) -> CompressionResult:
    import pandas as pd

    means = participant_means(results, experiment)
    files = scene_files(list(means.index), results, experiment, images)
    enh = setup.enhancer()
    rows = []
    notes = []
    for image_id, m in means.iterrows():
        img = read_image(files[str(image_id)])
        h, w = img.shape[:2]
        if (w, h) != (setup.display.width_px, setup.display.height_px):
            notes.append(f"{image_id}: {w}x{h} px, not the display's native "
                         f"{setup.display.width_px}x{setup.display.height_px}")
        enh.set_image(img)
        size = {}
        for method in ("contrast", "ours"):
            rate = float(m[method])
            out = enh.enhance(setup.gaze, setup.params("foveated", rate)).output
            size[method] = jpeg_size(out, quality)
        rows.append({"image": image_id, "blur_rate_contrast": float(m["contrast"]),
                     "blur_rate_ours": float(m["ours"]), "n": int(m["n"]),
                     "bytes_contrast": size["contrast"], "bytes_ours": size["ours"],
                     "saving_pct": 100.0 * (1.0 - size["ours"] / size["contrast"]),
                     "width": w, "height": h})
    return CompressionResult(pd.DataFrame(rows), experiment, quality, setup.describe(enh), notes)


def figure(res: CompressionResult):  # noqa: ANN201
    plt = pyplot()
    df = res.table
    fig, ax = plt.subplots(figsize=(max(5.0, 0.6 * len(df) + 2), 3.3))  # type: ignore[arg-type]
    x = np.arange(len(df))  # type: ignore[arg-type]
    ax.bar(x, df["saving_pct"], color="tab:orange")  # type: ignore[index]
    ax.set_xticks(x, df["image"], rotation=45, ha="right", fontsize=8)  # type: ignore[index]
    ax.set_ylabel("JPEG size saved by ours (%)")
    ax.axhline(23.0, color="k", ls="--", lw=0.8, label="paper: up to 23 %")
    ax.legend(fontsize=8)
    ax.set_title(f"Foveated JPEG (quality {res.quality}, {JPEG_SUBSAMPLING}) at the blur-rates "
                 "of ours vs contrast", fontsize=9)
    fig.tight_layout()
    return fig


def note(res: CompressionResult, results: Path) -> str:
    df = res.table
    rows = [(r.image, r.blur_rate_contrast, r.blur_rate_ours, r.bytes_contrast, r.bytes_ours,
             f"{r.saving_pct:.1f}") for r in df.itertuples()]  # type: ignore[attr-defined]
    lines = [
        "# Foveated compression (paper section 6.3)",
        "",
        f"Participants' mean blur-rates from {results} (experiment {res.experiment}). "
        f"{res.setup_line}. Each scene foveated (method foveated) at the contrast and at "
        f"ours' blur-rate, encoded by Pillow as JPEG quality {res.quality}, {JPEG_SUBSAMPLING} "
        "chroma subsampling, 8-bit.",
        "",
        table_md(rows, ["scene", "blur-rate contrast", "blur-rate ours", "bytes contrast",
                        "bytes ours", "saving %"]),
        "",
        f"Saving of ours over contrast: mean {df['saving_pct'].mean():.1f} %, largest "  # type: ignore[index]
        f"{res.max_saving_pct:.1f} % (the paper: up to 23 %).",
    ]
    lines += [f"- note: {n}" for n in res.notes]
    return "\n".join(lines) + "\n"


def run(results: Path, setup: Setup, out: Path, experiment: str = "validation",
        images: Path | None = None, quality: int = JPEG_QUALITY) -> CompressionResult:
    res = analyse(results, setup, experiment, images, quality)
    folder = OutFolder(out)
    folder.csv("compression.csv", res.table)
    folder.figure("compression.png", figure(res))
    folder.note("compression.md", note(res, results))
    return res
