"""Power spectra of the outputs per eccentricity ring (paper section 6.1, Figure "Fourier
analysis"): foveation removes the aliasing band (f >= T_L), contrast enhancement cannot bring
it back, the noise does.

For each method (``foveated``, ``contrast``, ``ours``), blur-rate and eccentricity ring: the
radially averaged power spectrum of the displayed output's grey (BT.601 luma of the code
values), over Hann-windowed square patches whose centres lie in the ring, divided by the same
spectrum of the full-resolution image, in dB, against cycles/deg. Each patch's frequencies are
converted with its own pixels per degree (the exact viewing geometry: ppd grows off-axis), so
patches of one ring add up on one cycles/deg axis. Power is summed over the patches, then over
the images, before the ratio is taken (a ratio of averages: a patch with no power at some
frequency adds nothing rather than an infinite dB).

The band of a ring is [T_L(e), min(T_H(e), Nyquist)] at the ring's centre eccentricity e
(Thibos et al. 1996, as the method uses it: ``fovexp.t_low_cpd``, ``t_high_cpd``), Nyquist
being half the ring's mean pixels per degree; its power ratio is the power-weighted ratio over
the frequencies in it.

References
----------
.. [tariq] Tariq, T., Tursun, C., Didyk, P. (2022). Noise-based Enhancement for Foveated
   Rendering. ACM Transactions on Graphics 41(4) (SIGGRAPH 2022). doi:10.1145/3528223.3530101
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fovexp import FovexpError, ViewingGeometry, t_high_cpd, t_low_cpd

from .outputs import METHODS3, OutFolder, Setup, grey, outputs, pyplot, read_images, table_md

#: Default ring centres (deg) and half-width: three eccentricities past the 8 deg fovea that
#: the paper's display reaches in every direction from a central gaze (its half-height is
#: 25.6 deg).
RING_CENTRES_DEG = (12.0, 18.0, 24.0)
RING_HALF_WIDTH_DEG = 2.0
#: Patch side at 3840 px of image width, scaled with the width (at least 16 px).
PATCH_PX_AT_4K = 128
#: Frequency bins: log-spaced, this many per octave.
BINS_PER_OCTAVE = 4


@dataclass(frozen=True)
class Ring:
    lo_deg: float
    hi_deg: float

    @property
    def centre_deg(self) -> float:
        return 0.5 * (self.lo_deg + self.hi_deg)

    @property
    def label(self) -> str:
        return f"{self.lo_deg:g}-{self.hi_deg:g} deg"


def default_rings(centres_deg: Sequence[float] = RING_CENTRES_DEG,
                  half_width_deg: float = RING_HALF_WIDTH_DEG) -> list[Ring]:
    return [Ring(c - half_width_deg, c + half_width_deg) for c in centres_deg]


def patch_px(width_px: int) -> int:
    """The patch side for an image ``width_px`` wide: 128 px at 4K, scaled, even, >= 16."""
    return max(16, 2 * round(PATCH_PX_AT_4K * width_px / 3840 / 2))


@dataclass
class Patches:
    """The patches of one ring: top-left corners and each patch's pixels per degree."""

    y0: np.ndarray
    x0: np.ndarray
    ppd: np.ndarray

    def __len__(self) -> int:
        return int(self.y0.size)


def ring_patches(geom: ViewingGeometry, gaze: tuple[float, float], ring: Ring,
                 side_px: int) -> Patches:
    """The non-overlapping patches of a grid over the image whose centres lie in ``ring``."""
    h, w = geom.shape
    ys = np.arange(0, h - side_px + 1, side_px)
    xs = np.arange(0, w - side_px + 1, side_px)
    y0, x0 = (a.ravel() for a in np.meshgrid(ys, xs, indexing="ij"))
    cy, cx = y0 + 0.5 * (side_px - 1), x0 + 0.5 * (side_px - 1)
    ecc = geom.eccentricity_deg(cx, cy, geom.gaze_px(gaze))
    keep = (ecc >= ring.lo_deg) & (ecc < ring.hi_deg)
    return Patches(y0[keep], x0[keep], geom.ppd(cx[keep], cy[keep]))


def bin_edges_cpd(max_cpd: float) -> np.ndarray:
    """Log-spaced frequency bins from 0.5 cycles/deg up past ``max_cpd``."""
    octaves = max(1.0, np.log2(max_cpd / 0.5))
    n = int(np.ceil(octaves * BINS_PER_OCTAVE))
    return 0.5 * 2.0 ** (np.arange(n + 1) / BINS_PER_OCTAVE)


def patch_power(image_grey: np.ndarray, patches: Patches, side_px: int,
                edges_cpd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Summed power and sample count per frequency bin over the patches: each patch's mean
    removed, Hann-windowed, |FFT|^2 normalised by the window's energy (so that the mean power
    per frequency sample of white noise is its variance whatever the patch size)."""
    hann = np.hanning(side_px)
    window = np.outer(hann, hann)
    norm = float((window**2).sum())
    f = np.fft.fftfreq(side_px)
    r_cpp = np.hypot(f[:, None], f[None, :])
    nb = edges_cpd.size - 1
    power = np.zeros(nb)
    count = np.zeros(nb)
    for y0, x0, ppd in zip(patches.y0, patches.x0, patches.ppd, strict=True):
        p = image_grey[y0:y0 + side_px, x0:x0 + side_px]
        spec = np.abs(np.fft.fft2((p - p.mean()) * window)) ** 2 / norm
        idx = np.searchsorted(edges_cpd, r_cpp * ppd, side="right") - 1
        ok = (idx >= 0) & (idx < nb) & (r_cpp > 0) & (r_cpp <= 0.5)
        power += np.bincount(idx[ok], spec[ok], nb)
        count += np.bincount(idx[ok], None, nb)
    return power, count


@dataclass
class SpectraResult:
    """``curves``: image (or ``all``), blur_rate, ring, method, f_cpd, power, ratio_db;
    ``bands``: image (or ``all``), blur_rate, ring, method, band_lo_cpd, band_hi_cpd,
    ratio_db; ``patches``: ring -> patch count per image."""

    curves: object  # pandas.DataFrame
    bands: object  # pandas.DataFrame
    side_px: int
    rings: list[Ring]
    n_patches: dict[str, int]
    ppd: dict[str, float]
    images: list[str]
    blur_rates: list[float]
    setup_line: str = ""


def _ratio_db(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        r = 10.0 * np.log10(num / den)
    return np.where(np.isfinite(r), r, np.nan)


def analyse(paths: Sequence[Path], setup: Setup, blur_rates: Sequence[float],
            rings: Sequence[Ring] | None = None, side_px: int | None = None) -> SpectraResult:
    """The spectra of every method's output for each image and blur-rate (module docstring)."""
    import pandas as pd

    rings = list(rings or default_rings())
    enh = setup.enhancer()
    # (image, blur_rate, ring, method) -> (power, count); method "full" is the reference
    acc: dict[tuple[str, float, str, str], tuple[np.ndarray, np.ndarray]] = {}
    edges: np.ndarray | None = None
    names: list[str] = []
    n_patches: dict[str, int] = {}
    ring_ppd: dict[str, float] = {}
    shape: tuple[int, int] | None = None
    for name, image in read_images(paths):
        names.append(name)
        h, w = image.shape[:2]
        if shape is None:
            shape = (h, w)
            side_px = side_px or patch_px(w)
            geom = ViewingGeometry.for_image(setup.display, w, h, "exact")
            per_ring = {r.label: ring_patches(geom, setup.gaze, r, side_px) for r in rings}
            for r in rings:
                pt = per_ring[r.label]
                if not len(pt):
                    raise FovexpError(
                        f"ring {r.label}: no {side_px} px patch of a {w}x{h} image on display "
                        f"{setup.display.name} has its centre there (gaze {setup.gaze}); "
                        "choose rings the image reaches (--rings)")
                n_patches[r.label] = len(pt)
                ring_ppd[r.label] = float(pt.ppd.mean())
            edges = bin_edges_cpd(0.5 * max(float(p.ppd.max()) for p in per_ring.values()))
        elif (h, w) != shape:
            raise FovexpError(f"{name}: {w}x{h} px; the images of one run must share one size "
                              f"(the first was {shape[1]}x{shape[0]})")
        assert edges is not None and side_px is not None
        full = grey(image)
        for r in rings:
            acc[(name, 0.0, r.label, "full")] = patch_power(full, per_ring[r.label], side_px,
                                                            edges)
        for br in blur_rates:
            outs = outputs(enh, setup, image, br)
            for method, out in outs.items():
                g = grey(out)
                for r in rings:
                    acc[(name, br, r.label, method)] = patch_power(g, per_ring[r.label],
                                                                   side_px, edges)
    if not names:
        raise FovexpError("no images given")
    assert edges is not None and side_px is not None
    centres = np.sqrt(edges[:-1] * edges[1:])
    curves, bands = [], []
    for scope in [*names, "all"]:
        imgs = names if scope == "all" else [scope]
        for r in rings:
            ref_p = sum(acc[(i, 0.0, r.label, "full")][0] for i in imgs)
            cnt = acc[(imgs[0], 0.0, r.label, "full")][1] * len(imgs)
            lo = float(t_low_cpd(r.centre_deg))
            hi = min(float(t_high_cpd(r.centre_deg)), 0.5 * ring_ppd[r.label])
            in_band = (centres >= lo) & (centres <= hi) & (cnt > 0)
            for br in blur_rates:
                for method in METHODS3:
                    p = sum(acc[(i, br, r.label, method)][0] for i in imgs)
                    ratio = _ratio_db(p, ref_p)
                    for k in np.nonzero(cnt > 0)[0]:
                        curves.append({"image": scope, "blur_rate": br, "ring": r.label,
                                       "method": method, "f_cpd": centres[k],
                                       "power": p[k] / cnt[k], "ratio_db": ratio[k]})
                    band_db = (float(_ratio_db(np.array(p[in_band].sum()),
                                               np.array(ref_p[in_band].sum())))
                               if in_band.any() else float("nan"))
                    bands.append({"image": scope, "blur_rate": br, "ring": r.label,
                                  "method": method, "band_lo_cpd": lo, "band_hi_cpd": hi,
                                  "ratio_db": band_db})
    return SpectraResult(pd.DataFrame(curves), pd.DataFrame(bands), side_px, rings, n_patches,
                         ring_ppd, names, list(blur_rates), setup.describe(enh))


COLOURS = {"foveated": "tab:grey", "contrast": "tab:blue", "ours": "tab:orange"}


def figure(res: SpectraResult):  # noqa: ANN201  (a matplotlib Figure)
    """Rows: blur-rates; columns: rings (the paper's layout). Power relative to full
    resolution (dB) against cycles/deg, averaged over the images; T_L and T_H of the ring
    dashed, the band the noise may fill shaded."""
    plt = pyplot()
    nr, nc = len(res.blur_rates), len(res.rings)
    fig, axes = plt.subplots(nr, nc, figsize=(3.6 * nc, 2.8 * nr), squeeze=False,
                             sharex=True, sharey=True)
    df = res.curves
    allrows = df[df["image"] == "all"]  # type: ignore[index]
    for i, br in enumerate(res.blur_rates):
        for j, r in enumerate(res.rings):
            ax = axes[i][j]
            sel = allrows[(allrows["blur_rate"] == br) & (allrows["ring"] == r.label)]
            for method in METHODS3:
                m = sel[sel["method"] == method]
                ax.semilogx(m["f_cpd"], m["ratio_db"], label=method, color=COLOURS[method])
            lo, hi = float(t_low_cpd(r.centre_deg)), float(t_high_cpd(r.centre_deg))
            nyq = 0.5 * res.ppd[r.label]
            ax.axvspan(lo, min(hi, nyq), color="tab:orange", alpha=0.08)
            ax.axvline(lo, color="k", ls="--", lw=0.8)
            ax.axvline(hi, color="k", ls=":", lw=0.8)
            ax.axhline(0.0, color="k", lw=0.5)
            ax.set_title(f"blur-rate {br:g}, {r.label}", fontsize=9)
            if i == nr - 1:
                ax.set_xlabel("cycles/deg")
            if j == 0:
                ax.set_ylabel("power / full res. (dB)")
    axes[0][0].legend(fontsize=8, loc="lower left")
    fig.suptitle(f"Output spectra relative to full resolution ({len(res.images)} image(s)); "
                 "T_L dashed, T_H dotted", fontsize=10)
    return fig


def note(res: SpectraResult) -> str:
    """The Markdown note: settings, rings and patches, the band ratios averaged over images."""
    b = res.bands
    allb = b[b["image"] == "all"]  # type: ignore[index]
    rows = []
    for br in res.blur_rates:
        for r in res.rings:
            sel = allb[(allb["blur_rate"] == br) & (allb["ring"] == r.label)]
            vals = {m: float(sel[sel["method"] == m]["ratio_db"].iloc[0]) for m in METHODS3}
            band = sel.iloc[0]
            rows.append((br, r.label, f"{band['band_lo_cpd']:.3g}-{band['band_hi_cpd']:.3g}",
                         vals["foveated"], vals["contrast"], vals["ours"]))
    rings = "; ".join(f"{r.label}: {res.n_patches[r.label]} patches, "
                      f"{res.ppd[r.label]:.1f} px/deg" for r in res.rings)
    return "\n".join([
        "# Output spectra (paper section 6.1, Figure \"Fourier analysis\")",
        "",
        f"Images: {', '.join(res.images)}. {res.setup_line}.",
        f"Rings: {rings} (per image). Patches: {res.side_px} x {res.side_px} px, Hann window, "
        "mean removed, non-overlapping grid, a patch counted in the ring its centre lies in. "
        "Spectra of the display-encoded grey (BT.601 luma); power summed over patches and "
        "images before the ratio to full resolution.",
        "",
        "Power in the band [T_L, min(T_H, Nyquist)] relative to full resolution (dB; 0 = "
        "restored), over all images:",
        "",
        table_md(rows, ["blur-rate", "ring", "band (cpd)", "foveated", "contrast", "ours"]),
        "",
        "Files: `spectra.csv` (curves per image and over all: image = all), `bands.csv` (the "
        "table above per image), `spectra.png` (rows: blur-rates, columns: rings).",
        "",
    ])


def run(paths: Sequence[Path], setup: Setup, blur_rates: Sequence[float], out: Path,
        rings: Sequence[Ring] | None = None, side_px: int | None = None) -> SpectraResult:
    """:func:`analyse`, then write ``spectra.csv``, ``bands.csv``, ``spectra.png`` and
    ``spectra.md`` into ``out``."""
    res = analyse(paths, setup, blur_rates, rings, side_px)
    folder = OutFolder(out)
    folder.csv("spectra.csv", res.curves)
    folder.csv("bands.csv", res.bands)
    folder.figure("spectra.png", figure(res))
    folder.note("spectra.md", note(res))
    return res
