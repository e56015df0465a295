"""What one mouse-wheel step costs the experiment runner at 4K: the enhancer with the runner's
half-frame viewport (the mirrored left half, enhanced at the right of a 3840x2160 frame), gaze
at the centre, 12 impulses, CPU. Writes benchmarks/WHEEL_STEPS.md.

    .venv/bin/python benchmarks/wheel_steps.py
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from fovexp import EnhanceParams, Enhancer, load_display, read_image

HERE = Path(__file__).resolve().parent
SPONZA = HERE.parent.parent / "shared" / "stimuli" / "sponza-4k.jpg"


def main() -> None:
    from run import machine  # the same machine description as the main benchmark

    img = read_image(SPONZA)
    h, w = img.shape[:2]
    half = np.ascontiguousarray(img[:, : w // 2][:, ::-1])
    enh = Enhancer(load_display("lg-oled55cx"))
    enh.set_image(half, viewport=(w // 2, 0, w, h))
    p = EnhanceParams(blur_rate=0.34, impulses=12).resolved()
    enh.enhance((0.5, 0.5), p)
    steps = {"s_k": [10, 12, 14, 16, 18, 20, 22], "f_e": [0.1, 0.12, 0.14, 0.16, 0.18, 0.2, 0.22],
             "blur_rate": [0.3, 0.32, 0.36, 0.38, 0.4, 0.42, 0.44]}
    m = machine()
    lines = ["# Wheel-step cost in the runner (4K, CPU)", "",
             f"Machine: {m['cpu']}, {m['cores']} cores; Numba {m['numba']}; {m['date']}. "
             "Command: `.venv/bin/python benchmarks/wheel_steps.py` (Sponza, half-frame "
             "viewport, 12 impulses; medians of 7 steps).", "",
             "| parameter stepped | median s | min s |", "|---|---|---|"]
    for key, values in steps.items():
        times = []
        for v in values:
            t0 = time.perf_counter()
            enh.enhance((0.5, 0.5), p.model_copy(update={key: v}))
            times.append(time.perf_counter() - t0)
        lines.append(f"| {key} | {np.median(times):.3f} | {min(times):.3f} |")
    text = "\n".join(lines) + "\n"
    (HERE / "WHEEL_STEPS.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
