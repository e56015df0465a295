"""Where the noise's strength goes: the clipping control's neighbourhoods side by side (issue 26).

For each clipping rule (``EngineOptions.clipping``: paper, widened, release, exact, and off,
the uncapped K of eq. 9), each image (the shared Sponza frame and the 15 generated scenes) and
each of Table 2's blur-rates, with Table 2's parameters, 64 impulses, gaze at the centre:

- the fraction of the band-open pixels in each ring where the cap binds (K below the uncapped
  K of rule ``off``), and the median K;
- the band's power against full resolution per ring, in dB (the spectra of
  ``fovexp evaluate spectra``: display-encoded grey, Hann-windowed patches, power summed over
  patches and images before the ratio);
- the fraction of the ring's output values (pixel x channel) the noise pushes out of [0, 1]
  before the display clips them, and by how much (the mean and the 99th percentile of the
  excess, linear light);
- the wheel's reach: the noise's std past 16 deg at the s_k protocol's lowest step, Table 2's
  s_k, twice it and the protocol's highest (calibration-sk: 0..45).

And one measurement of the space the noise is added in: on the band-open pixels the display
does not clip, linear(output) - linear(contrast output) against the noise map, and the same
difference of the display-encoded values.

    .venv/bin/python benchmarks/clipping.py [--quick] [--images N] [--out benchmarks]

writes ``clipping.json`` and ``CLIPPING.md`` (the record: benchmarks/CLIPPING.md).
"""

from __future__ import annotations

import argparse
import gc
import json
import math
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

from fovexp import (
    PAPER_TABLE2,
    EngineOptions,
    Enhancer,
    ViewingGeometry,
    load_display,
    make_params,
    read_image,
)
from fovexp.bench import machine_cpu
from fovexp.evaluation.outputs import grey
from fovexp.evaluation.spectra import (
    bin_edges_cpd,
    default_rings,
    patch_power,
    patch_px,
    ring_band_cpd,
    ring_patches,
)
from fovexp.params import RELEASE_TABLE

ROOT = Path(__file__).resolve().parents[1]
SPONZA = ROOT.parent / "shared" / "stimuli" / "sponza-4k.jpg"
RULES = ("paper", "widened", "release", "exact", "off")
BLUR_RATES = (0.11, 0.34, 0.57)
#: the s_k protocol's range (protocols/calibration-sk.yaml: 0..45, step 1.5): its first step
SK_WHEEL = (1.5, 45.0)
PAST_DEG = 16.0


def band_power(img_grey, per_ring, side_px, edges):
    return {label: patch_power(img_grey, pt, side_px, edges)[0] for label, pt in per_ring.items()}


def in_band(ring, ppd, edges):
    """The frequency bins in the ring's band (``fovexp evaluate spectra``'s), and the band."""
    centres = np.sqrt(edges[:-1] * edges[1:])
    lo, hi = ring_band_cpd(ring, ppd)
    return (centres >= lo) & (centres <= hi), lo, hi


class RingSpectra:
    """The spectra's set-up for one image (``fovexp evaluate spectra``'s rings, patches and
    frequency bins, gaze at the centre) and the full-resolution image's band power."""

    def __init__(self, display, image, rings):
        h, w = image.shape[:2]
        geom = ViewingGeometry.for_image(display, w, h, "exact")
        self.side = patch_px(w)
        self.per_ring = {r.label: ring_patches(geom, (0.5, 0.5), r, self.side) for r in rings}
        self.ppd = {k: float(v.ppd.mean()) for k, v in self.per_ring.items()}
        self.edges = bin_edges_cpd(0.5 * max(float(p.ppd.max())
                                             for p in self.per_ring.values()))
        self.full = self.power(image)

    def power(self, image):
        """Band power per ring (label -> power per frequency bin) of an image's grey."""
        return band_power(grey(image), self.per_ring, self.side, self.edges)


def measure(images, presets, blur_rates, rules, quick, release_images=1):
    display = load_display("lg-oled55cx")
    rings = default_rings()
    out = {"rows": [], "wheel": [], "space": []}
    for preset in presets:
        table = PAPER_TABLE2 if preset == "paper" else RELEASE_TABLE
        for name, path in (images if preset == "paper" else images[:release_images]):
            image = read_image(path)
            spec = RingSpectra(display, image, rings)
            ppd, edges, full = spec.ppd, spec.edges, spec.full
            ecc = None
            for br in blur_rates:
                f_e, s_k, s_f = table.at(br)
                k_off = None
                k_maps, this = {}, {}
                for rule in rules:
                    t0 = time.perf_counter()
                    enh = Enhancer(display, preset=preset,
                                   options=EngineOptions(clipping=rule))
                    enh.set_image(image)
                    res = enh.enhance((0.5, 0.5), make_params(
                        blur_rate=br, preset=preset, impulses=64, seed=1))
                    if ecc is None:
                        ecc = res.map("eccentricity_deg")
                    k = res.map("amplitude")
                    k_maps[rule] = k
                    if rule == "off":
                        k_off = k
                    noise = res.map("noise")
                    lin = enh.linear("contrast") + (noise[..., None] if image.ndim == 3
                                                    else noise)
                    row = {"preset": preset, "image": name, "blur_rate": br, "rule": rule,
                           "s_k": s_k, "rings": {}}
                    powers = {"ours": spec.power(res.output)}
                    if rule == rules[0]:
                        for m in ("foveated", "contrast"):
                            r2 = enh.enhance((0.5, 0.5), make_params(
                                method=m, blur_rate=br, preset=preset))
                            powers[m] = spec.power(r2.output)
                    for r in rings:
                        sel = (ecc >= r.lo_deg) & (ecc < r.hi_deg)
                        mask, lo, hi = in_band(r, ppd[r.label], edges)
                        ring = {"band_cpd": [lo, hi], "ppd": ppd[r.label],
                                "full_power": float(full[r.label][mask].sum())}
                        for m, pw in powers.items():
                            ring[f"{m}_power"] = float(pw[r.label][mask].sum())
                        ring["median_K"] = float(np.median(k[sel & (k > 0)])) if (
                            sel & (k > 0)).any() else 0.0
                        ring["noise_std"] = float(noise[sel].std())
                        sel3 = sel[..., None] if lin.ndim == 3 else sel
                        v = lin[np.broadcast_to(sel3, lin.shape)]
                        excess = np.maximum(v - 1.0, 0.0) + np.maximum(-v, 0.0)
                        ring["clip_fraction"] = float((excess > 0).mean())
                        ring["clip_excess_mean"] = float(excess[excess > 0].mean()) if (
                            excess > 0).any() else 0.0
                        ring["clip_excess_p99"] = float(np.quantile(excess[excess > 0], 0.99)
                                                        ) if (excess > 0).any() else 0.0
                        # what the display's clip takes away, against the noise's own power
                        n_sel = noise[sel].astype(np.float64)
                        n_pow = float((n_sel**2).sum()) * (lin.shape[-1] if lin.ndim == 3
                                                           else 1)
                        ring["clip_residual_db"] = db(float((excess.astype(np.float64)**2
                                                             ).sum()), n_pow)
                        row["rings"][r.label] = ring
                    row["seconds"] = time.perf_counter() - t0
                    out["rows"].append(row)
                    this[rule] = row
                    # an enhancer's stage cache refers to it from its stages: a cycle, which
                    # holds a 4K frame's gigabytes until the cycle collector runs
                    del enh, res, noise, lin
                    gc.collect()
                    print(f"{preset} {name} {br} {rule}: {row['seconds']:.1f} s", flush=True)
                # binding fractions against the uncapped K (rule "off", the last)
                for rule, row in this.items():
                    if rule == "off" or k_off is None:
                        continue
                    k = k_maps[rule]
                    for r in rings:
                        sel = (ecc >= r.lo_deg) & (ecc < r.hi_deg) & (k_off > 0)
                        row["rings"][r.label]["binds"] = float(
                            (k[sel] < k_off[sel] * (1 - 1e-6)).mean()) if sel.any() else 0.0
                    sel16 = (ecc > PAST_DEG) & (k_off > 0)
                    row["binds_past_16"] = float(
                        (k[sel16] < k_off[sel16] * (1 - 1e-6)).mean()) if sel16.any() else 0.0
                if name == "sponza" and math.isclose(br, 0.34):
                    out["wheel"] += wheel(display, image, preset, br, rules, ecc)
                    out["space"].append(space(display, image, preset, br))
            if quick:
                break
    return out


def wheel(display, image, preset, br, rules, ecc):
    rows = []
    table = PAPER_TABLE2 if preset == "paper" else RELEASE_TABLE
    s_k0 = table.at(br)[1]
    past = ecc > PAST_DEG
    for rule in rules:
        enh = Enhancer(display, preset=preset, options=EngineOptions(clipping=rule))
        enh.set_image(image)
        stds = {}
        for label, s_k in (("lowest", SK_WHEEL[0]), ("table", s_k0), ("double", 2 * s_k0),
                           ("highest", SK_WHEEL[1])):
            res = enh.enhance((0.5, 0.5), make_params(blur_rate=br, preset=preset, s_k=s_k))
            stds[label] = float(res.map("noise")[past].std())
        del enh, res
        gc.collect()
        rows.append({"preset": preset, "rule": rule, "blur_rate": br, "s_k_table": s_k0,
                     "std": stds, "double_gain": stds["double"] / stds["table"] - 1.0})
        print(f"wheel {preset} {rule}: {stds}", flush=True)
    return rows


def space(display, image, preset, br):
    """Where the noise is added: linear(ours) - linear(contrast) against the noise map, and
    the difference of the encoded values against it, on band-open pixels nobody clips."""
    enh = Enhancer(display, preset=preset)
    enh.set_image(image)
    res = enh.enhance((0.5, 0.5), make_params(blur_rate=br, preset=preset))
    noise = res.map("noise")
    lin_c = enh.linear("contrast")
    ours = res.output
    con = enh.enhance((0.5, 0.5), make_params(method="contrast", blur_rate=br,
                                              preset=preset)).output
    gamma = display.gamma
    if preset == "release":
        return {"preset": preset, "note": "release transfer: not measured"}
    lin_o = np.power(ours.astype(np.float64), gamma)
    lin_k = np.power(con.astype(np.float64), gamma)
    n3 = noise[..., None] if ours.ndim == 3 else noise
    lin_v = lin_c + n3
    ok = (np.abs(n3) > 1e-4) & (lin_v > 0.01) & (lin_v < 0.99)
    d_lin = (lin_o - lin_k)[ok] - np.broadcast_to(n3, ok.shape)[ok]
    d_enc = (ours.astype(np.float64) - con)[ok] - np.broadcast_to(n3, ok.shape)[ok]
    rms_noise = float(np.sqrt(np.mean(np.broadcast_to(n3, ok.shape)[ok] ** 2)))
    return {"preset": preset, "pixels": int(ok.sum()), "rms_noise": rms_noise,
            "rms_linear_residual": float(np.sqrt(np.mean(d_lin**2))),
            "rms_encoded_residual": float(np.sqrt(np.mean(d_enc**2)))}


def db(num, den):
    return 10 * math.log10(num / den) if num > 0 and den > 0 else float("nan")


def summarise(data, presets, blur_rates, rules):
    """Per preset, blur-rate, rule and ring: the band's dB over all images, binding fractions
    and clipping averaged over images."""
    rows = []
    for preset in presets:
        for br in blur_rates:
            for rule in rules:
                sel = [r for r in data["rows"] if r["preset"] == preset
                       and math.isclose(r["blur_rate"], br) and r["rule"] == rule]
                if not sel:
                    continue
                for label in sel[0]["rings"]:
                    rings = [r["rings"][label] for r in sel]
                    full = sum(x["full_power"] for x in rings)
                    ref = [r for r in data["rows"] if r["preset"] == preset
                           and math.isclose(r["blur_rate"], br) and r["rule"] == rules[0]]
                    fov = sum(r["rings"][label]["foveated_power"] for r in ref)
                    con = sum(r["rings"][label]["contrast_power"] for r in ref)
                    ours = sum(x["ours_power"] for x in rings)
                    lost = full - fov
                    rows.append({
                        "preset": preset, "blur_rate": br, "rule": rule, "ring": label,
                        "band_cpd": rings[0]["band_cpd"],
                        "foveated_db": db(fov, full), "contrast_db": db(con, full),
                        "ours_db": db(ours, full),
                        "restored_share": (ours - fov) / lost if lost > 0 else float("nan"),
                        "binds": float(np.mean([x.get("binds", 0.0) for x in rings])),
                        "median_K": float(np.median([x["median_K"] for x in rings])),
                        "clip_fraction": float(np.mean([x["clip_fraction"] for x in rings])),
                        "clip_excess_p99": float(np.max([x["clip_excess_p99"] for x in rings])),
                        "clip_residual_db": db(
                            sum(10 ** (x["clip_residual_db"] / 10) * x["noise_std"] ** 2
                                for x in rings if not math.isnan(x["clip_residual_db"])),
                            sum(x["noise_std"] ** 2 for x in rings)),
                        "images": len(sel),
                    })
    return rows


def markdown(data, summary, info) -> str:
    lines = [
        "# The clipping control's neighbourhoods side by side (issue 26)",
        "",
        f"Machine: {info['machine']}; {info['date']}. Command: `{info['command']}` "
        f"({info['total_s']:.0f} s). Images: {', '.join(info['images'])} "
        "(display lg-oled55cx, gaze at the centre, 64 impulses, seed 1, Table 2's f_e, s_k, "
        "s_f at each blur-rate; release preset: its own defaults).",
        "",
        "Rules (`EngineOptions(clipping=...)`, `fovexp.amplitude.clipping_extremes`): "
        "**paper**, one level-3 min/max block (8 x 8 px) of luminance, section 4.2 as "
        "written; **widened**, every level-3 block the kernel reaches, over the colour "
        "channels; **release**, a 25 x 25 px box of grey; **exact**, the true extremes over "
        "the channels of the pixels each kernel covers; **off**, no clipping control (the "
        "uncapped K of eq. 9).",
        "",
        "Columns: band power of the output against full resolution in the ring's band "
        "[T_L, min(T_H, Nyquist)] (dB, over all images; 0 = restored); *restored* = the "
        "share of the band power foveation lost that the output puts back, "
        "(P_ours - P_foveated) / (P_full - P_foveated); *binds* = fraction of the ring's "
        "band-open pixels where the cap lowers K (mean over images); *median K* (median "
        "over images of the ring's median K where K > 0, linear light); *clips* = fraction "
        "of the ring's output values (pixel x channel) outside [0, 1] before the display "
        "clips them (mean over images), and the largest 99th percentile of the excess "
        "(linear light); *clip residual* = the power the display's clip takes from the noisy "
        "image, against the noise's power, in dB (images weighted by their noise power): an "
        "upper bound of how much of the noise's spectrum the clipping alters. Both clip "
        "columns include the contrast image's own excursions (f_e's extrapolation, docs/"
        "METHOD.md 5.3), which the noise does not cause: the rows of rings where the band is "
        "closed (ours = contrast: restored and residual '-') show them alone, and under the "
        "widened and exact rules, whose noise is small, they are most of what is left.",
        "",
        "The choice made from this record, and its reasons: docs/METHOD.md, 6.6. What the "
        "other reading of the paper's colour space would change: "
        "[clipping_space.md](clipping_space.md).",
        "",
    ]
    for preset in info["presets"]:
        for br in info["blur_rates"]:
            rows = [r for r in summary if r["preset"] == preset
                    and math.isclose(r["blur_rate"], br)]
            if not rows:
                continue
            lines += [f"## {preset} preset, blur-rate {br:g} arcmin/deg", "",
                      "| ring | band (cpd) | rule | foveated dB | contrast dB | ours dB | "
                      "restored | binds | median K | clips | excess p99 | clip residual |",
                      "|---|---|---|---|---|---|---|---|---|---|---|---|"]
            for r in rows:
                lo, hi = r["band_cpd"]
                # no noise in the ring's band (closed: ours is the contrast output): no share
                # restored, no noise to measure the clip against
                quiet = r["median_K"] == 0.0 or abs(r["ours_db"] - r["contrast_db"]) < 0.05
                restored = "-" if quiet else f"{100 * r['restored_share']:.0f} %"
                residual = "-" if quiet else f"{r['clip_residual_db']:.1f} dB"
                lines.append(
                    f"| {r['ring']} | {lo:.3g}-{hi:.3g} | {r['rule']} | "
                    f"{r['foveated_db']:.1f} | {r['contrast_db']:.1f} | {r['ours_db']:.1f} | "
                    f"{restored} | {100 * r['binds']:.0f} % | "
                    f"{r['median_K']:.3f} | {100 * r['clip_fraction']:.2f} % | "
                    f"{r['clip_excess_p99']:.3f} | {residual} |")
            lines.append("")
    if data["wheel"]:
        lines += ["## The wheel's reach (Sponza 4K, blur-rate 0.34)", "",
                  "Noise std past 16 deg (linear light) at the s_k protocol's first step "
                  f"({SK_WHEEL[0]:g}), Table 2's s_k, twice it, and the protocol's top "
                  f"({SK_WHEEL[1]:g}).", "",
                  ("| preset | rule | s_k 1.5 | Table 2 | 2 x Table 2 | 45 "
                   "| doubling raises it by |"),
                  "|---|---|---|---|---|---|---|"]
        for w in data["wheel"]:
            s = w["std"]
            lines.append(f"| {w['preset']} | {w['rule']} | {s['lowest']:.4f} | "
                         f"{s['table']:.4f} | {s['double']:.4f} | {s['highest']:.4f} | "
                         f"{100 * w['double_gain']:.0f} % |")
        lines.append("")
    for s in data["space"]:
        if "pixels" in s:
            lines += ["## The space the noise is added in (Sponza 4K, 0.34, paper preset)", "",
                      f"On {s['pixels']} band-open output values the display does not clip "
                      f"(noise RMS {s['rms_noise']:.4f}): linear(ours) - linear(contrast) "
                      f"differs from the noise map by {s['rms_linear_residual']:.2e} RMS, "
                      f"the encoded difference by {s['rms_encoded_residual']:.2e}: the noise "
                      "is added in linear light.", ""]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="one image, 0.34, for a smoke run")
    ap.add_argument("--images", type=int, default=15, help="generated scenes to include")
    ap.add_argument("--size", default="3840x2160", help="the generated scenes' size")
    ap.add_argument("--presets", default="paper,release")
    ap.add_argument("--release-images", type=int, default=1,
                    help="images the release preset runs on (the first: Sponza)")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks")
    ap.add_argument("--markdown-only", action="store_true",
                    help="write CLIPPING.md again from --out's clipping.json (no measuring)")
    args = ap.parse_args(argv)
    if args.markdown_only:
        data = json.loads((args.out / "clipping.json").read_text())
        (args.out / "CLIPPING.md").write_text(markdown(data, data["summary"], data["info"]))
        print(f"wrote {args.out / 'CLIPPING.md'} from clipping.json")
        return 0
    t0 = time.perf_counter()
    images = []
    if SPONZA.exists():
        images.append(("sponza", SPONZA))
    gen = ROOT / "stimuli" / "generated" / args.size
    images += [(p.stem, p) for p in sorted(gen.glob("scene-*.png"))[:args.images]]
    if not images:
        print(f"no images: {SPONZA} absent and no scenes under {gen} "
              f"(fovexp stimuli generate --size {args.size})", file=sys.stderr)
        return 2
    presets = args.presets.split(",")
    blur_rates = (0.34,) if args.quick else BLUR_RATES
    data = measure(images, presets, blur_rates, RULES, args.quick, args.release_images)
    summary = summarise(data, presets, blur_rates, RULES)
    info = {"machine": f"{machine_cpu()}, {os.cpu_count()} cores, Python "
                       f"{platform.python_version()}",
            "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
            "command": "python benchmarks/clipping.py " + " ".join(argv or sys.argv[1:]),
            "total_s": time.perf_counter() - t0, "presets": presets,
            "blur_rates": list(blur_rates),
            "images": sorted({r["image"] for r in data["rows"]})}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "clipping.json").write_text(json.dumps(
        {"info": info, "summary": summary, **data}, indent=1))
    (args.out / "CLIPPING.md").write_text(markdown(data, summary, info))
    print(f"wrote {args.out / 'CLIPPING.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
