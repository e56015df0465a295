"""What every analysis of :mod:`fovexp.evaluation` shares: its inputs (image files, the
enhancer's outputs per method) and its outputs (a CSV, a PNG figure and a Markdown note in one
folder, each written atomically)."""

from __future__ import annotations

import io
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fovexp import (
    Display,
    FovexpError,
    iter_frames,
    load_display,
    make_enhancer,
    make_params,
    progress_bar,
    read_image,
    write_bytes_atomic,
)

#: The three conditions the paper compares (section 6.1): foveation alone, + contrast
#: enhancement (Patney et al. 2016), + noise (ours).
METHODS3 = ("foveated", "contrast", "ours")


def colour_of(image: np.ndarray) -> np.ndarray:
    """An image without its alpha channel (grey + alpha -> grey, RGBA -> RGB)."""
    if image.ndim == 3 and image.shape[2] in (2, 4):
        return image[..., :-1] if image.shape[2] == 4 else image[..., 0]
    return image


def grey(image: np.ndarray) -> np.ndarray:
    """Display-encoded grey of an image: BT.601 luma of the RGB code values (the weights the
    enhancer's luminance uses, docs/METHOD.md 5.4), float64."""
    c = colour_of(np.asarray(image))
    if c.ndim == 2:
        return c.astype(np.float64)
    return c[..., :3].astype(np.float64) @ np.array([0.299, 0.587, 0.114])


@dataclass
class Setup:
    """The enhancer settings an analysis runs with (``fovexp enhance``'s options)."""

    display: Display
    backend: str = "auto"
    impulses: int = 64
    seed: int = 1
    gaze: tuple[float, float] = (0.5, 0.5)
    #: "paper" (Table 2) or "release" (the release's constants and defaults)
    preset: str = "paper"

    @classmethod
    def make(cls, display: str, backend: str = "auto", impulses: int = 64, seed: int = 1,
             gaze: tuple[float, float] = (0.5, 0.5), preset: str = "paper") -> Setup:
        return cls(load_display(display), backend, impulses, seed, gaze, preset)

    def enhancer(self) -> Any:
        return make_enhancer(self.display, preset=self.preset, backend=self.backend)

    def params(self, method: str, blur_rate: float, seed: int | None = None) -> Any:
        return make_params(method=method, blur_rate=blur_rate, impulses=self.impulses,
                           seed=self.seed if seed is None else seed, preset=self.preset)

    def describe(self, enh: Any) -> str:
        kind = enh.backend + (f" ({enh.fallback_reason})" if getattr(
            enh, "fallback_reason", None) else "")
        return (f"display {self.display.name} ({self.display.width_px}x"
                f"{self.display.height_px} px, {self.display.distance_cm:g} cm), gaze "
                f"{self.gaze[0]:g},{self.gaze[1]:g}, {self.impulses} impulses per kernel, seed "
                f"{self.seed}, "
                + ("Table 2's f_e, s_k, s_f" if self.preset == "paper"
                   else "the release preset's constants and defaults (f_e, s_k, s_f)")
                + f", clipping rule {getattr(enh, 'clipping', '?')}; backend {kind}")


def outputs(enh: Any, setup: Setup, image: np.ndarray, blur_rate: float,
            methods: Iterable[str] = METHODS3) -> dict[str, np.ndarray]:
    """Each method's displayed output of ``image`` (full resolution, foveated by the
    enhancer) at ``blur_rate``: one frame set, the stage cache shares the foveation."""
    enh.set_image(image)
    return {m: enh.enhance(setup.gaze, setup.params(m, blur_rate)).output for m in methods}


def table2_clamp(blur_rate: float) -> str:
    """One line when Table 2 (paper section 5.3, ``fovexp.PAPER_TABLE2``: blur-rates 0.11 to
    0.57) does not reach ``blur_rate``: the paper preset's f_e, s_k and s_f are then its
    nearest row's (``ParameterTable.at`` clamps outside the table), which must not pass
    silently (the paper's FovVDP figure is at 0.68). "" inside the table's range."""
    from fovexp import PAPER_TABLE2

    rates = [r.blur_rate for r in PAPER_TABLE2.rows]
    lo, hi = min(rates), max(rates)
    if lo <= blur_rate <= hi:
        return ""
    edge = lo if blur_rate < lo else hi
    f_e, s_k, s_f = PAPER_TABLE2.at(edge)
    return (f"blur-rate {blur_rate:g} lies outside Table 2's rows ({lo:g} to {hi:g}): f_e, s_k "
            f"and s_f are clamped to its {edge:g} row (f_e {f_e:g}, s_k {s_k:g}, s_f {s_f:g})")


def parse_blur_rates(text: str) -> list[float]:
    """``"0.11,0.34"`` -> [0.11, 0.34], each checked against the blur-rate's range."""
    from fovexp import check_parameter

    out = []
    for part in text.split(","):
        try:
            out.append(float(check_parameter("blur_rate", part.strip())))
        except ValueError as exc:
            raise FovexpError(f"--blur-rate {part.strip()!r}: {exc}") from None
    if not out:
        raise FovexpError("--blur-rate: give at least one blur-rate")
    return out


@dataclass
class Written:
    """The files an analysis wrote, and its note's text."""

    folder: Path
    files: list[Path] = field(default_factory=list)
    note: str = ""


class OutFolder:
    """The analysis' output folder: each file written atomically (a failed run leaves the
    files of an earlier run as they were, never half a file)."""

    def __init__(self, folder: Path) -> None:
        if folder.exists() and not folder.is_dir():
            raise FovexpError(f"--out {folder}: is a file, not a folder")
        self.folder = folder
        self.written = Written(folder)

    def bytes(self, name: str, data: bytes) -> Path:
        path = self.folder / name
        write_bytes_atomic(path, data)
        self.written.files.append(path)
        return path

    def csv(self, name: str, frame: Any) -> Path:
        """A pandas DataFrame as CSV (floats with 6 significant digits)."""
        return self.bytes(name, frame.to_csv(index=False, float_format="%.6g").encode())

    def figure(self, name: str, fig: Any) -> Path:
        """A matplotlib figure as PNG (closed after)."""
        import matplotlib.pyplot as plt

        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=110, bbox_inches="tight")
        plt.close(fig)
        return self.bytes(name, buf.getvalue())

    def note(self, name: str, text: str) -> Path:
        self.written.note = text
        return self.bytes(name, text.encode())

    def npy(self, name: str, array: np.ndarray) -> Path:
        buf = io.BytesIO()
        np.save(buf, array)
        return self.bytes(name, buf.getvalue())


def pyplot() -> Any:
    """matplotlib's pyplot on the Agg backend (files only, no window)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def read_images(paths: Sequence[Path], desc: str | None = None
                ) -> Iterator[tuple[str, np.ndarray]]:
    """``(name, image)`` of each file named, a folder standing for its images (sorted by
    name, as a sequence's frames); the name is the file's stem. Read one at a time. Every path
    is checked before the first image is read (a missing one is said at once, not after
    minutes of work on the others); with ``desc``, a progress bar counts the images as the
    caller is done with each (``fovexp.progress_bar``)."""
    if not paths:
        raise FovexpError("no images given")
    missing = [str(p) for p in paths if not p.exists()]
    if missing:
        raise FovexpError(f"{', '.join(missing)}: no such file or folder")
    counts = [iter_frames(p)[0] if p.is_dir() else 1 for p in paths]
    total = None if any(c is None for c in counts) else sum(counts)

    def images() -> Iterator[tuple[str, np.ndarray]]:
        for p in paths:
            if p.is_dir():
                for name, image, _depth in iter_frames(p)[2]:
                    yield name, image
            else:
                yield p.stem, read_image(p)

    if desc is None:
        yield from images()
    else:
        yield from progress_bar(images(), total=total, desc=desc, unit="image")


def table_md(rows: Sequence[Sequence[Any]], header: Sequence[str]) -> str:
    """A Markdown table."""
    def cell(v: Any) -> str:
        if isinstance(v, float):
            return f"{v:.4g}"
        return str(v)

    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(cell(v) for v in r) + " |" for r in rows]
    return "\n".join(lines)
