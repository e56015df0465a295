"""Speed and accuracy of the GPU backend on a 4K frame; results written to benchmarks/GPU.md
and benchmarks/gpu.json with the device (GL_RENDERER) and machine they came from.

    .venv/bin/python benchmarks/gpu.py [--repeats 15] [--out DIR]

Each case is timed after a warm-up, median (and minimum) of the repeats, by ONE method for all
its repeats: a GL timer query (GL_TIME_ELAPSED) around the call, or, where the driver's query
is unusable for any repeat of the case (Mesa llvmpipe reports no elapsed time), the wall-clock
time of the call between two glFinish; the table says which. GL_TIME_ELAPSED spans the call on
the GPU's timeline, from glBeginQuery to glEndQuery: it includes the time the GPU idles while
the CPU side of the call (Python, uploads, impulse generation) runs between dispatches. It is
the GPU-timeline time of the call, not the shaders' execution time alone.

Cases: a whole frame (new image, moved gaze), already foveated and with the foveation
simulation; the runner's wheel steps on the processed half of a split screen (s_k, f_e,
blur-rate); the read-back of the finished frame. Accuracy: the frame against the CPU backend's.

Per stage and per compute entry: ``fovexp.gpu.profile_stages`` (each dispatch timed by a GL
timer query, or by the wall clock with glFinish where the query is unusable), 12 and 64
impulses with the foveation simulation and 12 already foveated, next to the roofline
prediction of benchmarks/gpu_roofline.py where the device is one it names. A lab measures its
own GPU's stages with one command:

    .venv/bin/python benchmarks/gpu.py --stages-only --out DIR

The measuring drives the enhancer's stage cache directly (to time a frame without its
read-back), so it makes the enhancer's context current itself (``with ctx:``), as the
enhancer's public methods do.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from gpu_roofline import device_for, predictions  # noqa: E402
from run import _frame, machine  # noqa: E402

GL_TIMER = "GL timer query (GPU timeline of the call)"
WALL_CLOCK = "wall clock + glFinish (timer query unusable on this driver)"


def _measure(ctx, query, fn: Callable[[], object]) -> tuple[float | None, float]:
    """One call of ``fn``: (GL_TIME_ELAPSED in s, None where the driver's value is unusable;
    wall-clock s between a glFinish before and one after). ``ctx`` must be current."""
    ctx.finish()
    t0 = time.perf_counter()
    with query:
        fn()
    ctx.finish()
    wall_s = time.perf_counter() - t0
    gl_s = query.elapsed * 1e-9
    # llvmpipe reports 0 ns, or next to it, for calls that take seconds
    usable = gl_s > 0.0 and (gl_s > 1e-5 or wall_s < 1e-3)
    return (gl_s if usable else None), wall_s


def _median(ctx, query, fn: Callable[[], object], repeats: int) -> tuple[float, float, str]:
    """(median s, min s, timing method) of ``repeats`` calls after a warm-up; one method for
    every repeat: the timer query if it was usable for all of them, else the wall clock."""
    fn()  # warm-up: buffer allocation, first-use costs
    gl_s, wall_s = [], []
    for _ in range(repeats):
        g, w = _measure(ctx, query, fn)
        gl_s.append(g)
        wall_s.append(w)
    if all(g is not None for g in gl_s):
        return statistics.median(gl_s), min(gl_s), GL_TIMER
    return statistics.median(wall_s), min(wall_s), WALL_CLOCK


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--stage-repeats", type=int, default=11,
                    help="frames per stage profile (after 2 warm-up frames)")
    ap.add_argument("--stages-only", action="store_true",
                    help="measure the per-stage tables only (the lab's one command); the "
                         "cases of an earlier run in --out on the same device are kept")
    ap.add_argument("--out", type=Path, default=HERE, help="folder for GPU.md and gpu.json")
    ap.add_argument("--markdown-only", action="store_true",
                    help="rewrite GPU.md from the gpu.json in --out (no measuring)")
    args = ap.parse_args()
    if args.markdown_only:
        data = json.loads((args.out / "gpu.json").read_text())
        (args.out / "GPU.md").write_text(_markdown(data))
        return 0

    from fovexp import load_display
    from fovexp.gpu import GpuEnhancer, is_software

    display = load_display("lg-oled55cx")
    image, source = _frame()
    with GpuEnhancer(display) as enh:
        if args.stages_only:
            h, w = image.shape[:2]
            results = {"device": enh.renderer, "machine": machine(),
                       "frame": f"{source} ({w}x{h})", "cases": {}}
            old = args.out / "gpu.json"
            if old.is_file():  # keep the cases measured before on the same device and frame
                before = json.loads(old.read_text())
                if (before.get("device"), before.get("frame")) == (enh.renderer,
                                                                   results["frame"]):
                    results = before
                    results.pop("stages_s", None)  # the older per-stage table (glFinish)
        else:
            results = _measure_all(enh, display, image, source, args.repeats)
            print("accuracy vs CPU:", results["accuracy_vs_cpu"])
        results["software_renderer"] = is_software(enh.ctx)
        results["stage_profiles"] = stage_profiles(display, image, args.stage_repeats, enh.ctx)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "gpu.json").write_text(json.dumps(results, indent=2) + "\n")
    (args.out / "GPU.md").write_text(_markdown(results))
    return 0


def _measure_all(enh, display, image: np.ndarray, source: str, repeats: int) -> dict:
    """Every case on ``enh``, whose context is current for the whole measurement."""
    from fovexp import EnhanceParams, Enhancer
    from fovexp.gpu import GpuEnhancer

    ctx = enh.ctx
    h, w = image.shape[:2]
    results: dict = {"device": enh.renderer, "machine": machine(),
                     "frame": f"{source} ({w}x{h})", "repeats": repeats, "cases": {}}
    cases = results["cases"]
    gazes = [(0.5, 0.5), (0.52, 0.49)]
    with ctx:  # the cases call the stage cache directly, not through a public method
        # one timer query, reused by every measurement: moderngl 5.13's Query has no
        # release(), so one made per call would stay until the context goes
        query = ctx.query(time=True)

        def record(name: str, fn: Callable[[], object]) -> None:
            med, best, how = _median(ctx, query, fn, repeats)
            cases[name] = {"median_s": med, "min_s": best, "timing": how}
            print(f"{name:58s} {med * 1e3:9.2f} ms (min {best * 1e3:.2f}; {how})", flush=True)

        copies = [image.copy(), image.copy()]  # a new array is a new frame to the stage cache
        for n in (12, 64):
            p = EnhanceParams(blur_rate=0.34, impulses=n).resolved(None)
            state = {"i": 0}

            def frame(foveated: bool, p=p, state=state) -> None:
                # Enhancer.enhance without its read-back (timed separately below); the upload
                # of the frame is included (a renderer would have it on the GPU already)
                state["i"] += 1
                enh.set_image(copies[state["i"] % 2], foveated=foveated)
                enh._c.set(**_inputs(p, gazes[state["i"] % 2]))
                enh._c.get("output")

            record(f"4K frame, already foveated, {n} impulses", lambda f=frame: f(True))
            record(f"4K frame with the foveation simulation, {n} impulses",
                   lambda f=frame: f(False))

        # the runner: the processed half of a split screen, wheel steps (12 impulses)
        half = np.ascontiguousarray(image[:, w // 2:])
        enh.set_image(half, viewport=(w - half.shape[1], 0, w, h))
        base = EnhanceParams(blur_rate=0.34, impulses=12).resolved(None)
        enh.enhance((0.5, 0.5), base)
        for field, values in (("s_k", (20.0, 21.0)), ("f_e", (0.20, 0.21)),
                              ("blur_rate", (0.34, 0.35))):
            state = {"i": 0}

            def step(field=field, values=values, state=state) -> None:
                state["i"] += 1
                p = base.model_copy(update={field: values[state["i"] % 2]})
                enh._c.set(**_inputs(p, (0.5, 0.5)))
                enh._c.get("output")

            record(f"wheel step {field}, 4K half frame (GPU work only)", step)
        record("read-back of a 4K half frame (float32 RGB)", lambda: enh._output())

    # accuracy, whole 4K frame (public calls: each makes ctx current)
    p = EnhanceParams(blur_rate=0.34, impulses=12)
    with GpuEnhancer(display, ctx=ctx) as gpu:
        gpu.set_image(image)
        output = gpu.enhance((0.5, 0.5), p).output
    cpu = Enhancer(display)
    cpu.set_image(image)
    ref = cpu.enhance((0.5, 0.5), p)
    d = np.abs(ref.output.astype(np.float64) - output)
    results["accuracy_vs_cpu"] = {"max": float(d.max()), "rms": float(np.sqrt((d**2).mean())),
                                  "p99_99": float(np.quantile(d, 0.9999))}
    return results


#: (impulses per kernel, foveation simulated) of the stage profiles
STAGE_CASES = ((12, True), (64, True), (12, False))


def stage_profiles(display, image: np.ndarray, repeats: int, ctx=None) -> list[dict]:
    """fovexp.gpu.profile_stages for each of STAGE_CASES (blur-rate 0.34, gaze at the
    centre), with the roofline prediction of each entry where the device is one
    benchmarks/gpu_roofline.py names."""
    from fovexp import EnhanceParams
    from fovexp.gpu import profile_stages

    out = []
    for impulses, simulate in STAGE_CASES:
        load = os.getloadavg()[0]  # other work on the machine (the shaders' figures on llvmpipe)
        prof = profile_stages(display, image, EnhanceParams(blur_rate=0.34, impulses=impulses),
                              simulate_foveation=simulate, repeats=repeats, ctx=ctx).as_dict()
        prof["impulses"] = impulses
        prof["machine"] = machine()  # when and where: a profile may be merged into older cases
        prof["load_average_at_start"] = round(load, 2)
        key = device_for(prof["device"])
        if key is not None and image.shape[:2] == (2160, 3840):
            pred = predictions((key,))[(impulses, simulate)]["devices"][key]
            prof["predicted_ms"] = {k: v[0] for k, v in pred["entries"].items()}
            prof["predicted_total_ms"] = pred["total_ms"]
        print(f"stages, {impulses} impulses, {prof['frame']}: {prof['frame_ms']:.2f} ms "
              f"({prof['timing_method']})", flush=True)
        out.append(prof)
    return out


def _inputs(p, gaze) -> dict:
    """The enhancer's per-call inputs (what Enhancer.enhance sets), without the read-back."""
    return dict(gaze=gaze, blur_rate=p.blur_rate, f_e=p.f_e, s_k=p.s_k, s_f=p.s_f,
                n_impulses=p.impulses, seed=p.seed, method=p.method)


def _markdown(r: dict) -> str:
    m = r["machine"]
    command = f"--repeats {r['repeats']}" if r["cases"] else "--stages-only"
    lines = [
        "# GPU backend benchmark",
        "",
        f"Device: **{r['device']}**" + (
            " (a software renderer: these figures are the shaders run on the CPU's cores, "
            "slower than the Numba CPU backend, not a GPU's)" if r["software_renderer"] else ""),
        f"Machine: {m['cpu']}, {m['cores']} cores, {m['memory_gb']} GB; Python {m['python']}, "
        f"NumPy {m['numpy']}; measured {m['date']}.",
        f"Frame: {r['frame']}.",
        f"Command: `.venv/bin/python benchmarks/gpu.py {command}`",
    ]
    if r["cases"]:
        a = r["accuracy_vs_cpu"]
        lines += [
            "",
            f"## Cases (median of {r['repeats']} after a warm-up)",
            "",
            "| Case | Median | Min | Timing |",
            "|---|---|---|---|",
            *(f"| {name} | {c['median_s'] * 1e3:.2f} ms | {c['min_s'] * 1e3:.2f} ms "
              f"| {c['timing']} |" for name, c in r["cases"].items()),
            "",
            "Timing: one method per case. A GL timer query (GL_TIME_ELAPSED) is the call's span "
            "on the GPU's timeline, GPU idle time while the CPU side of the call runs included; "
            "the wall clock is the call between two glFinish.",
            "",
            f"Output against the CPU backend (display-encoded, [0, 1]): max {a['max']:.2g}, "
            f"RMS {a['rms']:.2g}, 99.99th percentile {a['p99_99']:.2g}.",
        ]
    lines += _stage_markdown(r.get("stage_profiles", []))
    return "\n".join(lines)


def _stage_markdown(profiles: list[dict]) -> list[str]:
    """The per-stage and per-entry tables of the stage profiles, with the prediction."""
    if not profiles:
        return [""]
    p0 = profiles[0]
    m = p0["machine"]
    heads = [f"{p['impulses']} imp., {p['frame'].split(', ', 1)[1]}" for p in profiles]
    lines = [
        "",
        f"## Per stage (median of {p0['repeats']} frames after {p0['warmup']} warm-up frames, "
        "blur-rate 0.34, gaze at the centre)",
        "",
        f"Device: {p0['device']}; {m['cpu']}, {m['cores']} cores; measured {m['date']}; "
        "load average at the start of each profile: "
        + ", ".join(f"{p['load_average_at_start']:.1f}" for p in profiles) + ". Command: "
        f"`.venv/bin/python benchmarks/gpu.py --stages-only --stage-repeats {p0['repeats']}`.",
        "",
        f"Timing: {p0['timing_method']}. A stage's time is the sum of its dispatches' "
        "(transfers are not dispatches: the upload, the impulses' records and the read-back "
        "are left out).",
        "",
        "| Stage | " + " | ".join(heads) + " |",
        "|---|" + "---|" * len(profiles),
    ]
    stages = list(dict.fromkeys(k for p in profiles for k in p["stages_ms"]))
    for k in stages:
        lines.append(f"| {k} | " + " | ".join(
            f"{p['stages_ms'][k]:.2f} ms" if k in p["stages_ms"] else "-" for p in profiles)
            + " |")
    predicted = any("predicted_ms" in p for p in profiles)
    lines += [
        "",
        "Per compute entry (summed over its dispatches in a frame)"
        + (", and the roofline prediction (benchmarks/gpu_roofline.py; docs/GPU.md)"
           if predicted else "; no roofline prediction for this device "
           "(benchmarks/gpu_roofline.py names the RTX 2080 Ti and H100)") + ":",
        "",
        "| Entry | Dispatches | " + " | ".join(
            h + (" (predicted)" if "predicted_ms" in p else "")
            for h, p in zip(heads, profiles, strict=True)) + " |",
        "|---|---|" + "---|" * len(profiles),
    ]

    def cell(p: dict, k: str) -> str:
        if k not in p["dispatches_ms"]:
            return "-"
        got = f"{p['dispatches_ms'][k]:.3f} ms"
        return got + (f" ({p['predicted_ms'][k]:.3f})" if k in p.get("predicted_ms", {}) else "")

    entries = list(dict.fromkeys(k for p in profiles for k in p["dispatches_ms"]))
    for k in entries:
        counts = "/".join(str(p["dispatch_counts"].get(k, 0)) for p in profiles)
        lines.append(f"| {k} | {counts} | " + " | ".join(cell(p, k) for p in profiles) + " |")
    lines.append("| **frame** | | " + " | ".join(
        f"**{p['frame_ms']:.2f} ms**" + (f" ({p['predicted_total_ms']:.2f})"
                                         if "predicted_total_ms" in p else "")
        for p in profiles) + " |")
    return lines + [""]


if __name__ == "__main__":
    raise SystemExit(main())
