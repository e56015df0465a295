"""Speed, memory and accuracy of the enhancer on a 4K frame; results written to
benchmarks/RESULTS.md and benchmarks/results.json with the machine they came from.

    .venv/bin/python benchmarks/run.py [--repeats 7] [--quick]

Each timing case runs in its own process (so its peak resident memory is its own), warms up
(Numba compilation, caches) and reports the median of the repeats. A "frame" is what a renderer
calls per frame: a new image and a moved gaze, with the impulses kept (section 4.4).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from fovexp.bench import machine_cpu

HERE = Path(__file__).resolve().parent
SPONZA = HERE.parent.parent / "shared" / "stimuli" / "sponza-4k.jpg"
# the authors' C++ noise generator, single-threaded, 4K, on a CI-class machine (docs/METHOD.md, 7)
RELEASE_NOISE_S = {12: 10.0, 64: 52.0}


def _frame():
    from fovexp import read_image

    if SPONZA.is_file():
        return read_image(SPONZA), "sponza-4k.jpg"
    sys.path.insert(0, str(HERE.parent / "tests"))
    from engine_helpers import textured_image

    return textured_image(2160, 3840), "generated 3840x2160 texture"


def reset_peak_rss() -> None:
    """Start the peak-RSS count afresh (Linux: writing 5 to clear_refs resets VmHWM)."""
    import gc

    gc.collect()
    try:
        Path("/proc/self/clear_refs").write_text("5")
    except OSError:
        pass


def peak_rss_mb() -> float:
    """Peak resident memory of this process (VmHWM), MB."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def case_timing(impulses: int, prefoveated: bool, repeats: int) -> dict:
    """Median per-frame time of the whole enhancement and of each stage."""
    from fovexp import EnhanceParams, Enhancer, load_display

    image, source = _frame()
    display = load_display("lg-oled55cx")
    params = EnhanceParams(blur_rate=0.34, impulses=impulses)
    frame = image
    if prefoveated:  # the real use: the renderer's frame is foveated already
        prep = Enhancer(display)
        prep.set_image(image)
        frame = prep.enhance((0.5, 0.5), params).map("foveated")
        del prep
        reset_peak_rss()
    enh = Enhancer(display)
    totals, stages = [], []
    for i in range(repeats + 2):  # two warm-up frames
        gaze = (0.5 + 0.001 * (i % 3), 0.5)  # the gaze moves a little every frame
        enh.set_image(frame.copy(), foveated=prefoveated)
        t0 = time.perf_counter()
        res = enh.enhance(gaze, params)
        dt = time.perf_counter() - t0
        if i >= 2:
            totals.append(dt)
            stages.append(res.timings_s)
    names = sorted({k for s in stages for k in s})
    return {
        "case": f"{'enhance foveated frame' if prefoveated else 'foveate + enhance'}, "
                f"{impulses} impulses",
        "source": source, "impulses": impulses, "prefoveated": prefoveated,
        "median_s": float(np.median(totals)), "min_s": float(np.min(totals)),
        "stages_median_s": {k: float(np.median([s.get(k, 0.0) for s in stages])) for k in names},
        "peak_rss_mb": peak_rss_mb(),
    }


def case_noise_alone(impulses: int, repeats: int) -> dict:
    """The noise synthesis alone, as the C++ generator does: the pipeline's ``noise`` stage,
    isolated by changing only s_k between frames (amplitude -> noise -> output rerun)."""
    from fovexp import EnhanceParams, Enhancer, load_display

    image, source = _frame()
    enh = Enhancer(load_display("lg-oled55cx"))
    enh.set_image(image)
    times = []
    for i in range(repeats + 1):
        params = EnhanceParams(blur_rate=0.34, impulses=impulses, s_k=20.0 + i)
        res = enh.enhance((0.5, 0.5), params)
        if i:
            times.append(res.timings_s["noise"])
    med = float(np.median(times))
    return {"case": f"noise synthesis alone, {impulses} impulses", "source": source,
            "impulses": impulses, "median_s": med, "min_s": float(np.min(times)),
            "speedup_vs_release_cpp": RELEASE_NOISE_S[impulses] / med,
            "peak_rss_mb": peak_rss_mb()}


def case_foveation_error(samples: int = 20000) -> dict:
    """Fast blur stack against the exact per-pixel convolution, at random pixels."""
    from fovexp import EnhanceParams, Enhancer, load_display
    from fovexp.colour import linearize
    from fovexp.foveation import foveate, foveate_exact

    image, source = _frame()
    display = load_display("lg-oled55cx")
    lin = linearize(image, display.gamma)
    rows = []
    rng = np.random.default_rng(0)
    for br in (0.11, 0.34, 0.57):
        enh = Enhancer(display)
        enh.set_image(image)
        sigma = enh.enhance((0.5, 0.5), EnhanceParams(blur_rate=br, method="foveated")).map(
            "sigma_px")
        foveate(lin, sigma)
        t0 = time.perf_counter()
        fast = foveate(lin, sigma)
        dt = time.perf_counter() - t0
        blurred = np.flatnonzero(sigma.ravel() > 0)
        pick = rng.choice(blurred, size=min(samples, blurred.size), replace=False)
        ys, xs = np.unravel_index(pick, sigma.shape)
        err = np.abs(fast[ys, xs] - foveate_exact(lin, sigma, ys, xs)).max(axis=1)
        rows.append({"blur_rate": br, "max_sigma_px": float(sigma.max()), "time_s": dt,
                     "rms": float(np.sqrt(np.mean(err**2))),
                     "p99_9": float(np.quantile(err, 0.999)), "max": float(err.max()),
                     "pixels_checked": int(pick.size)})
    return {"case": "foveation error (linear [0, 1], blurred pixels)", "source": source,
            "rows": rows}


def case_foveation_tradeoff(samples: int = 20000) -> dict:
    """Run time against error of the blur stack's two knobs, at blur-rate 0.34."""
    from fovexp import EnhanceParams, Enhancer, load_display
    from fovexp.colour import linearize
    from fovexp.foveation import foveate, foveate_exact

    image, source = _frame()
    display = load_display("lg-oled55cx")
    lin = linearize(image, display.gamma)
    enh = Enhancer(display)
    enh.set_image(image)
    sigma = enh.enhance((0.5, 0.5), EnhanceParams(blur_rate=0.34, method="foveated")).map(
        "sigma_px")
    del enh
    rng = np.random.default_rng(0)
    blurred = np.flatnonzero(sigma.ravel() > 0)
    pick = rng.choice(blurred, size=min(samples, blurred.size), replace=False)
    ys, xs = np.unravel_index(pick, sigma.shape)
    exact = foveate_exact(lin, sigma, ys, xs)
    rows = []
    for ratio_exp in (0.125, 0.25, 0.5):
        for min_res in (0.75, 1.25, 2.0):
            kw = {"ratio": 2.0**ratio_exp, "min_residual_px": min_res}
            foveate(lin, sigma, **kw)
            times = []
            for _ in range(3):
                t0 = time.perf_counter()
                fast = foveate(lin, sigma, **kw)
                times.append(time.perf_counter() - t0)
            err = np.abs(fast[ys, xs] - exact).max(axis=1)
            rows.append({"ratio": f"2^{ratio_exp}", "min_residual_px": min_res,
                         "time_s": float(np.median(times)),
                         "rms": float(np.sqrt(np.mean(err**2))),
                         "p99_9": float(np.quantile(err, 0.999)), "max": float(err.max())})
    return {"case": "foveation trade-off", "source": source, "rows": rows}


def case_clipping() -> dict:
    """Fraction of noise-carrying pixels that adding the noise pushes out of [0, 1]."""
    from fovexp import EnhanceParams, Enhancer, load_display

    image, source = _frame()
    enh = Enhancer(load_display("lg-oled55cx"))
    enh.set_image(image)
    rows = []
    for br in (0.11, 0.34, 0.57):
        for n in (12, 64):
            res = enh.enhance((0.5, 0.5), EnhanceParams(blur_rate=br, impulses=n))
            c, noise = res.linear("contrast"), res.map("noise")[..., None]
            inside = (c >= 0) & (c <= 1)
            total = c + noise
            pushed = inside & ((total < 0) | (total > 1))
            noisy = inside & (noise != 0)
            excess = np.maximum(total - 1, -total)[pushed]
            rows.append({"blur_rate": br, "impulses": n, "noisy_fraction": float(noisy.mean()),
                         "pushed_fraction_of_noisy": float(pushed.sum() / max(noisy.sum(), 1)),
                         "max_excess": float(excess.max()) if excess.size else 0.0})
    return {"case": "clipping control", "source": source, "rows": rows}


CASES = {
    "timing": case_timing, "noise": case_noise_alone, "foveation": case_foveation_error,
    "tradeoff": case_foveation_tradeoff, "clipping": case_clipping,
}


def machine() -> dict:
    import numba
    import scipy

    cpu = machine_cpu()
    mem_gb = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30
    return {"cpu": cpu, "cores": os.cpu_count(), "memory_gb": round(mem_gb, 1),
            "python": platform.python_version(), "numpy": np.__version__,
            "scipy": scipy.__version__, "numba": numba.__version__,
            "numba_threads": numba.config.NUMBA_NUM_THREADS,
            "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}


def _sub(case: str, **kw) -> dict:
    out = subprocess.run(
        [sys.executable, __file__, "--case", case, "--kw", json.dumps(kw)],
        check=True, capture_output=True, text=True,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--case")
    ap.add_argument("--kw", default="{}")
    ap.add_argument("--repeats", type=int, default=7)
    args = ap.parse_args()
    if args.case:
        print(json.dumps(CASES[args.case](**json.loads(args.kw))))
        return
    results = {"machine": machine(), "cases": []}
    for n in (12, 64):
        for pre in (True, False):
            results["cases"].append(_sub("timing", impulses=n, prefoveated=pre,
                                         repeats=args.repeats))
        results["cases"].append(_sub("noise", impulses=n, repeats=args.repeats))
    results["cases"].append(_sub("foveation"))
    results["cases"].append(_sub("tradeoff"))
    results["cases"].append(_sub("clipping"))
    (HERE / "results.json").write_text(json.dumps(results, indent=1))
    (HERE / "RESULTS.md").write_text(report(results))
    print(report(results))


#: The other records in benchmarks/ (RESULTS.md lists them first).
INDEX = [
    "Other records in this folder: [BENCH.md](BENCH.md) (`fovexp bench`: run time against "
    "error of every engine option, noise statistics, time and memory against resolution), "
    "[SKIPPING.md](SKIPPING.md) (skipping flat regions), [GPU.md](GPU.md) (the GPU backend, "
    "per stage), [CLI.md](CLI.md) (the command line), [SCENES.md](SCENES.md) (generated "
    "scenes), [DISPLAY_LOOP.md](DISPLAY_LOOP.md) (the runner's display loop), "
    "[WHEEL_STEPS.md](WHEEL_STEPS.md) (wheel-step cost).",
]


def report(r: dict) -> str:
    m = r["machine"]
    lines = [
        "# Benchmark results", "",
        f"Machine: {m['cpu']}, {m['cores']} cores, {m['memory_gb']} GB; Python {m['python']}, "
        f"NumPy {m['numpy']}, SciPy {m['scipy']}, Numba {m['numba']} "
        f"({m['numba_threads']} threads); {m['date']}.",
        "Command: `.venv/bin/python benchmarks/run.py` (medians of 7 frames after 2 warm-up "
        "frames; peak RSS of the case's own process).", "",
        *INDEX, "",
        "## Speed and memory (4K, blur-rate 0.34, LG OLED55CX profile)", "",
        "| case | median s | min s | peak RSS MB | target |", "|---|---|---|---|---|",
    ]
    targets = {("enhance foveated frame", 12): "<= 1.0 s", ("noise synthesis alone", 12):
               "<= 0.25 s", ("noise synthesis alone", 64): "<= 1.2 s"}
    for c in r["cases"]:
        if "median_s" not in c:
            continue
        key = (c["case"].split(",")[0], c["impulses"])
        lines.append(f"| {c['case']} | {c['median_s']:.3f} | {c['min_s']:.3f} | "
                     f"{c['peak_rss_mb']:.0f} | {targets.get(key, '')} |")
    lines += ["", "Stage medians (s) of the per-frame cases:", ""]
    for c in r["cases"]:
        if "stages_median_s" in c:
            st = ", ".join(f"{k} {v:.3f}" for k, v in sorted(
                c["stages_median_s"].items(), key=lambda kv: -kv[1]) if v >= 0.001)
            lines.append(f"- {c['case']}: {st}")
    for c in r["cases"]:
        if "speedup_vs_release_cpp" in c:
            lines.append(f"- {c['case']}: "
                         f"{c['speedup_vs_release_cpp']:.0f}x the release's C++ "
                         f"({RELEASE_NOISE_S[c['impulses']]:.0f} s, docs/METHOD.md, 7)")
    fov = next(c for c in r["cases"] if c["case"].startswith("foveation"))
    lines += ["", "## Foveation: fast blur stack against the exact per-pixel convolution", "",
              f"{fov['source']}, linear values in [0, 1], errors over random blurred pixels "
              "(max over channels).", "",
              "| blur-rate | max sigma px | time s | RMS | 99.9th pct | max | pixels |",
              "|---|---|---|---|---|---|---|"]
    for row in fov["rows"]:
        lines.append(f"| {row['blur_rate']} | {row['max_sigma_px']:.1f} | {row['time_s']:.2f} | "
                     f"{row['rms']:.5f} | {row['p99_9']:.4f} | {row['max']:.4f} | "
                     f"{row['pixels_checked']} |")
    trade = next(c for c in r["cases"] if c["case"].startswith("foveation trade-off"))
    lines += ["", "Run time against error (blur-rate 0.34): stack ratio past 1.5 px, and the least "
              "residual blur (level px) before a level moves to a coarser pyramid level. The "
              "default is 2^0.25 and 1.25.", "",
              "| ratio | min residual px | time s | RMS | 99.9th pct | max |",
              "|---|---|---|---|---|---|"]
    for row in trade["rows"]:
        lines.append(f"| {row['ratio']} | {row['min_residual_px']} | {row['time_s']:.2f} | "
                     f"{row['rms']:.5f} | {row['p99_9']:.4f} | {row['max']:.4f} |")
    clip = next(c for c in r["cases"] if c["case"].startswith("clipping"))
    lines += ["", "## Clipping control", "",
              "Pixels the noise pushes out of [0, 1] (linear, before display clipping), as a "
              "fraction of the pixels that carry noise.", "",
              "| blur-rate | impulses | noisy fraction | pushed / noisy | max excess |",
              "|---|---|---|---|---|"]
    for row in clip["rows"]:
        lines.append(f"| {row['blur_rate']} | {row['impulses']} | {row['noisy_fraction']:.3f} | "
                     f"{row['pushed_fraction_of_noisy']:.5f} | {row['max_excess']:.3f} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
