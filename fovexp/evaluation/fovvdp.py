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
The paper reports these p-values only: no mean differences, effect sizes or per-scene JODs, so
a record can compare its p-values and signs with the paper's, nothing more.

Beside the foveated mode, the metric is also run non-foveated (``foveated=False``: every pixel
judged as if fixated), and the note gives the per-scene differences in both modes: whether a
difference between the methods comes from the model of the periphery or is there anyway.

The parameters (f_e, s_k, s_f) come from Table 2 at the blur-rate; Table 2 stops at 0.57 and
the paper's FovVDP figure is at 0.68, where ``fovexp.ParameterTable`` holds the 0.57 row (the
paper does not say what it used there). Such a clamp is said in one warning line and in the
note (:func:`.outputs.table2_clamp`).

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
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fovexp import Display, FovexpError

from .outputs import (
    METHODS3,
    OutFolder,
    Setup,
    colour_of,
    outputs,
    pyplot,
    read_images,
    table2_clamp,
    table_md,
)

#: The paper's t-tests: (a, b) of each paired test a - b.
TESTS = (("foveated", "contrast"), ("foveated", "ours"), ("ours", "contrast"))
#: The blur-rate of the paper's FovVDP figure (section 6.1).
PAPER_BLUR_RATE = 0.68
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
                 contrast_ratio: float = 1000.0, device: str = "cpu",
                 foveated: bool = True) -> None:
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
                                    foveated=foveated, heatmap=None, quiet=True,
                                    device=self.device)
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


#: FovVDP's modes: with its model of the periphery around the fixation (the paper's), and
#: without (every pixel as if fixated).
MODES = ("foveated", "non-foveated")
#: Each mode's JOD and timing columns in :attr:`FovvdpResult.jod`.
JOD_COLUMN = {"foveated": "jod", "non-foveated": "jod_nonfoveated"}
SECONDS_COLUMN = {"foveated": "seconds", "non-foveated": "seconds_nonfoveated"}


@dataclass
class FovvdpResult:
    """``jod``: image, method, jod (foveated mode), seconds, and with the non-foveated mode
    jod_nonfoveated, seconds_nonfoveated; ``tests``: mode, a, b, n, mean_a, mean_b,
    mean_diff, t, df, p, paper_p; ``clamp``: the line saying Table 2 was clamped ("" if
    not)."""

    jod: object  # pandas.DataFrame
    tests: object  # pandas.DataFrame
    blur_rate: float
    images: list[str]
    ppd: float
    setup_line: str = ""
    clamp: str = ""

    @property
    def modes(self) -> list[str]:
        return [m for m in MODES if JOD_COLUMN[m] in self.jod.columns]  # type: ignore[attr-defined]


def paired_tests(jod: Any, modes: Sequence[str]) -> Any:
    """The paper's three paired t-tests across scenes (section 6.1) in each mode: a DataFrame
    of mode, a, b, n, mean_a, mean_b, mean_diff, t, df, p, paper_p."""
    import pandas as pd

    from fovexp.analysis.stats import paired_ttest

    tests = []
    for mode in modes:
        wide = jod.pivot(index="image", columns="method", values=JOD_COLUMN[mode])
        for a, b in TESTS:
            r = paired_ttest(wide[a].to_numpy(), wide[b].to_numpy())
            tests.append({"mode": mode, "a": a, "b": b, "n": r.n, "mean_a": r.mean_a,
                          "mean_b": r.mean_b, "mean_diff": r.mean_diff, "t": r.t, "df": r.df,
                          "p": r.p, "paper_p": PAPER_P[(a, b)] if mode == "foveated" else "-"})
    return pd.DataFrame(tests)


def analyse(paths: Sequence[Path], setup: Setup, blur_rate: float,
            contrast_ratio: float = 1000.0, device: str = "cpu",
            nonfoveated: bool = True) -> FovvdpResult:
    """JOD of each method's output against the full-resolution image, per scene, in the
    foveated mode (fixation at the gaze) and, with ``nonfoveated``, the non-foveated one;
    the paper's t-tests in each mode (module docstring)."""
    import pandas as pd

    _import()  # the extra's absence as one line, before any enhancement
    modes = MODES if nonfoveated else MODES[:1]
    enh = setup.enhancer()
    metrics: dict[str, Metric] = {}
    rows, names = [], []
    for name, image in read_images(paths, desc="fovexp evaluate fovvdp"):
        h, w = image.shape[:2]
        if not metrics:
            metrics = {m: Metric(setup.display, w, h, contrast_ratio, device,
                                 foveated=m == "foveated") for m in modes}
        elif metrics["foveated"].shape != (h, w):
            raise FovexpError(f"{name}: {w}x{h} px; the images of one run must share one size")
        names.append(name)
        gaze_px = (setup.gaze[0] * w - 0.5, setup.gaze[1] * h - 0.5)
        for method, out in outputs(enh, setup, image, blur_rate).items():
            row: dict[str, Any] = {"image": name, "method": method}
            for mode, metric in metrics.items():
                t0 = time.perf_counter()
                row[JOD_COLUMN[mode]] = metric.jod(out, image, gaze_px)
                row[SECONDS_COLUMN[mode]] = time.perf_counter() - t0
            rows.append(row)
    if not metrics:
        raise FovexpError("no images given")
    jod = pd.DataFrame(rows)
    return FovvdpResult(jod, paired_tests(jod, modes), blur_rate, names,
                        metrics["foveated"].ppd, setup.describe(enh),
                        table2_clamp(blur_rate) if setup.preset == "paper" else "")


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


#: What the paper states about the FovVDP result (section 6.1): the three p-values, nothing
#: else (no mean differences, effect sizes or per-scene JODs).
PAPER_STATES = ("The paper reports only the three p-values (foveated mode): foveated - "
                "contrast and foveated - ours p < 0.001, ours - contrast p = 0.07; it gives no "
                "mean differences, effect sizes or per-scene JODs, so only the p-values and "
                "the signs can be compared with it.")


def per_scene(res: FovvdpResult) -> list[tuple[Any, ...]]:
    """Per scene and mode: the three JODs, ours - contrast and foveated - contrast."""
    rows = []
    for image in res.images:
        sel = res.jod[res.jod["image"] == image].set_index("method")  # type: ignore[index]
        for mode in res.modes:
            q = sel[JOD_COLUMN[mode]]
            rows.append((image, mode, *(float(q[m]) for m in METHODS3),
                         float(q["ours"] - q["contrast"]), float(q["foveated"] - q["contrast"])))
    return rows


def sign_agreement(res: FovvdpResult, a: str = "ours", b: str = "contrast") -> str:
    """In how many scenes ``a - b`` has the same sign in both modes ("" with one mode)."""
    if len(res.modes) < 2:
        return ""
    wide = {m: res.jod.pivot(index="image", columns="method",  # type: ignore[attr-defined]
                             values=JOD_COLUMN[m]) for m in res.modes}
    d = {m: np.sign((w[a] - w[b]).to_numpy()) for m, w in wide.items()}
    same = int((d["foveated"] == d["non-foveated"]).sum())
    return (f"{a} - {b} has the same sign in both modes in {same} of {len(res.images)} "
            "scene(s).")


def note(res: FovvdpResult) -> str:
    """The Markdown note: a clamp of Table 2 in one line, the mean JODs and t-tests in each
    mode, what the paper states, the per-scene differences in both modes."""
    jod = res.jod
    means = [(mode, *(float(jod.loc[jod["method"] == m, JOD_COLUMN[mode]].mean())  # type: ignore[attr-defined,index]
                      for m in METHODS3)) for mode in res.modes]
    tests = [(r.mode, f"{r.a} - {r.b}", r.n, r.mean_diff, r.t, r.p, r.paper_p)
             for r in res.tests.itertuples()]  # type: ignore[attr-defined]
    secs = float(jod["seconds"].mean())  # type: ignore[index]
    clamp = ([f"**Parameters clamped**: {res.clamp}. The paper's FovVDP figure is at "
              f"{PAPER_BLUR_RATE:g}, beyond Table 2, and does not say which parameters it "
              "used there.", ""] if res.clamp else [])
    agreement = sign_agreement(res)
    return "\n".join([
        "# FovVDP (paper section 6.1, Figure \"FovVDP outputs\")",
        "",
        f"Images: {', '.join(res.images)}; blur-rate {res.blur_rate:g}. {res.setup_line}.",
        "",
        *clamp,
        f"pyfvvdp in {' and '.join(res.modes)} mode (foveated: fixation at the gaze, the "
        "paper's; non-foveated: every pixel as if fixated); display model from the profile "
        f"({res.ppd:.1f} px/deg at the centre). {secs:.1f} s per foveated JOD on average.",
        "",
        "Mean JOD:",
        "",
        table_md(means, ["mode", *METHODS3]),
        "",
        "Paired t-tests across scenes (two-sided):",
        "",
        table_md(tests, ["mode", "test", "n", "mean diff (JOD)", "t", "p", "paper's p"]),
        "",
        PAPER_STATES,
        "",
        "Per scene (JOD, and the differences between the methods) in each mode:",
        "",
        table_md(per_scene(res), ["scene", "mode", *METHODS3, "ours - contrast",
                                  "foveated - contrast"]),
        "",
        *([agreement, ""] if agreement else []),
        "Files: `fovvdp.csv` (JOD per scene and method: `jod` foveated, `jod_nonfoveated`), "
        "`fovvdp-tests.csv` (per mode), `fovvdp.png` (foveated mode).",
        "",
    ])


def run(paths: Sequence[Path], setup: Setup, blur_rate: float, out: Path,
        contrast_ratio: float = 1000.0, device: str = "cpu",
        nonfoveated: bool = True) -> FovvdpResult:
    """:func:`analyse`, then ``fovvdp.csv``, ``fovvdp-tests.csv``, ``fovvdp.png`` and
    ``fovvdp.md`` into ``out``; a clamp of Table 2 is also a warning (one line)."""
    _import()  # the extra's absence first, as the only line
    clamp = table2_clamp(blur_rate) if setup.preset == "paper" else ""
    if clamp:  # said before the (long) run, not after it
        warnings.warn(f"fovvdp: {clamp}", UserWarning, stacklevel=2)
    res = analyse(paths, setup, blur_rate, contrast_ratio, device, nonfoveated)
    folder = OutFolder(out)
    folder.csv("fovvdp.csv", res.jod)
    folder.csv("fovvdp-tests.csv", res.tests)
    folder.figure("fovvdp.png", figure(res))
    folder.note("fovvdp.md", note(res))
    return res
