"""FovVDP of the outputs (paper section 6.1, Figure "FovVDP outputs").

FovVideoVDP (Mantiuk et al. 2021, the ``pyfvvdp`` package: the optional ``[fovvdp]`` extra,
licensed CC BY-NC 4.0, see the README) predicts the visible difference between a test image
and a reference in just-objectionable differences (JOD: 10 = identical, lower is worse) with
a model of peripheral acuity. Here the reference is the full-resolution image and the tests
are the three methods' outputs; the fixation is the gaze.

The display model is built from fovexp's display profile, not from pyfvvdp's named displays:
photometry ``fvvdp_display_photo_eotf`` with the profile's peak luminance and gamma (EOTF
``gamma``), a contrast ratio (``--contrast-ratio``, default pyfvvdp's 1000:1) and no ambient
light (the paper's dark curtain); geometry ``fvvdp_display_geometry`` with the image's
resolution, the profile's viewing distance and its diagonal from width and height (an image
smaller than the display is shown full screen, as everywhere in fovexp).

The paper's three paired t-tests across scenes: foveated against contrast and against ours
(there p < 0.001: foveation is worse), and ours against contrast (p = 0.07: FovVDP barely
tells them apart, which the paper attributes to its CSF's low sensitivity in the aliasing band).

References
----------
.. [tariq] Tariq, T., Tursun, C., Didyk, P. (2022). Noise-based Enhancement for Foveated
   Rendering. ACM Transactions on Graphics 41(4) (SIGGRAPH 2022). doi:10.1145/3528223.3530101
.. [mantiuk] Mantiuk, R. K., Denes, G., Chapiro, A., Kaplanyan, A., Rufo, G., Bachy, R.,
   Lian, T., Patney, A. (2021). FovVideoVDP: A Visible Difference Predictor for Wide
   Field-of-View Video. ACM Transactions on Graphics 40(4). doi:10.1145/3450626.3459831
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fovexp import Display, FovexpError

from .outputs import METHODS3, OutFolder, Setup, colour_of, outputs, pyplot, read_images, table_md

#: The paper's t-tests: (a, b) of each paired test a - b.
TESTS = (("foveated", "contrast"), ("foveated", "ours"), ("ours", "contrast"))
#: What the paper reports for them (section 6.1).
PAPER_P = {("foveated", "contrast"): "< 0.001", ("foveated", "ours"): "< 0.001",
           ("ours", "contrast"): "0.07"}
INSTALL_HINT = ("the FovVDP analysis needs the [fovvdp] extra (pyfvvdp, CC BY-NC 4.0) and "
                "PyTorch: install a CPU build of torch first, then pip install 'fovexp[fovvdp]' "
                "(README, 'FovVDP')")


def _import() -> tuple[Any, Any]:
    try:
        import pyfvvdp
        import torch
    except ImportError as exc:
        raise FovexpError(f"{INSTALL_HINT}; missing: {exc.name}") from None
    return torch, pyfvvdp


class Metric:
    """pyfvvdp's metric with the display model of a fovexp display profile, for images of
    one size."""

    def __init__(self, display: Display, width_px: int, height_px: int,
                 contrast_ratio: float = 1000.0, device: str = "cpu") -> None:
        torch, pyfvvdp = _import()
        from pyfvvdp.fvvdp_display_model import (
            fvvdp_display_geometry,
            fvvdp_display_photo_eotf,
        )

        self.torch = torch
        photometry = fvvdp_display_photo_eotf(
            display.peak_luminance_cd_m2, contrast=contrast_ratio, EOTF="gamma",
            gamma=display.gamma, E_ambient=0.0, name=display.name)
        diagonal_in = math.hypot(display.width_cm, display.height_cm) / 2.54
        geometry = fvvdp_display_geometry((width_px, height_px),
                                          distance_m=display.distance_cm / 100.0,
                                          diagonal_size_inches=diagonal_in)
        try:
            self.device = torch.device(device)
        except RuntimeError as exc:
            raise FovexpError(f"--device {device!r}: {exc}") from None
        self.metric = pyfvvdp.fvvdp(display_photometry=photometry, display_geometry=geometry,
                                    foveated=True, heatmap=None, quiet=True, device=self.device)
        self.ppd = float(geometry.get_ppd())
        self.shape = (height_px, width_px)

    def jod(self, test: np.ndarray, reference: np.ndarray, fixation_px: tuple[float, float]
            ) -> float:
        """JOD of ``test`` against ``reference`` (display-encoded, [0, 1], same shape)."""
        t, r = (np.ascontiguousarray(colour_of(a), dtype=np.float32) for a in (test, reference))
        if t.ndim == 2:
            t, r = t[..., None], r[..., None]
        fix = self.torch.tensor([float(fixation_px[0]), float(fixation_px[1])])
        with self.torch.no_grad():
            q, _stats = self.metric.predict(self.torch.from_numpy(t), self.torch.from_numpy(r),
                                            dim_order="HWC", fixation_point=fix)
        return float(q)


@dataclass
class FovvdpResult:
    """``jod``: image, method, jod, seconds; ``tests``: a, b, n, mean_a, mean_b, mean_diff,
    t, df, p, paper_p."""

    jod: object  # pandas.DataFrame
    tests: object  # pandas.DataFrame
    blur_rate: float
    images: list[str]
    ppd: float
    setup_line: str = ""


def analyse(paths: Sequence[Path], setup: Setup, blur_rate: float,
            contrast_ratio: float = 1000.0, device: str = "cpu") -> FovvdpResult:
    import pandas as pd

    from fovexp.analysis.stats import paired_ttest

    _import()  # the extra's absence as one line, before any enhancement
    enh = setup.enhancer()
    metric: Metric | None = None
    rows, names = [], []
    for name, image in read_images(paths):
        h, w = image.shape[:2]
        if metric is None:
            metric = Metric(setup.display, w, h, contrast_ratio, device)
        elif metric.shape != (h, w):
            raise FovexpError(f"{name}: {w}x{h} px; the images of one run must share one size")
        names.append(name)
        gaze_px = (setup.gaze[0] * w - 0.5, setup.gaze[1] * h - 0.5)
        for method, out in outputs(enh, setup, image, blur_rate).items():
            t0 = time.perf_counter()
            q = metric.jod(out, image, gaze_px)
            rows.append({"image": name, "method": method, "jod": q,
                         "seconds": time.perf_counter() - t0})
    if metric is None:
        raise FovexpError("no images given")
    jod = pd.DataFrame(rows)
    wide = jod.pivot(index="image", columns="method", values="jod")
    tests = []
    for a, b in TESTS:
        r = paired_ttest(wide[a].to_numpy(), wide[b].to_numpy())
        tests.append({"a": a, "b": b, "n": r.n, "mean_a": r.mean_a, "mean_b": r.mean_b,
                      "mean_diff": r.mean_diff, "t": r.t, "df": r.df, "p": r.p,
                      "paper_p": PAPER_P[(a, b)]})
    return FovvdpResult(jod, pd.DataFrame(tests), blur_rate, names, metric.ppd,
                        setup.describe(enh))


def figure(res: FovvdpResult):  # noqa: ANN201
    """JOD per scene and method (the paper's left panel), scenes in the order given."""
    plt = pyplot()
    df = res.jod
    fig, ax = plt.subplots(figsize=(max(5.0, 0.55 * len(res.images) + 2.5), 3.3))
    colours = {"foveated": "tab:grey", "contrast": "tab:blue", "ours": "tab:orange"}
    x = np.arange(len(res.images))
    for k, m in enumerate(METHODS3):
        sel = df[df["method"] == m].set_index("image").loc[res.images]  # type: ignore[index]
        ax.bar(x + (k - 1) * 0.27, sel["jod"], width=0.27, label=m, color=colours[m])
    ax.set_xticks(x, res.images, rotation=45, ha="right", fontsize=8)
    ax.set_ylabel("FovVDP (JOD)")
    lo = float(df["jod"].min())  # type: ignore[index]
    ax.set_ylim(max(0.0, lo - 0.5), 10.0)
    ax.legend(fontsize=8, ncol=3)
    ax.set_title(f"FovVDP against full resolution, blur-rate {res.blur_rate:g}", fontsize=9)
    fig.tight_layout()
    return fig


def note(res: FovvdpResult) -> str:
    jod = res.jod
    means = jod.groupby("method")["jod"].mean()  # type: ignore[attr-defined]
    rows = [(f"{r.a} - {r.b}", r.n, r.mean_diff, r.t, r.p, r.paper_p)
            for r in res.tests.itertuples()]  # type: ignore[attr-defined]
    secs = float(jod["seconds"].mean())  # type: ignore[index]
    return "\n".join([
        "# FovVDP (paper section 6.1, Figure \"FovVDP outputs\")",
        "",
        f"Images: {', '.join(res.images)}; blur-rate {res.blur_rate:g}. {res.setup_line}.",
        f"pyfvvdp, foveated mode, fixation at the gaze; display model from the profile "
        f"({res.ppd:.1f} px/deg at the centre). {secs:.1f} s per JOD on average.",
        "",
        "Mean JOD: " + ", ".join(f"{m} {means[m]:.3f}" for m in METHODS3) + ".",
        "",
        "Paired t-tests across scenes (two-sided):",
        "",
        table_md(rows, ["test", "n", "mean diff (JOD)", "t", "p", "paper's p"]),
        "",
        "Files: `fovvdp.csv` (JOD per scene and method), `fovvdp-tests.csv`, `fovvdp.png`.",
        "",
    ])


def run(paths: Sequence[Path], setup: Setup, blur_rate: float, out: Path,
        contrast_ratio: float = 1000.0, device: str = "cpu") -> FovvdpResult:
    res = analyse(paths, setup, blur_rate, contrast_ratio, device)
    folder = OutFolder(out)
    folder.csv("fovvdp.csv", res.jod)
    folder.csv("fovvdp-tests.csv", res.tests)
    folder.figure("fovvdp.png", figure(res))
    folder.note("fovvdp.md", note(res))
    return res
