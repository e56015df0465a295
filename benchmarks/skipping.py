"""Skipping what a scene does not need (issue 10, section 2): run time with and without it, on
a textured 4K frame and on the same frame three quarters flat, and the output with it against
the output without it, bit for bit. Results: benchmarks/SKIPPING.md and skipping.json, with the
machine they came from.

    .venv/bin/python benchmarks/skipping.py [--repeats 7] [--impulses 64 12]

Scenes: Sponza (the shared 4K render; a generated texture when it is absent) and the same frame
with everything but its top-left quadrant replaced by constant grey (display value 0.5): "three
quarters flat". A frame is what a renderer calls per frame: a new image and a moved gaze, the
impulses kept (section 4.4). Two kinds of whole enhancement are timed:

- "foveated input": enhancing an already-foveated frame (the renderer hands one), i.e. the
  paper's section 7.3 count: parameter estimation and noise synthesis (plus the contrast
  enhancement and the display encoding, which it does not count);
- "foveation + enhancement": the same with the foveation simulated first.

For each impulse count and kind, the four enhancers (scene x skip on/off) run interleaved,
frame after frame, so that the machine's load falls on all of them alike; medians are
reported. Every frame's output with skipping is compared bit for bit with the one without.
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


def scenes() -> tuple[dict[str, np.ndarray], str]:
    image, source = _frame()
    flat = image.copy()
    h, w = image.shape[:2]
    keep = np.zeros((h, w), dtype=bool)
    keep[: h // 2, : w // 2] = True
    flat[~keep] = 0.5
    return {"textured": image, "3/4 flat": flat}, source


def run_group(images, impulses: int, prefoveated: bool, repeats: int) -> dict:
    from fovexp import EngineOptions, EnhanceParams, Enhancer, load_display

    display = load_display("lg-oled55cx")
    params = EnhanceParams(blur_rate=BLUR_RATE, impulses=impulses)
    frames = {}
    for name, image in images.items():
        if prefoveated:  # the renderer's frame is foveated already
            prep = Enhancer(display)
            prep.set_image(image)
            frames[name] = prep.enhance((0.5, 0.5), params).map("foveated")
            del prep
        else:
            frames[name] = image
    enhancers = {(name, skip): Enhancer(display, options=EngineOptions(skip=skip))
                 for name in frames for skip in (True, False)}
    times: dict[tuple[str, bool], list[float]] = {k: [] for k in enhancers}
    stages: dict[tuple[str, bool], list[dict]] = {k: [] for k in enhancers}
    identical = {name: True for name in frames}
    for i in range(repeats + 1):  # one warm-up frame
        gaze = (0.5 + 0.001 * (i % 3), 0.5)  # the gaze moves a little every frame
        outputs = {}
        for key, enh in enhancers.items():
            enh.set_image(frames[key[0]].copy(), foveated=prefoveated)  # a new frame
            t0 = time.perf_counter()
            res = enh.enhance(gaze, params)
            dt = time.perf_counter() - t0
            outputs[key] = res.output
            if i:
                times[key].append(dt)
                stages[key].append(res.timings_s)
        for name in frames:
            a, b = outputs[(name, True)], outputs[(name, False)]
            identical[name] &= bool(np.array_equal(a.view(np.uint32), b.view(np.uint32)))
        del outputs
        gc.collect()
    rows = []
    for (name, skip), t in times.items():
        names = sorted({k for s in stages[(name, skip)] for k in s})
        rows.append({
            "scene": name, "skip": skip, "median_s": float(np.median(t)),
            "min_s": float(np.min(t)),
            "stages_median_s": {k: float(np.median([s.get(k, 0.0) for s in stages[(name, skip)]]))
                                for k in names},
        })
    return {"impulses": impulses, "prefoveated": prefoveated, "rows": rows,
            "identical": identical}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--impulses", type=int, nargs="+", default=[64, 12])
    ap.add_argument("--out", type=Path, default=HERE)
    args = ap.parse_args()
    images, source = scenes()
    result = {"machine": machine(), "source": source, "blur_rate": BLUR_RATE,
              "repeats": args.repeats, "groups": []}
    for n in args.impulses:
        for pre in (True, False):
            result["groups"].append(run_group(images, n, pre, args.repeats))
            print(report(result), flush=True)
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
        f"Command: `.venv/bin/python benchmarks/skipping.py --repeats {r['repeats']}` (medians "
        "of the frames after one warm-up frame; the four enhancers of a row group run "
        "interleaved, frame after frame).", "",
        f"Scenes: {r['source']} (\"textured\"), and the same with all but its top-left "
        "quadrant constant grey (\"3/4 flat\"); 4K, blur-rate "
        f"{r['blur_rate']}, LG OLED55CX profile, a new frame and a moved gaze each time. "
        "\"foveated input\": enhancing an already-foveated frame (the paper's section 7.3 "
        "count, parameter estimation and synthesis, plus contrast and encoding); "
        "\"foveation + enhancement\": the foveation simulated first.", "",
        "| impulses | input | scene | skip on s | skip off s | saved | flat vs textured "
        "(skip on) | output identical |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for g in r["groups"]:
        kind = "foveated input" if g["prefoveated"] else "foveation + enhancement"
        tex_on = _row(g, "textured", True)["median_s"]
        for scene in ("textured", "3/4 flat"):
            on, off = _row(g, scene, True)["median_s"], _row(g, scene, False)["median_s"]
            ratio = f"{tex_on / on:.2f}x" if scene != "textured" else ""
            if ratio and g["impulses"] == 64:
                ratio += " (target >= 2x: " + ("met" if tex_on / on >= TARGET else "missed") + ")"
            lines.append(
                f"| {g['impulses']} | {kind} | {scene} | {on:.3f} | {off:.3f} | "
                f"{1 - on / off:.0%} | {ratio} | "
                f"{'yes, bit for bit' if g['identical'][scene] else 'NO'} |")
    lines += ["", "Stage medians (s), skip on / skip off:", ""]
    for g in r["groups"]:
        kind = "foveated input" if g["prefoveated"] else "foveation + enhancement"
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
