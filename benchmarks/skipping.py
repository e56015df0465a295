"""Skipping what a scene does not need (issue 10, section 2): run time with and without it, on
a textured 4K frame and on the same frame three quarters flat, and the output with it against
the output without it, bit for bit. Results: benchmarks/SKIPPING.md and skipping.json, with the
machine they came from.

    .venv/bin/python benchmarks/skipping.py [--repeats 7] [--impulses 64 12] [--runs 1]

Scenes: Sponza (the shared 4K render; a generated texture when it is absent) and the same frame
with everything but its top-left quadrant replaced by constant grey (display value 0.5): "three
quarters flat". A frame is what a renderer calls per frame: a new image and a moved gaze, the
impulses kept (section 4.4). Two kinds of whole enhancement are timed:

- "foveated input": enhancing an already-foveated frame (the renderer hands one), i.e. the
  paper's section 6.3 count: parameter estimation and noise synthesis (plus the contrast
  enhancement and the display encoding, which it does not count);
- "foveated input + sigma map": the same with the frame's sigma map given, as a foveated renderer
  knows it (no eccentricity and sigma maps to compute);
- "foveation + enhancement": the same with the foveation simulated first.

For each impulse count and kind, the four enhancers (scene x skip on/off) run interleaved,
frame after frame, in an order that rotates from frame to frame, so that the machine's load
falls on all of them alike; medians are reported. Every frame's output with skipping is
compared bit for bit with the one without.
"""

from __future__ import annotations

import argparse
import gc
import json
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from run import _frame, machine  # noqa: E402  (benchmarks/run.py: the frame, the machine)

BLUR_RATE = 0.34
TARGET = 2.0  # the flat scene at least 2x faster than the textured one (64 impulses)
#: The stages the paper's section 6.3 times: "building all the image pyramids and estimating
#: frequency, amplitude, and orientation for each Gabor patch", and the synthesis (not the
#: linearisation, the sigma map, the contrast enhancement or the encoding).
PAPER_STAGES = ("luma_and_blocks", "luma", "luma_blocks", "luma_flat", "imp_blocks", "pyramid",
                "abs_laplacian", "gradients", "headroom", "imp_band", "imp_active", "imp_frequency",
                "imp_laplacian", "imp_headroom", "imp_amplitude", "imp_orientation", "noise")


def scenes() -> tuple[dict[str, np.ndarray], str]:
    image, source = _frame()
    flat = image.copy()
    h, w = image.shape[:2]
    keep = np.zeros((h, w), dtype=bool)
    keep[: h // 2, : w // 2] = True
    flat[~keep] = 0.5
    return {"textured": image, "3/4 flat": flat}, source


#: What a frame is: a foveated frame (sigma from the blur-rate and the gaze), a foveated frame
#: with its sigma map (what a foveated renderer knows), or a full-resolution one to foveate.
KINDS = {"foveated": "foveated input", "sigma": "foveated input + sigma map",
         "full": "foveation + enhancement"}


def run_group(images, impulses: int, kind: str, repeats: int) -> dict:
    from fovexp import EngineOptions, EnhanceParams, Enhancer, load_display

    display = load_display("lg-oled55cx")
    params = EnhanceParams(blur_rate=BLUR_RATE, impulses=impulses)
    prefoveated = kind != "full"
    frames, sigmas = {}, {}
    for name, image in images.items():
        if prefoveated:  # the renderer's frame is foveated already
            prep = Enhancer(display)
            prep.set_image(image)
            frames[name] = prep.enhance((0.5, 0.5), params).map("foveated")
            for j in range(3):  # the gazes below: the renderer's sigma maps
                sigmas[j] = prep.enhance((0.5 + 0.001 * j, 0.5), params).map("sigma_px")
            del prep
        else:
            frames[name] = image
    enhancers = {(name, skip): Enhancer(display, options=EngineOptions(skip=skip))
                 for name in frames for skip in (True, False)}
    times: dict[tuple[str, bool], list[float]] = {k: [] for k in enhancers}
    cpu: dict[tuple[str, bool], list[float]] = {k: [] for k in enhancers}
    stages: dict[tuple[str, bool], list[dict]] = {k: [] for k in enhancers}
    identical = {name: True for name in frames}
    for i in range(repeats + 1):  # one warm-up frame
        gaze = (0.5 + 0.001 * (i % 3), 0.5)  # the gaze moves a little every frame
        outputs = {}
        # the order rotates from frame to frame: what runs later in a round (after the
        # others' allocations) is not always the same enhancer
        keys = list(enhancers)
        for key in keys[i % len(keys):] + keys[: i % len(keys)]:
            enh = enhancers[key]
            if kind == "sigma":  # a new frame and its sigma map
                enh.set_image(frames[key[0]].copy(), sigma_px=sigmas[i % 3].copy())
            else:  # a new frame
                enh.set_image(frames[key[0]].copy(), foveated=prefoveated)
            c0, t0 = time.process_time(), time.perf_counter()
            res = enh.enhance(gaze, params)
            dt, dc = time.perf_counter() - t0, time.process_time() - c0
            outputs[key] = res.output
            if i:
                times[key].append(dt)
                cpu[key].append(dc)
                stages[key].append(res.timings_s)
        for name in frames:
            a, b = outputs[(name, True)], outputs[(name, False)]
            identical[name] &= bool(np.array_equal(a.view(np.uint32), b.view(np.uint32)))
        del outputs
        gc.collect()
    rows = []
    for (name, skip), t in times.items():
        names = sorted({k for s in stages[(name, skip)] for k in s})
        paper = [sum(s.get(k, 0.0) for k in PAPER_STAGES) for s in stages[(name, skip)]]
        rows.append({
            "scene": name, "skip": skip, "median_s": float(np.median(t)),
            "min_s": float(np.min(t)), "paper_median_s": float(np.median(paper)),
            "cpu_median_s": float(np.median(cpu[(name, skip)])),
            "stages_median_s": {k: float(np.median([s.get(k, 0.0) for s in stages[(name, skip)]]))
                                for k in names},
        })
    return {"impulses": impulses, "kind": kind, "rows": rows,
            "identical": identical}


def amplitude_floor(image: np.ndarray, impulses: int = 64) -> dict:
    """What an amplitude floor would do (not adopted: skipping stays exact). Impulses whose
    K is below a floor would be left out like the flat ones; measured here: the share of the
    noise-carrying impulses it would leave out, and how many 8-bit output pixels change."""
    from fovexp import EnhanceParams, Enhancer, colour, gabor, load_display

    display = load_display("lg-oled55cx")
    enh = Enhancer(display)
    enh.set_image(image)
    res = enh.enhance((0.5, 0.5), EnhanceParams(blur_rate=BLUR_RATE, impulses=impulses))
    c = enh._c  # the per-impulse stages, to resynthesise without the impulses below a floor
    act, k, imp = c.get("imp_active"), c.get("imp_amplitude"), c.get("impulses")
    base = np.round(res.output * 255)
    rows = []
    for floor in (1e-4, 1e-3, 3e-3, 1e-2):
        full, freq, carrier = (np.zeros(len(imp)) for _ in range(3))
        full[act.index] = np.where(k < floor, 0.0, k)
        freq[act.index] = c.get("imp_frequency")
        carrier[act.index] = c.get("imp_orientation") - 0.5 * np.pi
        noise = gabor.synthesize(image.shape[:2], imp, full, freq, carrier, impulses,
                                 enh.preset.gabor_a_cpp)
        out = colour.encode(c.get("foveated"), display.gamma, "power", c.get("contrast"), noise)
        d = np.abs(np.round(out * 255) - base)
        rows.append({"floor": floor, "impulses_left_out": float((k[k > 0] < floor).mean()),
                     "pixels_changed": float((d > 0).mean()), "max_codes": float(d.max())})
    return {"impulses": impulses, "rows": rows}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--impulses", type=int, nargs="+", default=[64, 12])
    ap.add_argument("--runs", type=int, default=1,
                    help="run each group this many times (the ratio varies from run to run "
                    "on a shared machine more than within one)")
    ap.add_argument("--out", type=Path, default=HERE)
    args = ap.parse_args()
    images, source = scenes()
    result = {"machine": machine(), "source": source, "blur_rate": BLUR_RATE,
              "repeats": args.repeats, "runs": args.runs, "groups": []}
    for n in args.impulses:
        for kind in KINDS:
            for run in range(args.runs):
                result["groups"].append({**run_group(images, n, kind, args.repeats),
                                         "run": run + 1})
                print(report(result), flush=True)
    result["amplitude_floor"] = amplitude_floor(images["textured"])
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "skipping.json").write_text(json.dumps(result, indent=1))
    (args.out / "SKIPPING.md").write_text(report(result))


def _row(group: dict, scene: str, skip: bool) -> dict:
    return next(r for r in group["rows"] if r["scene"] == scene and r["skip"] == skip)


def report(r: dict) -> str:
    m = r["machine"]
    lines = [
        "# Skipping what a scene does not need", "",
        f"Machine: {m['cpu']}, {m['cores']} cores, {m['memory_gb']} GB; Python {m['python']}, "
        f"NumPy {m['numpy']}, SciPy {m['scipy']}, Numba {m['numba']} "
        f"({m['numba_threads']} threads); {m['date']}.",
        f"Command: `.venv/bin/python benchmarks/skipping.py --repeats {r['repeats']}"
        + (f" --runs {r['runs']}" if r.get("runs", 1) > 1 else "") + "` (medians "
        "of the frames after one warm-up frame; the four enhancers of a row group run "
        "interleaved, frame after frame, in an order that rotates). Wall-clock seconds "
        "(medians, and the ratio of the fastest frames, which a loaded machine disturbs "
        "least), and the process's CPU seconds (all threads).", "",
        f"Scenes: {r['source']} (\"textured\"), and the same with all but its top-left "
        "quadrant constant grey (\"3/4 flat\"); 4K, blur-rate "
        f"{r['blur_rate']}, LG OLED55CX profile, a new frame and a moved gaze each time. "
        "\"foveated input\": enhancing an already-foveated frame (the paper's section 6.3 "
        "count, parameter estimation and synthesis, plus contrast and encoding); "
        "\"+ sigma map\": with the frame's sigma map given, as a foveated renderer knows it; "
        "\"foveation + enhancement\": the foveation simulated first. \"section 6.3 stages\": "
        "the sum of the stages the paper's Performance section counts (pyramids, per-impulse "
        "parameters, synthesis), from the same frames.", "",
        "| impulses | input | scene | skip on s | skip off s | saved | flat vs textured "
        "(skip on) | same, fastest frames | CPU time, skip on s | flat vs textured | section 6.3 "
        "stages, skip on s | flat vs textured | output identical |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    runs = r.get("runs", 1)
    for g in r["groups"]:
        kind = KINDS[g["kind"]] + (f", run {g['run']}" if runs > 1 else "")
        tex_on = _row(g, "textured", True)["median_s"]
        tex_paper = _row(g, "textured", True)["paper_median_s"]
        tex_cpu = _row(g, "textured", True)["cpu_median_s"]
        tex_min = _row(g, "textured", True)["min_s"]
        for scene in ("textured", "3/4 flat"):
            on, off = _row(g, scene, True)["median_s"], _row(g, scene, False)["median_s"]
            paper = _row(g, scene, True)["paper_median_s"]
            cpu_on = _row(g, scene, True)["cpu_median_s"]
            cpu_ratio = f"{tex_cpu / cpu_on:.2f}x" if scene != "textured" else ""
            min_ratio = (f"{tex_min / _row(g, scene, True)['min_s']:.2f}x"
                         if scene != "textured" else "")
            ratio = f"{tex_on / on:.2f}x" if scene != "textured" else ""
            if ratio and g["impulses"] == 64:
                ratio += " (target >= 2x: " + ("met" if tex_on / on >= TARGET else "missed") + ")"
            paper_ratio = f"{tex_paper / paper:.2f}x" if scene != "textured" else ""
            lines.append(
                f"| {g['impulses']} | {kind} | {scene} | {on:.3f} | {off:.3f} | "
                f"{1 - on / off:.0%} | {ratio} | {min_ratio} | {cpu_on:.3f} | {cpu_ratio} | "
                f"{paper:.3f} | "
                f"{paper_ratio} | "
                f"{'yes, bit for bit' if g['identical'][scene] else 'NO'} |")
    if runs > 1:
        lines += ["", f"Flat vs textured (skip on, medians) over the {runs} runs of each group:",
                  ""]
        for n in dict.fromkeys(g["impulses"] for g in r["groups"]):
            for k in KINDS:
                ratios = [_row(g, "textured", True)["median_s"]
                          / _row(g, "3/4 flat", True)["median_s"]
                          for g in r["groups"] if g["impulses"] == n and g["kind"] == k]
                if ratios:
                    verdict = ((" (target >= 2x: " + ("met" if np.median(ratios) >= TARGET
                                                     else "missed") + ")") if n == 64 else "")
                    lines.append(f"- {n} impulses, {KINDS[k]}: "
                                 + ", ".join(f"{x:.2f}x" for x in ratios)
                                 + f"; median {np.median(ratios):.2f}x{verdict}")
    fl = r.get("amplitude_floor")
    if fl:
        lines += ["", "## An amplitude floor (measured, not adopted)", "",
                  "Low-contrast regions that are not exactly flat (sky, defocus) keep their "
                  "noise: skipping only leaves out what is exactly 0. A floor on K would be "
                  f"part of the method; on the textured scene at {fl['impulses']} impulses it "
                  "would change the output as follows (8-bit codes):", "",
                  "| floor on K (linear) | noise-carrying impulses left out | output pixels "
                  "changed | largest change |", "|---|---|---|---|"]
        for row in fl["rows"]:
            lines.append(f"| {row['floor']:g} | {row['impulses_left_out']:.1%} | "
                         f"{row['pixels_changed']:.3%} | {row['max_codes']:.0f} |")
    lines += ["", "Stage medians (s), skip on / skip off:", ""]
    for g in r["groups"]:
        kind = KINDS[g["kind"]] + (f", run {g['run']}" if runs > 1 else "")
        for scene in ("textured", "3/4 flat"):
            on, off = _row(g, scene, True), _row(g, scene, False)
            names = sorted(set(on["stages_median_s"]) | set(off["stages_median_s"]),
                           key=lambda k: -off["stages_median_s"].get(k, 0.0))
            st = ", ".join(f"{k} {on['stages_median_s'].get(k, 0.0):.3f} / "
                           f"{off['stages_median_s'].get(k, 0.0):.3f}" for k in names
                           if max(on["stages_median_s"].get(k, 0.0),
                                  off["stages_median_s"].get(k, 0.0)) >= 0.002)
            lines.append(f"- {g['impulses']} impulses, {kind}, {scene}: {st}")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
