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
the frequencies in it. Where Nyquist is at or below T_L (small images: at 960 x 540 on the
paper's display the 10-14 deg ring's Nyquist is 5 cycles/deg, T_L 9.5) the image holds no
frequency of the band: the ring's rows are marked ``above Nyquist`` and the run says so in one
warning, rather than showing a ratio of nothing.

Which scenes: the paper's figure is "averaged over 5 scenes" and does not say which; the
scenes averaged here are the caller's choice (the record uses the five calibration scenes),
and the note says so.

References
----------
.. [tariq] Tariq, T., Tursun, C., Didyk, P. (2022). Noise-based Enhancement for Foveated
   Rendering. ACM Transactions on Graphics 41(4) (SIGGRAPH 2022). doi:10.1145/3528223.3530101
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
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


#: A method's outputs of one image at one blur-rate: ``(image, blur_rate) -> {method: output}``
#: (default: the enhancer's, :func:`.outputs.outputs`; tests pass outputs of known spectra).
OutputsFn = Callable[[np.ndarray, float], dict[str, np.ndarray]]
#: ``band_status`` of a ring whose band holds frequencies of the image, and of one whose band
#: lies above the image's Nyquist frequency.
BAND_OPEN = "open"
BAND_ABOVE_NYQUIST = "above Nyquist"
BAND_BETWEEN_BINS = "no frequency bin in the band"


def ring_band_cpd(ring: Ring, ppd: float) -> tuple[float, float]:
    """The band of ``ring`` in cycles/deg (paper sections 4.1 and 6.1): ``(T_L(e_c),
    min(T_H(e_c), Nyquist))`` at the ring's centre eccentricity e_c, Nyquist being half the
    ring's mean pixels per degree ``ppd``. ``lo >= hi`` when Nyquist is at or below T_L."""
    e_c_deg = ring.centre_deg
    return float(t_low_cpd(e_c_deg)), min(float(t_high_cpd(e_c_deg)), 0.5 * ppd)


def band_status(lo_cpd: float, hi_cpd: float, in_band: np.ndarray) -> str:
    """Whether a band can be measured: :data:`BAND_OPEN`, :data:`BAND_ABOVE_NYQUIST` (the
    image's Nyquist frequency at or below T_L) or :data:`BAND_BETWEEN_BINS`."""
    if not lo_cpd < hi_cpd:
        return BAND_ABOVE_NYQUIST
    return BAND_OPEN if bool(np.any(in_band)) else BAND_BETWEEN_BINS


def band_ratio_db(power: np.ndarray, ref_power: np.ndarray, in_band: np.ndarray) -> float:
    """Power in the band relative to the reference's (dB): the ratio of the sums over the
    frequency bins ``in_band``; NaN for an empty band."""
    if not np.any(in_band):
        return float("nan")
    return float(_ratio_db(np.array(power[in_band].sum()), np.array(ref_power[in_band].sum())))


@dataclass
class SpectraResult:
    """``curves``: image (or ``all``), blur_rate, ring, method, f_cpd, power, ratio_db;
    ``bands``: image (or ``all``), blur_rate, ring, method, band_lo_cpd, band_hi_cpd,
    nyquist_cpd, band_status, ratio_db (NaN unless ``band_status`` is ``open``);
    ``n_patches``: ring -> patch count per image."""

    curves: object  # pandas.DataFrame
    bands: object  # pandas.DataFrame
    side_px: int
    rings: list[Ring]
    n_patches: dict[str, int]
    ppd: dict[str, float]
    images: list[str]
    blur_rates: list[float]
    setup_line: str = ""

    def closed_rings(self) -> list[Ring]:
        """The rings whose band lies above the image's Nyquist frequency."""
        return [r for r in self.rings
                if not ring_band_cpd(r, self.ppd[r.label])[0] < 0.5 * self.ppd[r.label]]

    def nyquist_warning(self) -> str:
        """One line naming the rings whose band lies above Nyquist ("" when none does)."""
        closed = self.closed_rings()
        if not closed:
            return ""
        parts = []
        for r in closed:
            lo, _hi = ring_band_cpd(r, self.ppd[r.label])
            parts.append(f"{r.label} (T_L {lo:.3g} cpd, Nyquist {0.5 * self.ppd[r.label]:.3g} "
                         f"cpd at {self.ppd[r.label]:.1f} px/deg)")
        return ("spectra: the band lies above the image's Nyquist frequency in ring(s) "
                + "; ".join(parts) + ": no frequency of this resolution is in the band, its "
                "rows are marked 'above Nyquist' (use a larger image or other --rings)")


def _ratio_db(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        r = 10.0 * np.log10(num / den)
    return np.where(np.isfinite(r), r, np.nan)


@dataclass
class _Grid:
    """The patches of every ring, fixed by the first image's size."""

    shape: tuple[int, int]
    side_px: int
    per_ring: dict[str, Patches]
    edges_cpd: np.ndarray

    @classmethod
    def make(cls, setup: Setup, shape: tuple[int, int], rings: Sequence[Ring],
             side_px: int | None) -> _Grid:
        h, w = shape
        side_px = side_px or patch_px(w)
        geom = ViewingGeometry.for_image(setup.display, w, h, "exact")
        per_ring = {r.label: ring_patches(geom, setup.gaze, r, side_px) for r in rings}
        for r in rings:
            if not len(per_ring[r.label]):
                raise FovexpError(
                    f"ring {r.label}: no {side_px} px patch of a {w}x{h} image on display "
                    f"{setup.display.name} has its centre there (gaze {setup.gaze}); "
                    "choose rings the image reaches (--rings)")
        edges = bin_edges_cpd(0.5 * max(float(p.ppd.max()) for p in per_ring.values()))
        return cls(shape, side_px, per_ring, edges)

    def power(self, image_grey: np.ndarray, ring: Ring) -> tuple[np.ndarray, np.ndarray]:
        return patch_power(image_grey, self.per_ring[ring.label], self.side_px, self.edges_cpd)


def analyse(paths: Sequence[Path], setup: Setup, blur_rates: Sequence[float],
            rings: Sequence[Ring] | None = None, side_px: int | None = None,
            outputs_fn: OutputsFn | None = None) -> SpectraResult:
    """The spectra of every method's output for each image and blur-rate (module docstring).
    ``outputs_fn``: each method's output of an image at a blur-rate (default: the
    enhancer's)."""
    rings = list(rings or default_rings())
    setup_line = "outputs given by the caller"
    if outputs_fn is None:
        enh = setup.enhancer()
        setup_line = setup.describe(enh)

        def outputs_fn(image: np.ndarray, br: float) -> dict[str, np.ndarray]:
            return outputs(enh, setup, image, br)

    # (image, blur_rate, ring, method) -> (power, count); method "full" is the reference
    acc: dict[tuple[str, float, str, str], tuple[np.ndarray, np.ndarray]] = {}
    names: list[str] = []
    grid: _Grid | None = None
    for name, image in read_images(paths, desc="fovexp evaluate spectra"):
        names.append(name)
        h, w = image.shape[:2]
        if grid is None:
            grid = _Grid.make(setup, (h, w), rings, side_px)
        elif (h, w) != grid.shape:
            raise FovexpError(f"{name}: {w}x{h} px; the images of one run must share one size "
                              f"(the first was {grid.shape[1]}x{grid.shape[0]})")
        full = grey(image)
        for r in rings:
            acc[(name, 0.0, r.label, "full")] = grid.power(full, r)
        for br in blur_rates:
            for method, out in outputs_fn(image, br).items():
                g = grey(out)
                for r in rings:
                    acc[(name, br, r.label, method)] = grid.power(g, r)
    if grid is None:
        raise FovexpError("no images given")
    n_patches = {r.label: len(grid.per_ring[r.label]) for r in rings}
    ring_ppd = {r.label: float(grid.per_ring[r.label].ppd.mean()) for r in rings}
    curves, bands = _tables(acc, names, rings, list(blur_rates), grid.edges_cpd, ring_ppd)
    return SpectraResult(curves, bands, grid.side_px, rings, n_patches, ring_ppd, names,
                         list(blur_rates), setup_line)


def _tables(acc: dict, names: list[str], rings: list[Ring], blur_rates: list[float],
            edges_cpd: np.ndarray, ring_ppd: dict[str, float]) -> tuple[object, object]:
    """The curves and the band table from the accumulated powers (over each image and over
    all of them: power summed before the ratio)."""
    import pandas as pd

    centres = np.sqrt(edges_cpd[:-1] * edges_cpd[1:])
    curves, bands = [], []
    for scope in [*names, "all"]:
        imgs = names if scope == "all" else [scope]
        for r in rings:
            ref_p = sum(acc[(i, 0.0, r.label, "full")][0] for i in imgs)
            cnt = acc[(imgs[0], 0.0, r.label, "full")][1] * len(imgs)
            lo, hi = ring_band_cpd(r, ring_ppd[r.label])
            in_band = (centres >= lo) & (centres <= hi) & (cnt > 0)
            status = band_status(lo, hi, in_band)
            for br in blur_rates:
                for method in METHODS3:
                    p = sum(acc[(i, br, r.label, method)][0] for i in imgs)
                    ratio = _ratio_db(p, ref_p)
                    for k in np.nonzero(cnt > 0)[0]:
                        curves.append({"image": scope, "blur_rate": br, "ring": r.label,
                                       "method": method, "f_cpd": centres[k],
                                       "power": p[k] / cnt[k], "ratio_db": ratio[k]})
                    bands.append({"image": scope, "blur_rate": br, "ring": r.label,
                                  "method": method, "band_lo_cpd": lo, "band_hi_cpd": hi,
                                  "nyquist_cpd": 0.5 * ring_ppd[r.label],
                                  "band_status": status,
                                  "ratio_db": band_ratio_db(p, ref_p, in_band)})
    return pd.DataFrame(curves), pd.DataFrame(bands)


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
            if lo < min(hi, nyq):  # no band above Nyquist
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


#: The paper's words on the figure's scenes (section 6.1, the caption of Figure "Fourier
#: analysis"): five, unnamed.
PAPER_SCENES = "averaged over 5 scenes"


def scenes_line(res: SpectraResult) -> str:
    """Which scenes are averaged, marked as this run's choice: the paper's figure is
    "averaged over 5 scenes" without naming them (section 6.1)."""
    return (f"Scenes (an assumption: the paper's figure is \"{PAPER_SCENES}\" and does not "
            f"say which): {len(res.images)} image(s) chosen for this run, "
            f"{', '.join(res.images)}.")


def _band_cells(band: object, ratios: dict[str, float]) -> tuple[str, ...]:
    """The band and the three methods' ratios of one table row; a band above Nyquist or
    between two frequency bins is said as such, never left as NaN."""
    lo, hi, status = band["band_lo_cpd"], band["band_hi_cpd"], band["band_status"]  # type: ignore[index]
    if status == BAND_ABOVE_NYQUIST:
        return (f"none: T_L {lo:.3g} >= Nyquist {band['nyquist_cpd']:.3g}",  # type: ignore[index]
                *([BAND_ABOVE_NYQUIST] * len(METHODS3)))
    if status != BAND_OPEN:
        return (f"{lo:.3g}-{hi:.3g}", *([status] * len(METHODS3)))
    return (f"{lo:.3g}-{hi:.3g}", *(f"{ratios[m]:.4g}" for m in METHODS3))


def note(res: SpectraResult) -> str:
    """The Markdown note: settings, scenes (an assumption), rings and patches, the band ratios
    over the images, a band above Nyquist in one line."""
    b = res.bands
    allb = b[b["image"] == "all"]  # type: ignore[index]
    rows = []
    for br in res.blur_rates:
        for r in res.rings:
            sel = allb[(allb["blur_rate"] == br) & (allb["ring"] == r.label)]
            vals = {m: float(sel[sel["method"] == m]["ratio_db"].iloc[0]) for m in METHODS3}
            rows.append((br, r.label, *_band_cells(sel.iloc[0], vals)))
    rings = "; ".join(f"{r.label}: {res.n_patches[r.label]} patches, "
                      f"{res.ppd[r.label]:.1f} px/deg" for r in res.rings)
    warning = res.nyquist_warning()
    return "\n".join([
        "# Output spectra (paper section 6.1, Figure \"Fourier analysis\")",
        "",
        scenes_line(res),
        "",
        f"{res.setup_line}.",
        f"Rings: {rings} (per image). Patches: {res.side_px} x {res.side_px} px, Hann window, "
        "mean removed, non-overlapping grid, a patch counted in the ring its centre lies in. "
        "Spectra of the display-encoded grey (BT.601 luma); power summed over patches and "
        "images before the ratio to full resolution.",
        "",
        "Power in the band [T_L, min(T_H, Nyquist)] at the ring's centre eccentricity, "
        "relative to full resolution (dB; 0 = restored), over all images:",
        "",
        table_md(rows, ["blur-rate", "ring", "band (cpd)", "foveated", "contrast", "ours"]),
        "",
        *([f"**Warning**: {warning}.", ""] if warning else []),
        "Files: `spectra.csv` (curves per image and over all: image = all), `bands.csv` (the "
        "table above per image, with `band_status`), `spectra.png` (rows: blur-rates, "
        "columns: rings).",
        "",
    ])


def run(paths: Sequence[Path], setup: Setup, blur_rates: Sequence[float], out: Path,
        rings: Sequence[Ring] | None = None, side_px: int | None = None) -> SpectraResult:
    """:func:`analyse`, then write ``spectra.csv``, ``bands.csv``, ``spectra.png`` and
    ``spectra.md`` into ``out``; a band above Nyquist is also a warning (one line)."""
    res = analyse(paths, setup, blur_rates, rings, side_px)
    folder = OutFolder(out)
    folder.csv("spectra.csv", res.curves)
    folder.csv("bands.csv", res.bands)
    folder.figure("spectra.png", figure(res))
    folder.note("spectra.md", note(res))
    warning = res.nyquist_warning()
    if warning:
        warnings.warn(warning, UserWarning, stacklevel=2)
    return res
