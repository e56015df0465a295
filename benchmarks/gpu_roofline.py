"""Roofline PREDICTION of the GPU backend's time per compute entry for a 4K frame on named GPUs.

    .venv/bin/python benchmarks/gpu_roofline.py              # print the tables
    .venv/bin/python benchmarks/gpu_roofline.py --update-docs  # rewrite them in docs/GPU.md

Method. For each compute entry of ``fovexp/gpu/shaders/`` the work of one frame is counted
from the shader source (the per-invocation counts below, each with the code it counts) times
the invocations the backend dispatches for the frame, which follow from the Python code the
backend runs: the blur-stack plan (``foveation.blur_stack_plan``), the pyramid levels, the
impulses (``gabor.generate_impulses``), the sigma map and the 16 x 16 tiles the foveation
skips by (computed here as the shaders decide it). Counted per entry:

- bytes: DRAM traffic, each buffer element a dispatch reads or writes moved once (neighbours
  of a stencil come from the caches); the per-impulse gathers count one 32-byte sector per row
  of taps (an upper bound: neighbouring impulses share sectors);
- flops: float32 arithmetic, a fused multiply-add counted 2, a compare/min/max/abs 1; integer
  index arithmetic is not counted;
- sfu: transcendentals (exp, exp2, log, log2, sqrt, reciprocal, sin, cos, atan's reciprocal;
  pow = log2 + exp2), which run on the special-function units;
- fp64: float64 operations (the fixed-point conversion of the summed-area table and the
  contrast change; the table's 64-bit integer adds are not counted); a division counts
  10 (a reciprocal estimate refined by Newton steps in FMA).

The predicted time of an entry is max(bytes / bandwidth, flops / FP32 peak, sfu / SFU rate,
fp64 / FP64 peak): the time no implementation of that work can beat on that GPU, reached only
by a kernel that keeps the bound unit busy. Not modelled: the idle time between dispatches
(each is followed by a memory barrier; the dispatch count is given), occupancy (SAT_ROWS and
SAT_COLS run one invocation per row or column, about 2 300 and 4 000 of them: too few to hide
memory latency, so they will be slower than predicted) and the caches' real hit rates.
"""

from __future__ import annotations

import argparse
import math
import re
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
DOCS = HERE.parent / "docs" / "GPU.md"
BEGIN, END = "<!-- roofline:begin -->", "<!-- roofline:end -->"


@dataclass(frozen=True)
class Device:
    name: str
    bandwidth_gb_s: float  #: DRAM bandwidth, GB/s
    fp32_tflops: float  #: FP32 peak, FMA counted 2
    fp64_tflops: float
    sfu_tops: float  #: SFU results per second (16 per SM per clock on Turing and Hopper)
    source: str


#: Peak figures assumed (boost clocks). The SFU rate is SMs x 16 x boost clock: 16 results per
#: clock per SM for compute capability 7.5 (Turing) and 9.0 (Hopper) in the CUDA C++
#: Programming Guide's table of arithmetic-instruction throughput (a quarter of the FP32 lanes
#: on Turing, an eighth on Hopper).
DEVICES: dict[str, Device] = {
    "rtx2080ti": Device(
        "NVIDIA GeForce RTX 2080 Ti (the paper's)", 616.0, 13.45, 13.45 / 32, 68 * 16 * 1.545e-3,
        "NVIDIA Turing GPU Architecture whitepaper (2018), reference board: 68 SMs, 4352 FP32 "
        "lanes at 1545 MHz boost, 352-bit GDDR6 at 14 Gbps = 616 GB/s; FP64 at 1/32 of FP32"),
    "h100-pcie": Device(
        "NVIDIA H100 PCIe", 2000.0, 51.2, 25.6, 114 * 16 * 1.755e-3,
        "NVIDIA H100 PCIe product brief PB-11133-001 and H100 datasheet: 114 SMs at 1755 MHz "
        "boost, 51 TFLOPS FP32, 26 TFLOPS FP64 (non-tensor), 2.0 TB/s HBM2e"),
    "h100-sxm": Device(
        "NVIDIA H100 SXM5", 3350.0, 66.9, 33.5, 132 * 16 * 1.98e-3,
        "NVIDIA H100 datasheet and Hopper architecture whitepaper: 132 SMs at 1980 MHz boost, "
        "67 TFLOPS FP32, 34 TFLOPS FP64 (non-tensor), 3.35 TB/s HBM3"),
}

# ------------------------------------------------------------------ per-invocation counts
# (flops, sfu) of the GLSL functions, read off their source; see the module docstring.
SCREEN_CM = (8, 0)  # geometry.glsl screen_cm: per axis add, add, FMA (0.5 screen), mul
# eccentricity_deg (exact): two screen_cm, cross (9), length (5 + sqrt), dot (5),
# atan(y, x) (about 25 and a reciprocal), degrees (1)
ECCENTRICITY = (2 * SCREEN_CM[0] + 9 + 5 + 5 + 25 + 1, 2)
# ppd (exact): screen_cm, sqrt(pitch x * pitch y) (1 + sqrt), dot + D^2 (5), sqrt, radians (1),
# the division by the pitch (1 + reciprocal)
PPD = (SCREEN_CM[0] + 1 + 5 + 1 + 1, 3)
SIGMA_PX = (5, 0)  # foveation.glsl sigma_px: max, sub, three muls
# frequency_band_cpp: two Thibos interpolations (about 8 compares, 2 subs, a division, an FMA
# each), two divisions by ppd, blur_cutoff (compare, division), max, min
BAND = (2 * 12 + 2 + 3 + 2, 5)
BAND_AT = (4 + ECCENTRICITY[0] + PPD[0] + SIGMA_PX[0] + BAND[0],
           ECCENTRICITY[1] + PPD[1] + BAND[1])  # pipeline.glsl band_at, the clamp included
# draw_truncated: lognormal_params (2 logs, 5), z_high (log, division, 1), two erfc (each:
# abs, a reciprocal, a 10-term Horner chain, exp, 5), p and q (3), normal_ppf (a 6/5-term
# rational in either branch, about 26, a division; the tails a log and a sqrt), exp, min
DRAW = (5 + 2 + 2 * 27 + 3 + 26 + 3, 2 + 2 + 2 * 2 + 2 + 1)
LAPLACIAN_LEVEL = (8, 4)  # amplitude.glsl: log, sqrt, division, log2, max
# laplacian_amplitude_at: two bilinear samples (scaling 2, taps 10, 4 FMA = 8) and the lerp
LAPLACIAN_AT = (2 * 20 + 6, 0)
HEADROOM_AND_K = (4 + 3, 0)  # headroom_limit_at, amplitude_k
# orientation_at: two gradient_cubic (20 Keys weights of about 8, 16 mul + FMA, setup 6),
# length (5 + sqrt), atan (25 + reciprocal), compare and sub
ORIENTATION = (2 * (20 * 8 + 16 * 3 + 6) + 5 + 25 + 2, 2)
CARRIER = (8, 2)  # IMPULSES: 2 pi F (cos t, sin t) and the amplitude


def _add(*parts: tuple[int, int]) -> tuple[int, int]:
    return sum(p[0] for p in parts), sum(p[1] for p in parts)


IMPULSE = _add(BAND_AT, DRAW, LAPLACIAN_LEVEL, LAPLACIAN_AT, HEADROOM_AND_K, ORIENTATION,
               CARRIER)
AMPLITUDE_MAP = _add(BAND_AT, LAPLACIAN_LEVEL, LAPLACIAN_AT, HEADROOM_AND_K)
# gathers per impulse (32-byte sectors): gradients 2 components x 4 rows, |L| 2 levels x 2 rows,
# headroom lo and hi; plus its record (16), quantiles (8) and the parameters written (32)
IMPULSE_BYTES = (2 * 4 + 2 * 2 + 2) * 32 + 16 + 8 + 32
# NOISE, per impulse of the 3 x 3 cells visited with A != 0: d (2), two abs and compares (4);
# per impulse inside the kernel's square: phase (3), |d|^2 (3), exponent (1), exp (1 + ex2),
# cos (1 + cos), accumulate (3)
NOISE_VISIT, NOISE_KERNEL = (6, 0), (12, 2)
FP64_DIVISION = 10

#: What one invocation of each entry is (its work group's threads)
INVOCATION_UNITS = {
    "LINEARIZE": "px", "TILE_EXTREMES": "px", "SIGMA": "px", "REDUCE": "level sample",
    "STACK_INIT": "px",
    "BLUR": "level sample, needed groups", "STACK_ACCUMULATE": "px, needed tiles",
    "LUMINANCE": "px", "ABS_LAPLACIAN": "level sample", "BOX3": "level sample",
    "SOBEL": "level-3 sample", "SAT_ROWS": "padded row", "SAT_COLS": "padded column",
    "CONTRAST_CHANGE": "px", "BLOCK_EXTREMES": "8 x 8 block", "EXTREMES_FILTER": "8 x 8 block",
    "IMPULSES": "impulse", "NOISE": "px", "COMPOSE": "px",
}


@dataclass
class Cost:
    entry: str
    stage: str
    dispatches: int = 0
    invocations: int = 0
    bytes: float = 0.0
    flops: float = 0.0
    sfu: float = 0.0
    fp64: float = 0.0

    def per_invocation(self) -> str:
        """Average bytes and operations of one invocation."""
        n = max(self.invocations, 1)

        def num(v: float) -> str:
            return f"{v:,.0f}" if v >= 1000 else f"{v:.3g}"

        parts = [f"{num(self.bytes / n)} B", f"{num(self.flops / n)} FLOP"]
        parts += [f"{num(v / n)} {k}" for k, v in (("SFU", self.sfu), ("FP64", self.fp64)) if v]
        return ", ".join(parts)

    def seconds(self, dev: Device) -> tuple[float, str]:
        """(predicted s, the bound: memory, fp32, sfu or fp64)."""
        t = {"memory": self.bytes / (dev.bandwidth_gb_s * 1e9),
             "fp32": self.flops / (dev.fp32_tflops * 1e12),
             "sfu": self.sfu / (dev.sfu_tops * 1e12),
             "fp64": self.fp64 / (dev.fp64_tflops * 1e12)}
        bound = max(t, key=t.get)
        return t[bound], bound


class _Frame:
    """Accumulates the costs of one frame's dispatches, by entry."""

    def __init__(self) -> None:
        self.costs: dict[str, Cost] = {}

    def add(self, entry: str, stage: str, invocations: int, bytes_: float = 0.0,
            flops: float = 0.0, sfu: float = 0.0, fp64: float = 0.0, dispatches: int = 1) -> None:
        c = self.costs.setdefault(entry, Cost(entry, stage))
        if stage not in c.stage.split(", "):
            c.stage += f", {stage}"
        c.dispatches += dispatches
        c.invocations += int(invocations)
        c.bytes += bytes_
        c.flops += flops
        c.sfu += sfu
        c.fp64 += fp64


def _tile_ranges(sigma: np.ndarray, tile: int) -> tuple[np.ndarray, np.ndarray]:
    """Each tile's sigma (min, max): foveation.glsl SIGMA's TILES."""
    h, w = sigma.shape
    ty, tx = -(-h // tile), -(-w // tile)
    b = np.pad(sigma, ((0, ty * tile - h), (0, tx * tile - w)), mode="edge")
    b = b.reshape(ty, tile, tx, tile)
    return b.min(axis=(1, 3)), b.max(axis=(1, 3))


def _groups_needed(need: np.ndarray, grid_hw: tuple[int, int], tile: int, scale: int, pad: int,
                   margin_yx: tuple[int, int]) -> np.ndarray:
    """foveation.glsl region_needed for every work group of a level grid: whether any tile its
    samples feed needs the stack level."""
    cum = np.zeros((need.shape[0] + 1, need.shape[1] + 1), np.int64)
    cum[1:, 1:] = need.cumsum(0).cumsum(1)
    spans = []  # per axis: the first and one past the last tile each group's region meets
    for n, m, tiles in zip(grid_hw, margin_yx, need.shape, strict=True):
        g0 = np.arange(-(-n // tile)) * tile
        lo = np.clip(np.maximum((g0 - m) * scale - pad, 0) // tile, 0, tiles - 1)
        hi = np.clip(np.maximum((g0 + tile + m) * scale - pad, 0) // tile, 0, tiles - 1)
        spans.append((lo, hi + 1))
    (y0, y1), (x0, x1) = spans
    count = cum[y1][:, x1] - cum[y0][:, x1] - cum[y1][:, x0] + cum[y0][:, x0]
    return count > 0


def _samples_in(groups: np.ndarray, grid_hw: tuple[int, int], tile: int) -> int:
    """Samples of a grid covered by the selected work groups (edge groups are partial)."""
    rows = np.minimum(tile, grid_hw[0] - np.arange(groups.shape[0]) * tile)
    cols = np.minimum(tile, grid_hw[1] - np.arange(groups.shape[1]) * tile)
    return int((rows[:, None] * cols[None, :] * groups).sum())


def frame_costs(width: int = 3840, height: int = 2160, channels: int = 3, impulses: int = 12,
                blur_rate: float = 0.34, gaze: tuple[float, float] = (0.5, 0.5),
                simulate_foveation: bool = True, display_name: str = "lg-oled55cx",
                seed: int = 0) -> tuple[list[Cost], dict]:
    """The costs of one frame's dispatches, by entry (the order they first run), and the
    frame's facts (impulse count, stack levels, ...)."""
    from fovexp import gabor, load_display
    from fovexp.amplitude import MAX_LAPLACIAN_LEVEL
    from fovexp.contrast import sat_pad_px
    from fovexp.foveation import blur_stack_plan, sigma_px
    from fovexp.frequency import frequency_band_cpp
    from fovexp.geometry import ViewingGeometry
    from fovexp.gpu.programs import LOCAL_1D, LOCAL_2D
    from fovexp.orientation import ORIENTATION_LEVEL
    from fovexp.params import get_preset

    preset = get_preset("paper")
    h, w, c = height, width, channels
    n_px = h * w
    tile = LOCAL_2D[0]
    geom = ViewingGeometry.for_image(load_display(display_name), w, h, "exact", None)
    gaze_px = geom.gaze_px(gaze)
    ecc, ppd = geom.eccentricity_and_ppd_maps(gaze_px)
    sigma = sigma_px(ecc, ppd, blur_rate, preset.fovea_deg).astype(np.float32)
    max_sigma = float(sigma.max())
    f = _Frame()
    blurred = sigma > 0
    facts: dict = {"frame": f"{w}x{h} {'RGB' if c == 3 else 'grey'}", "impulses_per_kernel":
                   impulses, "blur_rate": blur_rate, "max_sigma_px": round(max_sigma, 2),
                   "foveation": "simulated" if simulate_foveation else "already foveated"}

    f.add("LINEARIZE", "linear", n_px, 8 * c * n_px, 1 * c * n_px, 2 * c * n_px)
    f.add("SIGMA", "sigma", n_px, 4 * n_px + 8 * n_px / tile**2,
          (ECCENTRICITY[0] + PPD[0] + SIGMA_PX[0]) * n_px, (ECCENTRICITY[1] + PPD[1]) * n_px)

    if simulate_foveation and max_sigma > 0:
        plan = blur_stack_plan(max_sigma)
        pad = plan.pad_px
        grids = [(h, w)]
        ph, pw = h + 2 * pad, w + 2 * pad
        for _ in range(plan.top):
            ph, pw = (ph + 1) // 2, (pw + 1) // 2
            grids.append((ph, pw))
        for m in range(1, plan.top + 1):  # REDUCE: 5 x 5 taps per sample and channel
            dst = grids[m][0] * grids[m][1]
            src = grids[m - 1][0] * grids[m - 1][1]
            f.add("REDUCE", "foveated", dst, 4 * c * (src + dst), 60 * c * dst)
        levels = plan.sigmas_px
        n_lv = levels.size
        # TILE_EXTREMES (skipping): each tile's min and max per channel of the linear image,
        # a shared-memory tree (2 compares per sample and channel)
        f.add("TILE_EXTREMES", "foveated", n_px, 4 * c * n_px + 8 * c * n_px / tile**2,
              2 * c * n_px)
        # STACK_INIT: the bracketing search over the levels, t, level 0's weight per channel
        f.add("STACK_INIT", "foveated", n_px, (4 + 8 + 8 * c) * n_px,
              (n_lv + 4 + 2 * c) * n_px, n_px)
        lo, hi = _tile_ranges(sigma, tile)
        s = sigma.astype(np.float64)
        k = np.where(s > 0, np.minimum(np.searchsorted(levels, s, side="left") - 1, n_lv - 2), -1)
        facts.update(stack_levels=int(n_lv), pyramid_top=plan.top, pad_px=pad)
        blur_samples = 0
        for lv in range(1, n_lv):
            m = int(plan.pyramid_level[lv])
            g, scale = grids[m], 1 << m
            level_pad = pad if m > 0 else 0
            need_hi = levels[lv + 1] if lv + 1 < n_lv else np.inf
            need = (hi > levels[lv - 1]) & (lo <= need_hi)
            radius = plan.kernels[lv].size // 2
            for along_y in (1, 0):  # BLUR: (2 r + 1) FMA per sample and channel
                margin_yx = (1, radius + 1) if along_y else (1, 1)  # the shader's, (y, x)
                groups = _groups_needed(need, g, tile, scale, level_pad, margin_yx)
                active = _samples_in(groups, g, tile)
                blur_samples += active
                f.add("BLUR", "foveated", active, 8 * c * active,
                      2 * (2 * radius + 1) * c * active)
            in_tiles = int(need.sum()) * tile * tile
            used = int(((k == lv) | (k == lv - 1)).sum())
            # STACK_ACCUMULATE: the bracket read in every needed tile; where this level is
            # one of the pixel's two: weights (16) and 4 taps + the add per channel
            f.add("STACK_ACCUMULATE", "foveated", in_tiles,
                  8 * in_tiles + (8 * c + 4 * c / scale**2) * used, (16 + 8 * c) * used)
        facts["blur_samples_per_px"] = round(blur_samples / n_px, 2)

    f.add("LUMINANCE", "luma", n_px, (4 * c + 4) * n_px, (5 if c == 3 else 0) * n_px)
    # the luminance's tile extremes, which the |L|, contrast and noise early exits read
    f.add("TILE_EXTREMES", "luma", n_px, 4 * n_px + 8 * n_px / tile**2, 2 * n_px)
    luma = [(h, w)]
    while len(luma) <= MAX_LAPLACIAN_LEVEL and min(luma[-1]) >= 2:
        luma.append(((luma[-1][0] + 1) // 2, (luma[-1][1] + 1) // 2))
    for m in range(1, len(luma)):
        dst, src = luma[m][0] * luma[m][1], luma[m - 1][0] * luma[m - 1][1]
        f.add("REDUCE", "pyramid", dst, 4 * (src + dst), 60 * dst)
    for kk in range(1, min(MAX_LAPLACIAN_LEVEL, len(luma) - 1) + 1):
        n = luma[kk - 1][0] * luma[kk - 1][1]  # |L_k| on G_{k-1}'s grid
        f.add("ABS_LAPLACIAN", "abs_laplacian", n, 9 * n, 26 * n)
        f.add("BOX3", "abs_laplacian", n, 8 * n, 10 * n)
    n = luma[ORIENTATION_LEVEL][0] * luma[ORIENTATION_LEVEL][1]
    f.add("SOBEL", "gradients", n, 12 * n, 18 * n)

    if max_sigma > 0:
        sp = sat_pad_px(max_sigma)
        hp, wp = h + 2 * sp, w + 2 * sp
        sat_bytes = 8 * (hp + 1) * (wp + 1)
        # The table holds 64-bit integers (fixed point, contrast.glsl): its adds are integer
        # work (two 32-bit operations each on most GPUs), not counted. SAT_ROWS: per element
        # the symmetric index (a float division: 3 + reciprocal) and the value in fixed point
        # (to double, the scale, roundEven, to int64: 4 FP64); SAT_COLS: integer adds only
        f.add("SAT_ROWS", "sat", hp, 4 * n_px + sat_bytes, 3 * hp * wp, hp * wp, 4 * hp * wp)
        f.add("SAT_COLS", "sat", wp, 2 * sat_bytes, 0, 0, 0)
        # CONTRAST_CHANGE per blurred pixel: t and the pixel in fixed point (5 FP64), then per
        # integer level (two) the box by 4 integer corners, and in FP64 the difference's
        # conversion, the division by n^2, the gain 1 - f_e (1 + k) (3) and the weighted
        # accumulation (3); the result scaled (1)
        nb = int(blurred.sum())
        f.add("CONTRAST_CHANGE", "contrast", n_px, 12 * n_px + sat_bytes, 4 * nb, 0,
              nb * (2 * (1 + FP64_DIVISION + 3 + 3) + 6))
        facts["sat_pad_px"] = sp

    block = 1 << preset.minmax_level
    bh, bw = -(-h // block), -(-w // block)
    radius = int(math.ceil(gabor.kernel_radius_px(preset.gabor_a_cpp) / block))
    f.add("BLOCK_EXTREMES", "headroom", bh * bw, (4 * c + 4) * n_px + 8 * bh * bw, 3 * c * n_px)
    f.add("EXTREMES_FILTER", "headroom", bh * bw, 16 * bh * bw,
          2 * (2 * radius + 1) ** 2 * bh * bw)

    imp = gabor.generate_impulses(w, h, impulses, preset.gabor_a_cpp, seed)
    n_imp = len(imp)
    xi = np.clip(imp.x_px, 0, w - 1)
    yi = np.clip(imp.y_px, 0, h - 1)
    e_i = geom.eccentricity_deg(xi, yi, gaze_px)
    p_i = geom.ppd(xi, yi)
    f_lo, f_hi = frequency_band_cpp(e_i, p_i, sigma_px(e_i, p_i, blur_rate, preset.fovea_deg))
    open_fraction = float((f_lo < f_hi).mean())
    f.add("IMPULSES", "imp_params", n_imp, IMPULSE_BYTES * n_imp, IMPULSE[0] * n_imp,
          IMPULSE[1] * n_imp, dispatches=max(1, -(-n_imp // (65535 * LOCAL_1D))))
    per_cell = impulses / math.pi  # gabor.generate_impulses: N / pi per cell of side r
    visited, inside = 9 * per_cell, 4 * per_cell  # 3 x 3 cells; the (2r)^2 square of (3r)^2
    nx, ny = gabor.cell_counts(w, h, imp.cell_px)
    f.add("NOISE", "noise", n_px, 4 * n_px + 48 * n_imp + 4 * nx * ny,
          (5 + open_fraction * (visited * NOISE_VISIT[0] + inside * NOISE_KERNEL[0])) * n_px,
          open_fraction * inside * NOISE_KERNEL[1] * n_px)
    facts.update(impulse_count=n_imp, open_impulse_fraction=round(open_fraction, 3),
                 impulses_visited_per_px=round(visited, 1))
    f.add("COMPOSE", "output", n_px, (8 * c + 8) * n_px, (1 + 4 * c) * n_px, 2 * c * n_px)
    return list(f.costs.values()), facts


def map_costs(width: int = 3840, height: int = 2160) -> list[Cost]:
    """pipeline.glsl MAPS, one dispatch per map (EnhanceResult.map / --dump-maps)."""
    n = width * height
    return [
        Cost("MAPS eccentricity/F_L/F_H (each)", "maps", 1, n, 4 * n, BAND_AT[0] * n,
             BAND_AT[1] * n),
        Cost("MAPS amplitude", "maps", 1, n, 4 * n + 5 * n, AMPLITUDE_MAP[0] * n,
             AMPLITUDE_MAP[1] * n),
        Cost("MAPS orientation", "maps", 1, n, 4 * n, ORIENTATION[0] * n, ORIENTATION[1] * n),
    ]


def predictions(devices: tuple[str, ...] = tuple(DEVICES)) -> dict:
    """Predicted ms per entry and in all, per device, for the four 4K frames (12 and 64
    impulses, with and without the foveation simulation), at the default parameters."""
    out = {}
    for impulses in (12, 64):
        for simulate in (False, True):
            costs, facts = frame_costs(impulses=impulses, simulate_foveation=simulate)
            per_dev = {}
            for d in devices:
                ms = {c.entry: c.seconds(DEVICES[d]) for c in costs}
                per_dev[d] = {"entries": {k: (v[0] * 1e3, v[1]) for k, v in ms.items()},
                              "total_ms": sum(v[0] for v in ms.values()) * 1e3}
            out[(impulses, simulate)] = {"costs": costs, "facts": facts, "devices": per_dev}
    return out


def device_for(renderer: str) -> str | None:
    """The DEVICES key of a GL_RENDERER string, if it is one of them."""
    r = renderer.lower()
    if "2080 ti" in r:
        return "rtx2080ti"
    if "h100" in r:
        return "h100-pcie" if "pcie" in r and "hbm3" not in r else "h100-sxm"
    return None


def markdown() -> str:
    """The prediction tables for docs/GPU.md."""
    preds = predictions()
    devs = list(DEVICES)
    head = " | ".join(f"{DEVICES[d].name.split(' (')[0].replace('NVIDIA ', '')} ms (bound)"
                      for d in devs)
    lines = []
    for impulses in (12, 64):
        p = preds[(impulses, True)]
        facts = p["facts"]
        lines += [
            f"**{impulses} impulses per kernel**, {facts['frame']}, blur-rate "
            f"{facts['blur_rate']}, gaze at the centre (max sigma {facts['max_sigma_px']} px, "
            f"{facts['stack_levels']} stack levels on pyramid levels up to "
            f"{facts['pyramid_top']}, {facts['blur_samples_per_px']} blurred samples per "
            f"pixel after the tile skipping; {facts['impulse_count']} impulses, "
            f"{facts['open_impulse_fraction'] * 100:.0f} % with an open band, "
            f"{facts['impulses_visited_per_px']} visited per pixel by NOISE):",
            "",
            f"| Entry (stage) | Dispatches | Invocations | Per invocation | MB moved | {head} |",
            "|---|---|---|---|---|" + "---|" * len(devs),
        ]
        for c in p["costs"]:
            cells = " | ".join(f"{p['devices'][d]['entries'][c.entry][0]:.3f} "
                               f"({p['devices'][d]['entries'][c.entry][1]})" for d in devs)
            lines.append(f"| {c.entry} ({c.stage}) | {c.dispatches} | {c.invocations:,} "
                         f"{INVOCATION_UNITS[c.entry]} | {c.per_invocation()} | "
                         f"{c.bytes / 1e6:.1f} | {cells} |")
        n_disp = sum(c.dispatches for c in p["costs"])
        fov = " | ".join(f"**{p['devices'][d]['total_ms']:.2f}**" for d in devs)
        q = preds[(impulses, False)]
        nofov = " | ".join(f"**{q['devices'][d]['total_ms']:.2f}**" for d in devs)
        n_q = sum(c.dispatches for c in q["costs"])
        contrast = ("SAT_ROWS", "SAT_COLS", "CONTRAST_CHANGE")
        bare = " | ".join("**{:.2f}**".format(sum(
            v[0] for k, v in q["devices"][d]["entries"].items() if k not in contrast))
            for d in devs)
        n_bare = sum(c.dispatches for c in q["costs"] if c.entry not in contrast)
        lines += [
            f"| **frame with the foveation simulation** | {n_disp} | | | | {fov} |",
            f"| **frame already foveated** (the paper's setting) | {n_q} | | | | {nofov} |",
            f"| **the same without the contrast enhancement** | {n_bare} | | | | {bare} |",
            "",
        ]
    lines += [
        "The maps (`EnhanceResult.map`, `--dump-maps`), one MAPS dispatch each, 4K:",
        "",
        f"| Map | Per pixel | MB moved | {head} |",
        "|---|---|---|" + "---|" * len(devs),
    ]
    for c in map_costs():
        cells = " | ".join("{:.3f} ({})".format(*(lambda t: (t[0] * 1e3, t[1]))(
            c.seconds(DEVICES[d]))) for d in devs)
        lines.append(f"| {c.entry} | {c.per_invocation()} | {c.bytes / 1e6:.1f} | {cells} |")
    lines += ["", _paper_comparison(preds), "", "Peak figures assumed:", ""]
    for d in devs:
        dev = DEVICES[d]
        lines.append(f"- {dev.name}: {dev.bandwidth_gb_s:g} GB/s, {dev.fp32_tflops:g} TFLOPS "
                     f"FP32, {dev.fp64_tflops:.3g} TFLOPS FP64, {dev.sfu_tops:.2f} T SFU "
                     f"results/s. Source: {dev.source}.")
    return "\n".join(lines) + "\n"


#: The paper's measured times (section 6.3, RTX 2080 Ti, 4K, "the entire enhancement process"
#: from a foveated rendering), ms, by impulses per kernel
PAPER_MS = {12: 4.6, 64: 27.7}


def _paper_comparison(preds: dict) -> str:
    """The prediction for the paper's GPU and setting against the paper's measurement."""
    d = "rtx2080ti"
    contrast = ("SAT_ROWS", "SAT_COLS", "CONTRAST_CHANGE")

    def entry(impulses: int, simulate: bool, name: str) -> float:
        return preds[(impulses, simulate)]["devices"][d]["entries"][name][0]

    def total(impulses: int, simulate: bool, without=()) -> float:
        e = preds[(impulses, simulate)]["devices"][d]["entries"]
        return sum(v[0] for k, v in e.items() if k not in without)

    t12, t64 = total(12, False), total(64, False)
    b12, b64 = total(12, False, contrast), total(64, False, contrast)
    c = preds[(12, False)]["devices"][d]["entries"]["CONTRAST_CHANGE"]
    fov = total(12, True) - t12
    n_lv = preds[(12, True)]["facts"]["stack_levels"]
    return (
        f"Against the paper (section 6.3: {PAPER_MS[12]} ms for 12 impulses, {PAPER_MS[64]} ms "
        "for 64, \"the entire enhancement process\" from a foveated rendering on an RTX 2080 "
        f"Ti): the prediction for the same frame on the same GPU, already foveated, is "
        f"{t12:.2f} ms and {t64:.2f} ms ({b12:.2f} ms and {b64:.2f} ms without the contrast "
        f"enhancement, if the paper's timing left it out). For 12 impulses that is "
        f"{t12 / PAPER_MS[12] * 100:.0f} % of the paper's measurement, as a lower bound should "
        f"be; for 64, {t64 / PAPER_MS[64] * 100:.0f} %: here the noise synthesis is "
        f"compute-bound and grows from {entry(12, False, 'NOISE'):.2f} ms to "
        f"{entry(64, False, 'NOISE'):.2f} ms with the impulses, while the paper's frame grew by "
        f"{PAPER_MS[64] - PAPER_MS[12]:.1f} ms, so its synthesis ran far from this bound (its "
        f"implementation: GLSL fragment shaders, section 4.5; how they visit the impulses is not "
        f"described). The float64 contrast change is the "
        f"largest entry on the 2080 Ti ({c[0]:.2f} ms, {c[1]}-bound: its FP64 rate is 1/32 of "
        f"FP32); on an H100 it is memory-bound. The foveation simulation adds {fov:.2f} ms on "
        f"the 2080 Ti, memory-bound: STACK_ACCUMULATE reads and rewrites the image for each of "
        f"its {n_lv - 1} blurred levels where a tile needs it.")


def update_docs(path: Path = DOCS) -> bool:
    """Rewrite the tables between the roofline markers of docs/GPU.md; whether they changed."""
    text = path.read_text()
    pattern = re.compile(re.escape(BEGIN) + r".*?" + re.escape(END), re.S)
    if not pattern.search(text):
        raise SystemExit(f"{path} has no {BEGIN} ... {END} section")
    new = pattern.sub(lambda _: f"{BEGIN}\n{markdown()}{END}", text)
    path.write_text(new)
    return new != text


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--update-docs", action="store_true",
                    help=f"rewrite the tables in {DOCS.relative_to(HERE.parent)}")
    args = ap.parse_args()
    if args.update_docs:
        print("updated" if update_docs() else "unchanged", DOCS)
    else:
        sys.stdout.write(markdown())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
