"""What if the noise were added to display-encoded values? A what-if beside benchmarks/CLIPPING.md.

fovexp adds the noise (and the contrast change) to every channel of the linear-light image and
encodes afterwards, as the authors' release adds it to linear Y (docs/METHOD.md, 5.4). The
paper's section 4.5 ends "The resulting noise contains only luminance information that is added
to the input color images after gamma correction", which can also be read as adding it to the
encoded values. This script measures what that reading would change, with an enhancer whose
clipping extremes and composition are moved to encoded values (a subclass for this measurement
only, not an engine option): the same K from eq. 9, capped by one level-3 block of the encoded
luminance (the paper's rule, in encoded values), added to the encoded contrast image.

For the linear paper rule and the encoded variant, on Sponza 4K and the first generated scenes
at 0.34 and 0.57: the band's power against full resolution per ring (dB), the share of output
values the display clips, and the noise's std past 16 deg against s_k (the wheel's curve, from
the s_k protocol's first step to its top), Sponza at 0.34.

    .venv/bin/python benchmarks/clipping_space.py [--scenes N]

writes ``clipping_space.json`` and ``clipping_space.md`` beside this file (or into ``--out``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from fovexp import (
    EngineOptions,
    Enhancer,
    colour,
    load_display,
    make_params,
    pyramids,
    read_image,
)
from fovexp import amplitude as amp
from fovexp.bench import machine_cpu
from fovexp.evaluation.spectra import default_rings

sys.path.insert(0, str(Path(__file__).resolve().parent))
from clipping import ROOT, SPONZA, RingSpectra, db, in_band  # noqa: E402

S_K_CURVE = (1.5, 3.0, 6.0, 12.0, 21.02, 30.0, 42.04, 45.0)


class EncodedEnhancer(Enhancer):
    """The noise added to display-encoded values, capped by the extremes of one level-3 block
    of the encoded luminance (the measurement's what-if; module docstring)."""

    def _headroom(self, foveated, luma, delta):
        enc = colour.encode(foveated, self._gamma(), self.preset.transfer, delta)
        lum = colour.luminance(enc) if enc.ndim == 3 else enc
        lo, hi = pyramids.block_extremes(lum, self.preset.minmax_level)
        return amp.Extremes("blocks", lo, hi, pyramids.level_scale(self.preset.minmax_level))

    def _compose(self, method, foveated, contrast, noise):
        if method != "ours":
            return super()._compose(method, foveated, contrast, noise)
        enc = colour.encode(foveated, self._gamma(), self.preset.transfer, contrast())
        n = noise()
        return np.clip(enc + (n[..., None] if enc.ndim == 3 else n), 0, 1).astype(enc.dtype)


def variants(display):
    return {"linear (paper rule)": Enhancer(display, options=EngineOptions(clipping="paper")),
            "encoded (paper rule)": EncodedEnhancer(display,
                                                    options=EngineOptions(clipping="paper"))}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenes", type=int, default=3)
    ap.add_argument("--out", type=Path, default=Path(__file__).resolve().parent)
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    display = load_display("lg-oled55cx")
    gen = ROOT / "stimuli" / "generated" / "3840x2160"
    images = ([("sponza", SPONZA)] if SPONZA.exists() else []) + [
        (p.stem, p) for p in sorted(gen.glob("scene-*.png"))[:args.scenes]]
    rings = default_rings()
    bands, curve = [], []
    for name, path in images:
        image = read_image(path)
        spec = RingSpectra(display, image, rings)
        ppd, edges, full = spec.ppd, spec.edges, spec.full
        for label, enh in variants(display).items():
            enh.set_image(image)
            for br in (0.34, 0.57):
                res = enh.enhance((0.5, 0.5), make_params(blur_rate=br))
                out = res.output
                ecc = res.map("eccentricity_deg")
                pw = spec.power(out)
                noise = res.map("noise")
                if isinstance(enh, EncodedEnhancer):
                    base = colour.encode(enh.linear("contrast"), enh._gamma())
                else:
                    base = enh.linear("contrast")
                v = base + (noise[..., None] if base.ndim == 3 else noise)
                for r in rings:
                    mask, _, _ = in_band(r, ppd[r.label], edges)
                    sel = (ecc >= r.lo_deg) & (ecc < r.hi_deg)
                    vv = v[sel]
                    bands.append({"image": name, "variant": label, "blur_rate": br,
                                  "ring": r.label, "ours_power": float(pw[r.label][mask].sum()),
                                  "full_power": float(full[r.label][mask].sum()),
                                  "clips": float(((vv < 0) | (vv > 1)).mean())})
                if name == "sponza" and br == 0.34:
                    past = ecc > 16.0
                    for s_k in S_K_CURVE:
                        n = enh.enhance((0.5, 0.5), make_params(blur_rate=br, s_k=s_k))
                        curve.append({"variant": label, "s_k": s_k,
                                      "std": float(n.map("noise")[past].std())})
                print(f"{name} {label} {br}", flush=True)
    lines = ["# The noise in encoded values: a what-if (issue 26)", "",
             f"Machine: {machine_cpu()}; {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; "
             f"`python benchmarks/clipping_space.py {' '.join(argv or sys.argv[1:])}` "
             f"({time.perf_counter() - t0:.0f} s). Images: "
             f"{', '.join(n for n, _ in images)}; Table 2's parameters, 64 impulses.", "",
             "| blur-rate | ring | variant | ours dB (all images) | clips |",
             "|---|---|---|---|---|"]
    for br in (0.34, 0.57):
        for r in rings:
            for label in variants(display):
                sel = [b for b in bands if b["blur_rate"] == br and b["ring"] == r.label
                       and b["variant"] == label]
                ratio = db(sum(b["ours_power"] for b in sel), sum(b["full_power"] for b in sel))
                lines.append(f"| {br:g} | {r.label} | {label} | {ratio:.1f} | "
                             f"{100 * np.mean([b['clips'] for b in sel]):.2f} % |")
    lines += ["", "The wheel's curve: the noise's std past 16 deg against s_k (Sponza 4K, 0.34; "
              "linear light for the linear variant, encoded values for the encoded one).", "",
              "| s_k | " + " | ".join(variants(display)) + " |", "|---|---|---|"]
    for s_k in S_K_CURVE:
        vals = [next(c["std"] for c in curve if c["variant"] == v and c["s_k"] == s_k)
                for v in variants(display)]
        lines.append(f"| {s_k:g} | " + " | ".join(f"{x:.4f}" for x in vals) + " |")
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    (out / "clipping_space.json").write_text(json.dumps({"bands": bands, "curve": curve},
                                                        indent=1))
    (out / "clipping_space.md").write_text("\n".join(lines) + "\n")
    print(f"wrote {out / 'clipping_space.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
