"""``fovexp enhance --dump-maps DIR``: every intermediate map of a frame as a float32 ``.npy``
file (full resolution, values as computed) and a PNG preview a person can read.

A preview shows a map on a colour scale labelled with its unit; frequencies and amplitude mask
the region where the band is empty (F_L >= F_H: no noise is added there, and F_L grows without
bound, up to infinity, near the fovea) in neutral grey, named in the legend; the orientation is
in degrees on a cyclic colour map. Maps larger than :data:`PREVIEW_MAX_PX` are shown decimated
(every n-th pixel, said on the figure); the ``.npy`` files keep every pixel. The images
(``foveated``, ``contrast``, ``output``) are written as 8-bit PNGs.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .io import atomic_write_bytes, save_npy, write_image
from .pipeline import MAP_NAMES, EnhanceResult

#: Image maps, written as pictures.
IMAGE_MAPS = ("foveated", "contrast", "output")
#: The longest side of a preview's map, in map pixels (a 4K map is shown at 1/3).
PREVIEW_MAX_PX = 1280
#: The noise's colour scale ends at this percentile of |noise| (where there is noise); the
#: colour bar's arrows show that values beyond exist.
NOISE_PERCENTILE = 99.5
#: Colour of the band-empty region.
BAND_EMPTY_GREY = (0.5, 0.5, 0.5)


@dataclass(frozen=True)
class _Style:
    quantity: str  # the colour bar's label, with the unit
    unit: str
    cmap: str
    band_masked: bool = False  # grey where the band is empty
    symmetric: bool = False  # a diverging scale centred on 0


_STYLES: dict[str, _Style] = {
    "eccentricity_deg": _Style("eccentricity", "deg", "viridis"),
    "sigma_px": _Style("foveation blur sigma", "px", "magma"),
    "f_low_cpp": _Style("band low edge F_L", "cycles/px", "viridis", band_masked=True),
    "f_high_cpp": _Style("band high edge F_H", "cycles/px", "viridis", band_masked=True),
    "amplitude": _Style("noise amplitude K (noise std = K / 6)", "linear intensity", "inferno",
                        band_masked=True),
    "orientation_rad": _Style("orientation atan2(Gy, Gx) - 90 deg (x right, y down)", "deg",
                              "twilight"),
    "noise": _Style("noise added to every channel", "linear intensity", "RdBu_r",
                    symmetric=True),
}


def dump_maps(result: EnhanceResult, folder: Path,
              on_map: Callable[[str], None] | None = None) -> None:
    """Write every map of ``result`` to ``folder`` as NAME.npy and NAME.png; ``on_map(what)``
    is called as each is computed (``"computing NAME"``) and written (``"writing NAME"``): the
    command's progress."""
    def say(what: str) -> None:
        if on_map is not None:
            on_map(what)

    folder.mkdir(parents=True, exist_ok=True)
    maps = {}
    for name in MAP_NAMES:
        say(f"computing {name}")
        maps[name] = result.map(name)
    band_empty = ~(maps["f_low_cpp"] < maps["f_high_cpp"])  # NaN-safe: not open
    for name, m in maps.items():
        say(f"writing {name}")
        save_npy(folder / f"{name}.npy", m)
        if name in IMAGE_MAPS:
            write_image(folder / f"{name}.png", m)
        else:
            _write_preview(folder / f"{name}.png", name, m, band_empty)


def _scale(name: str, style: _Style, finite: np.ndarray) -> tuple[float, float, str]:
    """The colour scale's ends for the map's shown values, and which ends the colour bar marks
    as exceeded (matplotlib's ``extend``)."""
    if name == "orientation_rad":
        return -180.0, 180.0, "neither"
    lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
    extend = "neither"
    if style.symmetric:  # the noise's rare peaks would leave the rest white
        nonzero = np.abs(finite[finite != 0.0])
        lim = float(np.percentile(nonzero, NOISE_PERCENTILE)) if nonzero.size else 1.0
        extend = "both" if max(-lo, hi) > lim else "neither"
        lo, hi = -lim, lim
    if hi <= lo:  # a constant map: a scale around its value
        lo, hi = lo - 0.5, hi + 0.5
    return lo, hi, extend


def _write_preview(path: Path, name: str, m: np.ndarray, band_empty: np.ndarray) -> None:
    from matplotlib import colormaps
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure
    from matplotlib.patches import Patch

    style = _STYLES[name]
    step = max(1, math.ceil(max(m.shape[:2]) / PREVIEW_MAX_PX))
    values = np.asarray(m[::step, ::step], dtype=np.float64)
    if name == "orientation_rad":  # radians of any turn -> degrees in [-180, 180)
        values = (np.degrees(values) + 180.0) % 360.0 - 180.0
    mask = ~np.isfinite(values)
    if style.band_masked:
        mask |= band_empty[::step, ::step]
    shown = np.ma.masked_array(values, mask)
    lo, hi, extend = _scale(name, style, values[~mask])
    norm = Normalize(lo, hi)
    full_h, full_w = m.shape[:2]
    side = 9.0 / max(full_w, full_h)
    fig = Figure(figsize=(2.0 + full_w * side, 1.2 + full_h * side), dpi=100,
                 layout="constrained")
    ax = fig.subplots()
    cmap = colormaps[style.cmap].with_extremes(bad=BAND_EMPTY_GREY)
    # axes in the map's own pixels whatever the decimation
    im = ax.imshow(shown, cmap=cmap, norm=norm, interpolation="nearest",
                   extent=(0, full_w, full_h, 0))
    bar = fig.colorbar(im, ax=ax, shrink=0.9, extend=extend)
    bar.set_label(f"{style.quantity} ({style.unit})")
    if name == "orientation_rad":
        bar.set_ticks([-180, -90, 0, 90, 180])
    ax.set_title(f"{name}.npy" + (f", shown at 1/{step} (1 pixel in {step} each way)"
                                  if step > 1 else ""))
    ax.set_xlabel("x (px)")
    ax.set_ylabel("y (px)")
    if style.band_masked and mask.any():
        ax.legend(handles=[Patch(color=BAND_EMPTY_GREY,
                                 label="band empty (F_L >= F_H): no noise")],
                  loc="lower right", fontsize="small")
    atomic_write_bytes(path, lambda tmp: fig.savefig(tmp, format="png"))
