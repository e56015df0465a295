"""Time, file size and memory of the generated scenes (fovexp.stimuli.scenes); results written
to benchmarks/SCENES.md and benchmarks/scenes.json with the machine they came from.

    .venv/bin/python benchmarks/scenes.py [--sizes 3840x2160 480x270] [--repeats 3]

Per scene and resolution: drawing (median of the repeats), PNG encoding, PNG size, and the peak
resident memory of a process that draws and encodes one 4K scene. Then what an operator waits
for: ``fovexp stimuli generate --force`` into a scratch folder, all fifteen scenes, with one job
and with one job per core, wall-clock (median of the repeats, the two settings interleaved).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from run import machine, peak_rss_mb, reset_peak_rss  # noqa: E402


def per_scene(size: tuple[int, int], repeats: int) -> list[dict]:
    from fovexp.stimuli import scenes

    rows = []
    for spec in scenes.SCENES:
        draw = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            px = scenes.render_scene(spec.index, *size)
            draw.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        data = scenes.png_bytes(px)
        enc = time.perf_counter() - t0
        rows.append({"id": spec.id, "ground": spec.ground, "dark": spec.dark,
                     "draw_s": statistics.median(draw), "png_s": enc, "png_mb": len(data) / 1e6})
    return rows


def peak_memory_4k() -> float:
    """Peak RSS (MB) of this process while it draws and encodes the most demanding scene."""
    from fovexp.stimuli import scenes

    reset_peak_rss()
    scenes.png_bytes(scenes.render_scene(1, 3840, 2160))  # cobblestones: the largest arrays
    return peak_rss_mb()


def generate_wall(size: str, jobs: int) -> float:
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "fovexp", "stimuli", "generate", "--size", size,
                        "--jobs", str(jobs), "--force", "--stimuli", tmp],
                       check=True, capture_output=True)
        return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", nargs="+", default=["3840x2160", "480x270"])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--case", default=None, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.case == "memory":
        print(json.dumps({"peak_rss_mb": peak_memory_4k()}))
        return
    out: dict = {"machine": machine(), "sizes": {}}
    for s in args.sizes:
        size = tuple(int(v) for v in s.split("x"))
        rows = per_scene(size, args.repeats)  # type: ignore[arg-type]
        walls: dict[int, list[float]] = {1: [], os.cpu_count() or 1: []}
        for _ in range(args.repeats):
            for jobs in walls:  # interleaved
                walls[jobs].append(generate_wall(s, jobs))
        out["sizes"][s] = {
            "scenes": rows,
            "png_mb_total": sum(r["png_mb"] for r in rows),
            "generate_s": {str(j): statistics.median(v) for j, v in walls.items()},
            "generate_s_all": {str(j): v for j, v in walls.items()},
        }
    mem = subprocess.run([sys.executable, __file__, "--case", "memory"], check=True,
                         capture_output=True, text=True)
    out["peak_rss_mb_4k"] = json.loads(mem.stdout.strip().splitlines()[-1])["peak_rss_mb"]
    (HERE / "scenes.json").write_text(json.dumps(out, indent=1))
    m = out["machine"]
    lines = [
        "# Generated scenes: time, size, memory",
        "",
        f"Machine: {m['cpu']}, {m['cores']} cores, {m['memory_gb']} GB; Python {m['python']}, "
        f"numpy {m['numpy']}; {m['date']}. Command: `.venv/bin/python benchmarks/scenes.py`.",
        "Shared machine: other jobs ran beside it, so the times are noisy (medians of "
        f"{args.repeats}).",
        "",
        "| resolution | `fovexp stimuli generate --force`, all 15 | PNG, all 15 | per scene: draw "
        "(median, min-max) | PNG encode | PNG size |",
        "|---|---|---|---|---|---|",
    ]
    for s, d in out["sizes"].items():
        rows = d["scenes"]
        gen = ", ".join(f"{v:.1f} s ({j} job{'s' if j != '1' else ''})"
                        for j, v in d["generate_s"].items())
        draw = [r["draw_s"] for r in rows]
        enc = [r["png_s"] for r in rows]
        mb = [r["png_mb"] for r in rows]
        lines.append(
            f"| {s} | {gen} | {d['png_mb_total']:.1f} MB | {statistics.median(draw):.2f} s "
            f"({min(draw):.2f}-{max(draw):.2f}) | {statistics.median(enc):.2f} s | "
            f"{min(mb):.2f}-{max(mb):.2f} MB |")
    lines += ["", f"Peak resident memory drawing and encoding one 4K scene (scene-01, the "
              f"cobblestones): {out['peak_rss_mb_4k']:.0f} MB.", ""]
    big = out["sizes"].get("3840x2160")
    if big:
        lines += ["Per scene at 3840x2160:", "", "| scene | ground | night | draw | PNG | size |",
                  "|---|---|---|---|---|---|"]
        lines += [f"| {r['id']} | {r['ground']} | {'yes' if r['dark'] else ''} | "
                  f"{r['draw_s']:.2f} s | {r['png_s']:.2f} s | {r['png_mb']:.2f} MB |"
                  for r in big["scenes"]]
    (HERE / "SCENES.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
