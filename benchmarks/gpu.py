"""Speed and accuracy of the GPU backend on a 4K frame; results written to benchmarks/GPU.md
and benchmarks/gpu.json with the device (GL_RENDERER) and machine they came from.

    .venv/bin/python benchmarks/gpu.py [--repeats 15] [--out DIR]

Times are GPU execution times from GL timer queries (GL_TIME_ELAPSED) around each call, after
a warm-up, median of the repeats; where the driver's timer query is not usable (Mesa llvmpipe
returns no elapsed time) the wall-clock time of the call with a glFinish is used instead, and
the table says which. Cases: a whole frame (new image, moved gaze), already foveated and with
the foveation simulation; the runner's wheel steps on the processed half of a split screen
(s_k, f_e, blur-rate); the read-back of the finished frame. Accuracy: the frame against the
CPU backend's, and per-stage times from a profiled run.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from run import _frame, machine  # noqa: E402


def _timer(ctx, fn) -> tuple[float, str]:
    """Seconds of GPU work ``fn`` submits (GL timer query), else wall-clock with glFinish."""
    q = ctx.query(time=True)
    ctx.finish()
    t0 = time.perf_counter()
    with q:
        fn()
    ctx.finish()
    wall = time.perf_counter() - t0
    gl = q.elapsed * 1e-9
    if gl > 1e-5 or wall < 1e-3:
        return gl, "GL timer query"
    return wall, "wall clock + glFinish (timer query unusable on this driver)"


def _median(ctx, fn, repeats: int) -> tuple[float, float, str]:
    fn()  # warm-up: shader compilation, buffer allocation
    times, how = [], ""
    for _ in range(repeats):
        t, how = _timer(ctx, fn)
        times.append(t)
    return statistics.median(times), min(times), how


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--out", type=Path, default=HERE, help="folder for GPU.md and gpu.json")
    ap.add_argument("--markdown-only", action="store_true",
                    help="rewrite GPU.md from the gpu.json in --out (no measuring)")
    args = ap.parse_args()
    if args.markdown_only:
        data = json.loads((args.out / "gpu.json").read_text())
        (args.out / "GPU.md").write_text(_markdown(data))
        return 0

    from fovexp import EnhanceParams, Enhancer, load_display
    from fovexp.gpu import GpuEnhancer, is_software

    display = load_display("lg-oled55cx")
    image, source = _frame()
    h, w = image.shape[:2]
    enh = GpuEnhancer(display)
    ctx = enh.ctx
    results: dict = {"device": enh.renderer, "software_renderer": is_software(ctx),
                     "machine": machine(), "frame": f"{source} ({w}x{h})",
                     "repeats": args.repeats, "cases": {}}
    cases = results["cases"]
    gazes = [(0.5, 0.5), (0.52, 0.49)]

    def record(name: str, fn) -> None:
        med, best, how = _median(ctx, fn, args.repeats)
        cases[name] = {"median_s": med, "min_s": best, "timing": how}
        print(f"{name:58s} {med * 1e3:9.2f} ms (min {best * 1e3:.2f}; {how})", flush=True)

    copies = [image.copy(), image.copy()]  # a new array is a new frame to the stage cache
    for n in (12, 64):
        p = EnhanceParams(blur_rate=0.34, impulses=n).resolved(None)
        state = {"i": 0}

        def frame(foveated: bool, p=p, state=state) -> None:
            # Enhancer.enhance without its read-back (timed separately below); the upload of
            # the frame is included (a renderer would have it on the GPU already)
            state["i"] += 1
            enh.set_image(copies[state["i"] % 2], foveated=foveated)
            enh._c.set(**_inputs(p, gazes[state["i"] % 2]))
            enh._c.get("output")

        record(f"4K frame, already foveated, {n} impulses", lambda f=frame: f(True))
        record(f"4K frame with the foveation simulation, {n} impulses", lambda f=frame: f(False))

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

    # accuracy and per-stage times, whole 4K frame
    p = EnhanceParams(blur_rate=0.34, impulses=12)
    prof = GpuEnhancer(display, ctx=ctx, profile=True)
    prof.set_image(image)
    prof.enhance((0.5, 0.5), p)  # warm-up
    prof.set_image(image.copy())
    res = prof.enhance((0.5, 0.5), p)
    results["stages_s"] = res.timings_s
    cpu = Enhancer(display)
    cpu.set_image(image)
    ref = cpu.enhance((0.5, 0.5), p)
    d = np.abs(ref.output.astype(np.float64) - res.output)
    results["accuracy_vs_cpu"] = {"max": float(d.max()), "rms": float(np.sqrt((d**2).mean())),
                                  "p99_99": float(np.quantile(d, 0.9999))}
    print("accuracy vs CPU:", results["accuracy_vs_cpu"])
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "gpu.json").write_text(json.dumps(results, indent=2) + "\n")
    (args.out / "GPU.md").write_text(_markdown(results))
    return 0


def _inputs(p, gaze) -> dict:
    """The enhancer's per-call inputs (what Enhancer.enhance sets), without the read-back."""
    return dict(gaze=gaze, blur_rate=p.blur_rate, f_e=p.f_e, s_k=p.s_k, s_f=p.s_f,
                n_impulses=p.impulses, seed=p.seed, method=p.method)


def _markdown(r: dict) -> str:
    m = r["machine"]
    lines = [
        "# GPU backend benchmark",
        "",
        f"Device: **{r['device']}**" + (
            " (a software renderer: these figures are the shaders run on the CPU's cores, "
            "slower than the Numba CPU backend, not a GPU's)" if r["software_renderer"] else ""),
        f"Machine: {m['cpu']}, {m['cores']} cores, {m['memory_gb']} GB; Python {m['python']}, "
        f"NumPy {m['numpy']}; measured {m['date']}.",
        f"Frame: {r['frame']}; median of {r['repeats']} after a warm-up.",
        f"Command: `.venv/bin/python benchmarks/gpu.py --repeats {r['repeats']}`",
        "",
        "| Case | Median | Min | Timing |",
        "|---|---|---|---|",
    ]
    for name, c in r["cases"].items():
        lines.append(f"| {name} | {c['median_s'] * 1e3:.2f} ms | {c['min_s'] * 1e3:.2f} ms "
                     f"| {c['timing']} |")
    a = r["accuracy_vs_cpu"]
    lines += [
        "",
        f"Output against the CPU backend (display-encoded, [0, 1]): max {a['max']:.2g}, "
        f"RMS {a['rms']:.2g}, 99.99th percentile {a['p99_99']:.2g}.",
        "",
        "Per stage, one profiled 4K frame with the foveation simulation (glFinish after each):",
        "",
        "| Stage | Time |",
        "|---|---|",
        *(f"| {k} | {v * 1e3:.1f} ms |" for k, v in r["stages_s"].items()),
        "",
    ]
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(main())
