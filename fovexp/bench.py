"""``fovexp bench``: the engine's run time against its error (issue 10, section 1).

Every knob of :class:`~fovexp.params.EngineOptions` (and the impulse count, and the backend) is
run on one frame and compared with a stated converged **reference**: 256 impulses per kernel,
``float64``, the exact per-pixel foveation, the preset's clipping rule (:data:`REFERENCE_OPTIONS`;
256 is inside the public impulse range, 1..512; the kernel keeps its 0.01 cut, see there).

What is measured, per configuration, each in its own process (spawned, so that its peak
resident memory is its own and Numba's allocations, which tracemalloc does not see, count):

- time: the wall-clock seconds of :meth:`Enhancer.enhance` on a full frame whose foveation is
  simulated (a new image and a moved gaze every frame, the impulses kept: what a renderer
  pays per frame), median of ``repeats`` frames after a warm-up on a frame an eighth the size
  (Numba's cache loaded, the GPU's shaders compiled); fewer frames when they pass the time
  budget; per stage too (``timings_s``; on the GPU each stage's GL timer-query time,
  ``GpuEnhancer(profile="gpu")``, with the device's GL_RENDERER);
- peak memory: the process's peak resident set (Linux's VmHWM, which counts Numba's and
  NumPy's allocations alike; ``getrusage`` ``ru_maxrss`` elsewhere) over the warm-up and the
  timed frames, and its peak before the frame was loaded (the interpreter, NumPy, Numba);
- the output's RMSE in 8-bit display codes (the display-encoded output times 255, before
  rounding) against the reference (``rmse_ref_8bit``), and against the reference's options at
  the configuration's own impulse count (``rmse_paired_8bit``: the same random field, so it is
  the error of the fast path itself: meaningful for the foveation, the dtype, the truncation and
  the backend, and for the clipping rules how far each moves the output; blank for the noise
  variants, whose field differs), and of the foveated image alone (``rmse_foveated_8bit``).
  Against the reference, the output's RMSE is dominated by the noise: two impulse counts are
  two different random fields;
- the noise's statistics, the meaningful accuracy of the noise knobs, per eccentricity ring
  (:data:`RINGS_DEG`), from the ``noise``, ``amplitude``, ``f_low_cpp``, ``f_high_cpp`` and
  ``eccentricity_deg`` maps, on 64 px tiles where the noise is on throughout: the fraction of
  its power inside the band [F_L, F_H] (section 4.1), its std over K (the release's
  normalisation makes it 1/6: section 4.4), and its excess kurtosis (0 for Gaussian noise;
  few impulses give sparse, heavy-tailed noise).

And the time against resolution (``resolution`` knob: 1080p, 1440p, 4K, 8K), as seconds per
megapixel (the cost should be linear in pixels) with the peak memory.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import math
import os
import platform
import shlex
import sys
import tempfile
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from .errors import FovexpError

#: The converged configuration every error is measured against (docs/API.md, "Engine options").
REFERENCE_IMPULSES = 256
#: The kernel keeps the method's 0.01 cut (docs/METHOD.md, 4): ``kernel_truncation`` also sets
#: the reach of the widened and exact clipping rules (N_min, N_max over the pixels the kernel
#: reaches, section 4.2), so another cut is another headroom neighbourhood, not a more
#: converged kernel. The clipping rule is the preset's: each rule is its own method
#: (benchmarks/CLIPPING.md), not an approximation of another; the ``clipping`` knobs measure
#: how far each moves the output.
REFERENCE_OPTIONS: dict[str, Any] = {"foveation": "exact", "dtype": "float64"}
#: Eccentricity rings of the noise statistics, deg (the paper preset's fovea ends at 8 deg).
RINGS_DEG: tuple[tuple[float, float], ...] = ((8.0, 15.0), (15.0, 25.0), (25.0, 35.0),
                                              (35.0, math.inf))
TILE_PX = 64  # side of the tiles the statistics are taken on (band: 1/64 cycles/px resolution)
#: A tile counts when the noise is on (K > 0) at this fraction of its pixels at least.
TILE_ON_FRACTION = 0.9
DEFAULT_RESOLUTION = (3840, 2160)
QUICK_RESOLUTION = (480, 270)
SWEEP = ((1920, 1080), (2560, 1440), (3840, 2160), (7680, 4320))
QUICK_SWEEP = ((240, 135), (480, 270), (960, 540))
#: Knob groups, in the order they run. ``resolution`` is the time-against-size sweep.
KNOB_GROUPS = ("impulses", "foveation", "clipping", "dtype", "truncation", "noise", "backend",
               "resolution")
IMPULSE_COUNTS = (1, 2, 4, 8, 12, 16, 32, 64)
TRUNCATIONS = (0.1, 0.001, 1e-4)
#: Where the shared 4K Sponza render is looked for (the project's sibling ``shared/`` folder),
#: relative to the current folder and to a source checkout; else a generated scene is used.
SPONZA_CANDIDATES = (Path("../shared/stimuli/sponza-4k.jpg"),
                     Path(__file__).resolve().parents[2] / "shared/stimuli/sponza-4k.jpg")


# ------------------------------------------------------------------------------- statistics
def excess_kurtosis(x: np.ndarray) -> float:
    """Fisher's excess kurtosis E[(x - mu)^4] / sigma^4 - 3 (0 for a Gaussian, -2 for +-1
    values, 3 for a Laplacian); NaN for fewer than 4 values or a constant."""
    from scipy.stats import kurtosis

    x = np.asarray(x, np.float64).ravel()
    if x.size < 4 or not np.any(x != x[0]):
        return float("nan")
    return float(kurtosis(x, fisher=True, bias=True))


def _radial_cpp(n: int) -> np.ndarray:
    f = np.fft.fftfreq(n)
    return np.hypot(f[:, None], f[None, :])


def band_power_fraction(tiles: np.ndarray, f_low_cpp: np.ndarray | float,
                        f_high_cpp: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
    """Power of each square tile inside its band [f_low, f_high] (cycles/px, radial) and its
    total power, DC left out. ``tiles``: (N, T, T) or (T, T); a Hann window keeps the tiles'
    edges from leaking power across the spectrum. Returns (inside, total), each (N,)."""
    tiles = np.asarray(tiles, np.float64)
    if tiles.ndim == 2:
        tiles = tiles[None]
    n = tiles.shape[-1]
    if tiles.shape[-2] != n:
        raise ValueError("band_power_fraction takes square tiles")
    w = np.hanning(n)
    win = w[:, None] * w[None, :]
    x = tiles - tiles.mean(axis=(-2, -1), keepdims=True)
    power = np.abs(np.fft.fft2(x * win)) ** 2
    power[:, 0, 0] = 0.0
    fr = _radial_cpp(n)[None]
    lo = np.broadcast_to(np.asarray(f_low_cpp, np.float64), (len(tiles),))[:, None, None]
    hi = np.broadcast_to(np.asarray(f_high_cpp, np.float64), (len(tiles),))[:, None, None]
    inside = ((fr >= lo) & (fr <= hi) & np.isfinite(lo)).astype(np.float64)
    return (power * inside).sum(axis=(1, 2)), power.sum(axis=(1, 2))


def _tiles(a: np.ndarray, t: int) -> np.ndarray:
    """(H, W) -> (H//t * W//t, t, t), the image cropped to whole tiles."""
    h, w = (a.shape[0] // t) * t, (a.shape[1] // t) * t
    return (a[:h, :w].reshape(h // t, t, w // t, t).swapaxes(1, 2).reshape(-1, t, t))


def ring_label(ring: tuple[float, float]) -> str:
    lo, hi = ring
    return f"{lo:g}+deg" if math.isinf(hi) else f"{lo:g}-{hi:g}deg"


def noise_statistics(noise: np.ndarray, amplitude: np.ndarray, f_low_cpp: np.ndarray,
                     f_high_cpp: np.ndarray, eccentricity_deg: np.ndarray,
                     rings: Sequence[tuple[float, float]] = RINGS_DEG,
                     tile_px: int = TILE_PX) -> dict[str, dict[str, float]]:
    """The noise's statistics per eccentricity ring and over all of them (key ``"all"``), on
    ``tile_px`` tiles where the noise is on (K > 0) at :data:`TILE_ON_FRACTION` of the pixels
    at least, a tile in the ring of its mean eccentricity:

    ``band_frac``: the fraction of the noise's power inside the band [F_L, F_H] (the tile's
    median band, section 4.1); ``std_over_k``: rms(noise) / rms(K) (the normalisation of
    section 4.4 makes it 1/6); ``excess_kurtosis``: of the noise divided by its tile's rms
    (so that the slow change of K over the frame does not count as a heavy tail); ``tiles``:
    how many tiles. NaN where a ring has no such tile."""
    t = tile_px
    n_t = _tiles(np.asarray(noise, np.float64), t)
    k_t = _tiles(np.asarray(amplitude, np.float64), t)
    on = (k_t > 0).mean(axis=(1, 2)) >= TILE_ON_FRACTION
    rms_n = np.sqrt((n_t**2).mean(axis=(1, 2)))
    on &= rms_n > 0
    ecc = _tiles(np.asarray(eccentricity_deg, np.float64), t).mean(axis=(1, 2))
    idx = np.flatnonzero(on)
    labels = [ring_label(r) for r in rings]
    nan = {"band_frac": float("nan"), "std_over_k": float("nan"),
           "excess_kurtosis": float("nan"), "tiles": 0}
    if not idx.size:  # no tile with the noise on throughout (a tiny frame)
        return {label: dict(nan) for label in [*labels, "all"]}
    lo = np.median(_tiles(np.asarray(f_low_cpp, np.float64), t)[idx], axis=(1, 2))
    hi = np.median(_tiles(np.asarray(f_high_cpp, np.float64), t)[idx], axis=(1, 2))
    inside, total = band_power_fraction(n_t[idx], lo, hi)
    sq_n = (n_t[idx] ** 2).sum(axis=(1, 2))
    sq_k = (k_t[idx] ** 2).sum(axis=(1, 2))
    z = n_t[idx] / rms_n[idx][:, None, None]
    out: dict[str, dict[str, float]] = {}
    groups = [(lab, (ecc[idx] >= r[0]) & (ecc[idx] < r[1])) for lab, r in zip(labels, rings,
                                                                             strict=True)]
    groups.append(("all", np.ones(idx.size, bool)))
    for label, sel in groups:
        if not sel.any():
            out[label] = dict(nan)
            continue
        out[label] = {
            "band_frac": float(inside[sel].sum() / total[sel].sum()),
            "std_over_k": float(math.sqrt(sq_n[sel].sum() / sq_k[sel].sum())),
            "excess_kurtosis": excess_kurtosis(z[sel]),
            "tiles": int(sel.sum()),
        }
    return out


def rmse_8bit(a: np.ndarray, b: np.ndarray) -> float:
    """RMSE of two display-encoded images in 8-bit codes (values times 255, not rounded)."""
    d = np.asarray(a, np.float64) - np.asarray(b, np.float64)
    return float(255.0 * math.sqrt(float(np.mean(d * d))))


def pareto_front(times: Sequence[float], errors: Sequence[float]) -> list[int]:
    """Indices of the points no other point beats in both time and error (lower is better),
    by increasing time; NaNs are left out."""
    pts = [(t, e, i) for i, (t, e) in enumerate(zip(times, errors, strict=True))
           if math.isfinite(t) and math.isfinite(e)]
    front, best = [], math.inf
    for _, e, i in sorted(pts):
        if e < best:
            front.append(i)
            best = e
    return front


# ---------------------------------------------------------------------------- configurations
@dataclass(frozen=True)
class Config:
    """One thing to measure: an impulse count, engine options and a backend at a size."""

    name: str
    knob: str  #: the knob group it belongs to (KNOB_GROUPS, or "reference")
    impulses: int
    options: tuple[tuple[str, Any], ...] = ()  #: non-default EngineOptions
    backend: str = "cpu"
    size: tuple[int, int] = DEFAULT_RESOLUTION  #: (width, height)
    errors: bool = True  #: compare with the reference (False: the resolution sweep)

    @property
    def options_dict(self) -> dict[str, Any]:
        return dict(self.options)

    @property
    def same_field(self) -> bool:
        """Whether its noise is the reference options' random field at the same impulse
        count (the impulse draw is left at its default)."""
        o = self.options_dict
        return all(k not in o for k in ("impulse_count", "weights", "cell_scale"))


def configs_for(knobs: Iterable[str], base_impulses: int, backend: str,
                size: tuple[int, int], sweep: Sequence[tuple[int, int]]) -> list[Config]:
    """The configurations of the knob groups (or single ``group=value`` items) asked for."""
    other = "cpu" if backend == "gpu" else "gpu"
    cpu_only = "cpu"  # the GPU backend implements only the default options (docs/API.md)
    groups: dict[str, list[Config]] = {
        "impulses": [Config(f"impulses={n}", "impulses", n, backend=backend, size=size)
                     for n in IMPULSE_COUNTS],
        "foveation": [Config("foveation=exact", "foveation", base_impulses,
                             (("foveation", "exact"),), cpu_only, size)],
        "clipping": [Config(f"clipping={rule}", "clipping", base_impulses,
                            (("clipping", rule),), cpu_only, size)
                     for rule in ("paper", "widened", "release", "exact", "off")],
        "dtype": [Config("dtype=float64", "dtype", base_impulses, (("dtype", "float64"),),
                         cpu_only, size)],
        "truncation": [Config(f"truncation={v:g}", "truncation", base_impulses,
                              (("kernel_truncation", v),), cpu_only, size)
                       for v in TRUNCATIONS],
        "noise": [
            Config("impulse_count=jittered", "noise", base_impulses,
                   (("impulse_count", "jittered"),), cpu_only, size),
            Config("weights=sign", "noise", base_impulses, (("weights", "sign"),), cpu_only,
                   size),
            Config("cell_scale=0.5", "noise", base_impulses, (("cell_scale", 0.5),), cpu_only,
                   size),
        ],
        "backend": [Config(f"backend={other}", "backend", base_impulses, backend=other,
                           size=size)],
        "resolution": [Config(f"resolution={w}x{h}", "resolution", base_impulses,
                              backend=backend, size=(w, h), errors=False) for w, h in sweep],
    }
    base = Config(f"impulses={base_impulses}", "impulses", base_impulses, backend=backend,
                  size=size)
    out: list[Config] = [base]
    for knob in knobs:
        if knob in groups:
            out += groups[knob]
            continue
        hits = [c for g in groups.values() for c in g if c.name == knob]
        if not hits and knob.startswith("impulses="):  # any count in the public range
            n = int(knob.split("=", 1)[1])
            hits = [Config(knob, "impulses", n, backend=backend, size=size)]
        if not hits:
            names = ", ".join(KNOB_GROUPS)
            raise FovexpError(f"unknown knob {knob!r} (choose from the groups {names}, or one "
                              "of their items such as impulses=12, dtype=float64)")
        out += hits
    seen: set[tuple] = set()
    unique = []
    for c in out:
        key = (c.impulses, c.options, c.backend, c.size)
        if key not in seen:
            seen.add(key)
            unique.append(c)
    return unique


# ---------------------------------------------------------------------------------- machine
def machine() -> dict[str, Any]:
    """What the figures were measured on."""
    import numba
    import scipy

    cpu = machine_cpu()
    try:
        ram_gb = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 1e9
    except (ValueError, OSError, AttributeError):
        ram_gb = float("nan")
    return {
        "cpu": cpu, "cores": os.cpu_count(), "ram_gb": round(ram_gb, 1),
        "numba_threads": numba.config.NUMBA_NUM_THREADS,
        "python": platform.python_version(), "numpy": np.__version__,
        "scipy": scipy.__version__, "numba": numba.__version__,
        "os": platform.platform(),
        "date_utc": datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "load_average_start": _load(),
    }


def _load() -> str:
    try:
        return ", ".join(f"{v:.2f}" for v in os.getloadavg())
    except OSError:
        return "n/a"


# ------------------------------------------------------------------------------------ frame
def find_frame(image: Path | None) -> tuple[Path | None, str]:
    """The input frame: ``image``, else the shared Sponza render where it is, else None (a
    generated scene, drawn at each size)."""
    if image is not None:
        if not image.is_file():
            raise FovexpError(f"{image}: no such image")
        return image, str(image)
    for cand in SPONZA_CANDIDATES:
        if cand.is_file():
            return cand, f"{cand.name} (the shared Sponza render)"
    return None, "generated scene-00 (fovexp.stimuli.scenes), drawn natively at each size"


def frame_at(path: Path | None, size: tuple[int, int]) -> tuple[np.ndarray, str]:
    """The frame at ``size`` (width, height): the image scaled (area-averaged down, bilinear
    up; scikit-image) when it has another size, or the generated scene drawn at that size."""
    w, h = size
    if path is None:
        from .stimuli.scenes import render_scene

        return render_scene(0, w, h).astype(np.float32) / 255.0, "drawn at this size"
    from .io import read_image

    img = read_image(path)
    if img.shape[:2] == (h, w):
        return img, "as read"
    from skimage.transform import resize

    down = h < img.shape[0]
    out = resize(img, (h, w, *img.shape[2:]), order=1, anti_aliasing=down,
                 preserve_range=True)
    how = "scaled down (area-averaged)" if down else "scaled up (bilinear)"
    return np.clip(out, 0.0, 1.0).astype(np.float32), how


# ----------------------------------------------------------------------------------- worker
@dataclass
class Job:
    config: Config
    frame_npy: str
    ref_dir: str
    display: str
    blur_rate: float
    seed: int
    repeats: int
    budget_s: float
    #: the reference job: also write the reference options' outputs at these impulse counts
    paired_counts: tuple[int, ...] = ()
    extra: dict[str, Any] = field(default_factory=dict)


def _maxrss_mb() -> float:
    """Peak resident memory of this process, MB: Linux's VmHWM (the high-water mark of this
    process's own address space), else ``getrusage``'s ru_maxrss, which Linux carries over
    an exec from the forking parent (a spawned child would start at its parent's peak)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0
    except (OSError, ValueError, IndexError):
        pass
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux: KiB


def _make(cfg: Config, display: Any, profile: bool) -> Any:
    from .backends import make_enhancer
    from .params import make_options

    options = make_options(**cfg.options_dict)
    if cfg.backend == "gpu":
        from .gpu import GpuEnhancer

        return GpuEnhancer(display, options=options, profile="gpu" if profile else False)
    return make_enhancer(display, backend="cpu", options=options)


CENTRE = (0.5, 0.5)
MOVED = (0.501, 0.5)


def run_job(job: Job) -> dict[str, Any]:
    """Measure one configuration (in its own process: :func:`run_all` spawns one each)."""
    try:
        return _run_job(job)
    except FovexpError as exc:
        return {"skipped": str(exc)}


def _child(job: Job, conn: Any) -> None:
    """A spawned process's body: the result (or why it failed) back through ``conn``."""
    try:
        result = run_job(job)
    except Exception as exc:  # noqa: BLE001  a bug costs this configuration, not the run
        result = {"skipped": f"failed: {type(exc).__name__}: {exc}"}
    conn.send(result)
    conn.close()


def _in_process_of_its_own(ctx: Any, job: Job) -> dict[str, Any]:
    """:func:`run_job` in a fresh spawned process; the process is ended if this one is
    interrupted, and a process that dies (out of memory) is reported, not waited for."""
    recv, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(job, send), daemon=True)
    proc.start()
    send.close()
    try:
        return recv.recv()
    except EOFError:
        proc.join()
        return {"skipped": f"failed: its process ended with exit code {proc.exitcode}"}
    finally:
        if proc.is_alive():
            proc.terminate()
        proc.join()


def _run_job(job: Job) -> dict[str, Any]:
    from .geometry import load_display
    from .params import make_params

    rss_base = _maxrss_mb()
    cfg = job.config
    display = load_display(job.display)
    params = make_params(blur_rate=job.blur_rate, impulses=cfg.impulses, seed=job.seed)
    frame = np.load(job.frame_npy)
    small = np.ascontiguousarray(frame[::8, ::8])
    warm = _make(cfg, display, profile=False)  # Numba's cache loaded, shaders compiled
    warm.set_image(small)
    warm.enhance((0.5, 0.5), params)
    _close(warm)
    enh = _make(cfg, display, profile=True)
    device = _cpu_device()
    if cfg.backend == "gpu":
        from .gpu import is_software

        device = f"GPU: {enh.renderer}" + (" [software renderer: the CPU's cores, not a GPU]"
                                           if is_software(enh.ctx) else "")
    timing = getattr(enh, "timing_method", None) or "wall clock per stage (perf_counter)"
    times: list[float] = []
    stages: list[dict[str, float]] = []
    gaze = CENTRE
    for i in range(job.repeats):
        if i and sum(times) + times[-1] > job.budget_s:
            break  # the next frame would pass the budget
        gaze = MOVED if i % 2 else CENTRE  # a moved gaze every frame: every stage recomputes
        enh.set_image(frame.copy())  # a new array: a new frame to the stage cache
        t0 = time.perf_counter()
        res = enh.enhance(gaze, params)
        times.append(time.perf_counter() - t0)
        stages.append(dict(res.timings_s))
    peak = _maxrss_mb()
    names = list(dict.fromkeys(k for s in stages for k in s))
    out: dict[str, Any] = {
        "device": device, "timing": timing, "frames": len(times),
        "median_s": float(np.median(times)), "min_s": float(np.min(times)),
        "stages_s": {k: float(np.median([s.get(k, 0.0) for s in stages])) for k in names},
        "peak_rss_mb": peak, "base_rss_mb": rss_base,
    }
    if cfg.errors:
        if gaze != CENTRE:  # the errors at the reference's gaze (not timed)
            res = enh.enhance(CENTRE, params)
        out.update(_errors(job, res))
    if cfg.backend == "cpu" and cfg.size == DEFAULT_RESOLUTION:  # the roofline's noise taps
        out["noise_taps"] = noise_taps(enh, res, job.seed, cfg.impulses)
    if job.paired_counts:  # the reference: its options at the other impulse counts
        ref = Path(job.ref_dir)
        for n in job.paired_counts:
            r = enh.enhance(CENTRE, make_params(blur_rate=job.blur_rate, impulses=n,
                                                   seed=job.seed))
            np.save(ref / f"output-{n}.npy", r.output.astype(np.float32))
    _close(enh)
    return out


def _close(enh: Any) -> None:
    close = getattr(enh, "close", None)
    if close is not None:
        close()


def _cpu_device() -> str:
    import numba

    return f"CPU ({machine_cpu()}, {numba.config.NUMBA_NUM_THREADS} threads)"


def machine_cpu() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _errors(job: Job, res: Any) -> dict[str, Any]:
    """The noise's statistics; and, against the reference's files, the RMSEs (the reference
    job writes them: output at each impulse count, float32, and its foveated image)."""
    cfg = job.config
    stats = noise_statistics(res.map("noise"), res.map("amplitude"), res.map("f_low_cpp"),
                             res.map("f_high_cpp"), res.map("eccentricity_deg"))
    out: dict[str, Any] = {"noise_stats": stats}
    ref = Path(job.ref_dir)
    if cfg.knob == "reference":
        np.save(ref / f"output-{cfg.impulses}.npy", res.output.astype(np.float32))
        np.save(ref / "foveated.npy", res.map("foveated").astype(np.float32))
        out.update(rmse_ref_8bit=0.0, rmse_paired_8bit=0.0, rmse_foveated_8bit=0.0)
        return out
    output = res.output
    out["rmse_ref_8bit"] = rmse_8bit(output, np.load(ref / f"output-{REFERENCE_IMPULSES}.npy",
                                                     mmap_mode="r"))
    paired = ref / f"output-{cfg.impulses}.npy"
    out["rmse_paired_8bit"] = (rmse_8bit(output, np.load(paired, mmap_mode="r"))
                               if cfg.same_field and paired.is_file() else float("nan"))
    out["rmse_foveated_8bit"] = rmse_8bit(res.map("foveated"),
                                          np.load(ref / "foveated.npy", mmap_mode="r"))
    return out


# ----------------------------------------------------------------------------- CPU roofline
#: Issue 29's CPU roofline: per stage, the full-resolution float32 planes it must read and write
#: at the least (an RGB image is 3 planes), whatever its algorithm, as (read, written, what). A
#: stage's floor is those bytes at the machine's measured bandwidth; the noise's is also its
#: taps' arithmetic at the measured FP32 rate (:func:`noise_taps`). Stages left out work per
#: impulse or on grids of 1/64 of the frame and less.
CPU_TRAFFIC_PLANES: dict[str, tuple[float, float, str]] = {
    # set_image's pass, which also checks the values and, of an already-foveated RGB frame,
    # takes luma_and_blocks (its plane out is then under this stage's time, not its floor)
    "linear": (3, 3, "the frame in, linear light out"),
    "foveated": (3, 3, "linear light in, the foveated frame out"),
    "luma_and_blocks": (3, 1, "RGB in, luminance out (and its 8 x 8 block extremes)"),
    "pyramid": (4 / 3, 1 / 3, "each Gaussian level in, the next out"),
    "abs_laplacian": (5 / 3, 4 / 3, "G_k-1 and G_k in, |L_k| out (k >= 1)"),
    "contrast": (1, 1, "luminance in, its change out"),
    "headroom": (2, 0, "luminance and its change in (the paper's rule), block extremes out"),
    "noise": (0, 1, "the noise out; its taps' multiply-adds"),
    "output": (5, 3, "foveated RGB, the contrast change and the noise in, the frame out"),
}
#: float32 operations per noise tap: ``out += cr * er - ci * ei`` (two fused multiply-adds)
NOISE_FLOPS_PER_TAP = 4


def machine_rates(copy_mb: int = 400, gemm_n: int = 2048, repeats: int = 5) -> dict[str, float]:
    """The machine's memory bandwidth and FP32 rate, measured now (medians of ``repeats``):
    ``bandwidth_gb_s`` = bytes read plus written by a ``copy_mb`` MB ``np.copyto`` (one thread,
    as issue 29 measured it) per second; ``fp32_gflop_s`` = a float32 ``gemm_n``-square matrix
    product (BLAS, every core: 2 n^3 operations) per second; ``parallel_speedup`` = what every
    thread gains over one on arithmetic-bound compiled work
    (:func:`fovexp._parallel.parallel_speedup`: the thread count where each has a core of its
    own, less where they share vector units)."""
    import numba

    from ._parallel import parallel_speedup

    src = np.ones(copy_mb * 2**20 // 4, np.float32)
    dst = np.empty_like(src)
    np.copyto(dst, src)  # the pages touched before the timing
    copies = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        np.copyto(dst, src)
        copies.append(time.perf_counter() - t0)
    del src, dst
    rng = np.random.default_rng(0)
    a = rng.random((gemm_n, gemm_n), dtype=np.float32)
    b = rng.random((gemm_n, gemm_n), dtype=np.float32)
    a @ b
    gemms = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        a @ b
        gemms.append(time.perf_counter() - t0)
    return {"bandwidth_gb_s": 2 * copy_mb * 2**20 / float(np.median(copies)) / 1e9,
            "fp32_gflop_s": 2 * gemm_n**3 / float(np.median(gemms)) / 1e9,
            "copy_mb": copy_mb, "gemm_n": gemm_n,
            "parallel_speedup": parallel_speedup(repeats=repeats),
            "threads": numba.config.NUMBA_NUM_THREADS}


def parallel_sentence(rates: dict[str, float]) -> str:
    """The record's sentence on :func:`machine_rates`' ``parallel_speedup`` (empty for a
    record from before it was measured)."""
    if "parallel_speedup" not in rates:
        return ""
    return (f" Its {rates['threads']} threads together ran arithmetic-bound compiled work "
            f"{rates['parallel_speedup']:.2f}x as fast as one did "
            "(fovexp._parallel.parallel_speedup): the most the parallel kernels can gain "
            "from them.")


def noise_taps(enh: Any, res: Any, seed: int, impulses: int) -> int:
    """The noise stage's taps on a frame (``res``): every impulse whose K is not 0 adds its
    kernel's fixed-width rows (``gabor._window``) over its 2 ceil(r) + 1 rows."""
    from . import gabor

    h, w = res.output.shape[:2]
    o = enh.options
    imp = gabor.generate_impulses(w, h, impulses, enh.preset.gabor_a_cpp, seed,
                                  o.impulse_count, o.weights, o.cell_scale)
    k = res.map("amplitude")
    xi = np.clip(np.rint(imp.x_px).astype(np.int64), 0, w - 1)
    yi = np.clip(np.rint(imp.y_px).astype(np.int64), 0, h - 1)
    active = int(np.count_nonzero(k[yi, xi] > 0))
    r = gabor.kernel_radius_px(enh.preset.gabor_a_cpp, o.kernel_truncation)
    return active * gabor._window(r)[0] * (2 * math.ceil(r) + 1)


def roofline_rows(row: dict[str, Any], rates: dict[str, float]) -> list[list[str]]:
    """Per stage of ``row`` (a CPU configuration): its median time, the bytes it must move,
    its floor (those bytes at the measured bandwidth; for the noise also its taps at the FP32
    rate) and the time as a multiple of the floor."""
    w, h = (int(v) for v in row["resolution"].split("x"))
    plane = w * h * 4
    stages = dict((k, float(v)) for k, v in (x.split("=") for x in row["stages_s"].split(";")
                                              if x))
    out = []
    for name, (read, written, what) in CPU_TRAFFIC_PLANES.items():
        if name not in stages:
            continue
        t = stages[name]
        moved = (read + written) * plane
        floor = moved / (rates["bandwidth_gb_s"] * 1e9)
        arith = ""
        if name == "noise" and row.get("noise_taps"):
            flops = NOISE_FLOPS_PER_TAP * float(row["noise_taps"])
            arith = f"{flops / 1e9:.2f} GFLOP"
            floor = max(floor, flops / (rates["fp32_gflop_s"] * 1e9))
        out.append([name, what, f"{1e3 * t:.1f}", f"{moved / 1e6:.0f}", arith,
                    f"{1e3 * floor:.1f}", f"{t / floor:.1f}x" if floor > 0 else "-"])
    return out


# ------------------------------------------------------------------------------------- run
@dataclass
class BenchSettings:
    out: Path
    image: Path | None = None
    size: tuple[int, int] = DEFAULT_RESOLUTION
    sweep: tuple[tuple[int, int], ...] = SWEEP
    knobs: tuple[str, ...] = KNOB_GROUPS
    repeats: int = 3
    budget_s: float = 30.0
    base_impulses: int = 64
    backend: str = "cpu"
    display: str = "lg-oled55cx"
    blur_rate: float = 0.34
    seed: int = 1
    command: str = ""
    progress: bool = True


def run_all(s: BenchSettings, on_row: Callable[[list[dict[str, Any]]], None] | None = None,
            ) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """Run the reference and every configuration, each in a fresh spawned process, one at a
    time (so that each has the machine's cores to itself). Returns the rows and the run's
    description (machine, frame, settings); ``on_row(rows)`` is called after each. An
    interrupt (Ctrl-C, SIGINT) ends the running configuration's process and the run, keeping
    what it measured (``info["interrupted"]`` says so)."""
    import multiprocessing as mp

    from .progress import progress_bar

    if s.repeats < 1 or s.budget_s <= 0:
        raise FovexpError("--repeats must be >= 1 and --budget-s > 0")
    path, source = find_frame(s.image)
    configs = configs_for(s.knobs, s.base_impulses, s.backend, s.size, s.sweep)
    needs_ref = any(c.errors for c in configs)
    reference = Config("reference", "reference", REFERENCE_IMPULSES,
                       tuple(REFERENCE_OPTIONS.items()), "cpu", s.size)
    paired = tuple(sorted({c.impulses for c in configs if c.errors and c.same_field}
                          - {REFERENCE_IMPULSES}))
    info: dict[str, Any] = {"machine": machine(), "frame": source, "command": s.command,
                            "settings": {k: (str(v) if isinstance(v, Path) else v)
                                         for k, v in asdict(s).items()},
                            "reference": {"impulses": REFERENCE_IMPULSES,
                                          "options": REFERENCE_OPTIONS}}
    rows: list[dict[str, Any]] = []
    ctx = mp.get_context("spawn")
    started = time.perf_counter()
    info["rates"] = machine_rates()  # the roofline's bandwidth and FP32 rate, in this run
    with tempfile.TemporaryDirectory(prefix="fovexp-bench-") as tmp:
        frames: dict[tuple[int, int], str] = {}
        scaled: dict[str, str] = {}
        todo = ([reference] if needs_ref else []) + configs
        bar = progress_bar(todo, desc="fovexp bench", unit="config",
                           stream=sys.stderr if s.progress else io.StringIO())
        info["configurations"] = len(todo)
        try:
            for cfg in bar:
                bar.set_postfix_str(cfg.name)
                if cfg.size not in frames:
                    img, how = frame_at(path, cfg.size)
                    frames[cfg.size] = str(Path(tmp) / f"frame-{cfg.size[0]}x{cfg.size[1]}.npy")
                    np.save(frames[cfg.size], img)
                    scaled[f"{cfg.size[0]}x{cfg.size[1]}"] = how
                    del img
                ref = cfg.knob == "reference"
                job = Job(cfg, frames[cfg.size], tmp, s.display, s.blur_rate, s.seed,
                          1 if ref else s.repeats, s.budget_s, paired if ref else ())
                rows.append(_row(cfg, _in_process_of_its_own(ctx, job)))
                if on_row is not None:
                    on_row(rows)
        except KeyboardInterrupt:
            info["interrupted"] = (f"interrupted after {len(rows)} of {len(todo)} "
                                   "configurations")
        bar.close()
    info["frame_sizes"] = scaled
    info["total_s"] = time.perf_counter() - started
    info["machine"]["load_average_end"] = _load()
    return rows, info


def _row(cfg: Config, r: dict[str, Any]) -> dict[str, Any]:
    w, h = cfg.size
    mpx = w * h / 1e6
    opts = ", ".join(f"{k}={v}" for k, v in cfg.options) or "defaults"
    row: dict[str, Any] = {
        "config": cfg.name, "knob": cfg.knob, "backend": cfg.backend,
        "device": r.get("device", ""), "resolution": f"{w}x{h}", "megapixels": round(mpx, 3),
        "impulses": cfg.impulses, "options": opts, "frames": r.get("frames", 0),
        "median_s": r.get("median_s", float("nan")), "min_s": r.get("min_s", float("nan")),
        "s_per_mpx": r.get("median_s", float("nan")) / mpx,
        "peak_rss_mb": r.get("peak_rss_mb", float("nan")),
        "base_rss_mb": r.get("base_rss_mb", float("nan")),
        "rmse_ref_8bit": r.get("rmse_ref_8bit", float("nan")),
        "rmse_paired_8bit": r.get("rmse_paired_8bit", float("nan")),
        "rmse_foveated_8bit": r.get("rmse_foveated_8bit", float("nan")),
    }
    stats = r.get("noise_stats", {})
    for label in ["all", *(ring_label(x) for x in RINGS_DEG)]:
        st = stats.get(label, {})
        sfx = "" if label == "all" else f"_{label}"
        for key in ("band_frac", "std_over_k", "excess_kurtosis"):
            row[f"{key}{sfx}"] = st.get(key, float("nan"))
    row["timing"] = r.get("timing", "")
    row["stages_s"] = ";".join(f"{k}={v:.4f}" for k, v in
                               sorted(r.get("stages_s", {}).items(), key=lambda kv: -kv[1]))
    row["noise_taps"] = r.get("noise_taps", float("nan"))
    row["skipped"] = r.get("skipped", "")
    return row


def columns() -> list[str]:
    """The CSV's columns, in order."""
    return list(_row(Config("x", "x", 1), {}).keys())


# ---------------------------------------------------------------------------------- writing
def _fmt(v: Any, digits: int = 3) -> str:
    if isinstance(v, float):
        if not math.isfinite(v):
            return "-"
        return f"{v:.{digits}g}" if abs(v) < 1e4 else f"{v:.0f}"
    return str(v)


def write_csv(rows: list[dict[str, Any]], path: Path) -> None:
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=columns())
        w.writeheader()
        for r in rows:
            w.writerow({k: (repr(v) if isinstance(v, float) else v) for k, v in r.items()})


MAIN_COLUMNS = (("config", "config"), ("device", "device"), ("frames", "frames"),
                ("median_s", "median s"), ("min_s", "min s"), ("s_per_mpx", "s/Mpx"),
                ("peak_rss_mb", "peak RSS MB"), ("rmse_paired_8bit", "RMSE paired"),
                ("rmse_ref_8bit", "RMSE vs ref"), ("rmse_foveated_8bit", "RMSE foveated"),
                ("band_frac", "band frac"), ("std_over_k", "std/K"),
                ("excess_kurtosis", "ex. kurtosis"))


def table_text(rows: list[dict[str, Any]]) -> str:
    """The main table as aligned text (what the command prints)."""
    head = [h for _, h in MAIN_COLUMNS]
    body = [[_fmt(r[k]) if not r["skipped"] or k == "config" else
             ("skipped" if k == "device" else "") for k, _ in MAIN_COLUMNS] for r in rows]
    body = [[c if len(c) <= 40 else c[:37] + "..." for c in line] for line in body]
    widths = [max(len(x) for x in col) for col in zip(head, *body, strict=True)]
    lines = ["  ".join(c.ljust(w) for c, w in zip(line, widths, strict=True))
             for line in [head, *body]]
    return "\n".join(lines)


def _md_table(head: Sequence[str], lines: Iterable[Sequence[str]]) -> str:
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    out += ["| " + " | ".join(line) + " |" for line in lines]
    return "\n".join(out)


def _load_warning(m: dict[str, Any]) -> str:
    """A sentence when other work shared the machine (load average above its cores)."""
    try:
        loads = [float(m[k].split(",")[0]) for k in ("load_average_start", "load_average_end")
                 if k in m]
    except (ValueError, AttributeError):
        return ""
    if loads and max(loads) > (m.get("cores") or 1):
        return (" **The machine was shared and loaded** (load average above its "
                f"{m.get('cores')} cores): the times are slower and noisier than on a quiet "
                "machine (compare configurations only roughly; re-run it quiet). The errors "
                "and the noise statistics do not depend on the load.")
    return ""


def write_markdown(rows: list[dict[str, Any]], info: dict[str, Any], path: Path,
                   plots: Sequence[str]) -> None:
    m = info["machine"]
    ref = info["reference"]
    s = info["settings"]
    ok = [r for r in rows if not r["skipped"]]
    errs = [r for r in ok if r["knob"] != "resolution"]
    sweep = sweep_rows(ok)
    parts = [
        "# fovexp bench: run time against error",
        "",
        f"Machine: {m['cpu']}, {m['cores']} cores, {m['ram_gb']} GB RAM; Python {m['python']}, "
        f"NumPy {m['numpy']}, SciPy {m['scipy']}, Numba {m['numba']} "
        f"({m['numba_threads']} threads); {m['os']}. Date: {m['date_utc']}. Load average "
        f"(1, 5, 15 min) at the start: {m['load_average_start']}; at the end: "
        f"{m.get('load_average_end', 'n/a')}." + _load_warning(m),
        "",
        f"Command: `{info['command']}` (total {info.get('total_s', float('nan')):.0f} s"
        + (f"; **{info['interrupted']}**" if info.get("interrupted") else "") + ").",
        "",
        f"Frame: {info['frame']}; sizes: "
        + ", ".join(f"{k} {v}" for k, v in info.get("frame_sizes", {}).items())
        + f". Display profile {s['display']}, blur-rate {s['blur_rate']} arcmin/deg, gaze at "
        f"the centre, seed {s['seed']}, method ours (paper preset).",
        "",
        f"Reference: {ref['impulses']} impulses per kernel, "
        + ", ".join(f"{k}={v}" for k, v in ref["options"].items())
        + "; 256 is inside the public impulse range 1..512. The clipping rule is the "
        "preset's (each rule is a method of its own, benchmarks/CLIPPING.md). The kernel keeps "
        "the method's 0.01 cut: under the widened and exact clipping rules `kernel_truncation` "
        "also sets the reach of the extremes (N_min, N_max over the pixels the kernel reaches, "
        "section 4.2; the widened rule's reach is 2 ceil(r / 8) + 1 level-3 blocks), so "
        "another cut changes the headroom neighbourhood as well as the kernel's tail.",
        "",
        "How measured: each configuration in its own spawned process; time = wall clock of "
        "`Enhancer.enhance` on a frame whose foveation is simulated (new image, moved gaze, "
        f"impulses kept), median of up to {s['repeats']} frames after a warm-up on a frame an "
        f"eighth the size, fewer once {s['budget_s']:g} s were spent (column frames). Peak "
        "RSS = the process's peak resident set (Linux VmHWM, /proc/self/status) over the "
        "warm-up and the timed frames (Numba's allocations included, which tracemalloc "
        "does not see; the process holds "
        + (f"{np.median([r['base_rss_mb'] for r in ok]):.0f} MB" if ok else "-")
        + " before the frame is loaded). On the GPU, the stage times are GL timer-query "
        "times where the driver's query works (column timing in bench.csv), and the device "
        "is the GL_RENDERER; a software renderer such as llvmpipe runs the shaders on the "
        "CPU's cores: not a GPU figure.",
        "",
        "Errors: *RMSE* in 8-bit display codes (display-encoded output x 255, not rounded). "
        "*paired*: against the reference's options at the configuration's own impulse count "
        "(the same random field: the error of the fast path itself; blank for the noise "
        "variants, whose field differs). *vs ref*: against the reference itself; dominated "
        "by the noise, since two impulse counts are two random fields: it is not an accuracy "
        "measure for the noise knobs. *foveated*: the foveated image alone. The noise "
        f"statistics (on {TILE_PX} px tiles where the noise is on) are the accuracy measure of "
        "the noise knobs: *band frac* = the fraction of the noise's power inside [F_L, F_H]; "
        "*std/K* = rms(noise) / rms(K) (1/6 = 0.167 by the normalisation); *ex. kurtosis* = "
        "excess kurtosis of the noise over its tile's rms (0: Gaussian; sparse noise from "
        "few impulses is heavy-tailed).",
        "",
        "## Run time against error",
        "",
        _md_table([h for _, h in MAIN_COLUMNS],
                  ([_fmt(r[k]) for k, _ in MAIN_COLUMNS] for r in errs)),
        "",
    ]
    skipped = [r for r in rows if r["skipped"]]
    if skipped:
        parts += ["Not measured: " + "; ".join(f"{r['config']}: {r['skipped']}"
                                               for r in skipped) + ".", ""]
    ring_labels = [ring_label(x) for x in RINGS_DEG]
    if errs:
        parts += ["## Noise statistics per eccentricity ring", "",
                  "band frac / std/K / excess kurtosis, per ring.", "",
                  _md_table(["config", *ring_labels],
                            ([r["config"]] + [" / ".join(_fmt(r[f"{k}_{lab}"], 3) for k in
                                                         ("band_frac", "std_over_k",
                                                          "excess_kurtosis"))
                                              for lab in ring_labels] for r in errs)),
                  ""]
        front = pareto_front([r["median_s"] for r in errs],
                             [r["rmse_paired_8bit"] for r in errs])
        if front:
            parts += ["Pareto front (time against paired RMSE): "
                      + ", ".join(errs[i]["config"] for i in front) + ".", ""]
    if sweep:
        parts += ["## Time against resolution", "",
                  _md_table(["resolution", "device", "Mpx", "frames", "median s", "s/Mpx",
                             "peak RSS MB"],
                            ([r["resolution"], r["device"], _fmt(r["megapixels"]),
                              _fmt(r["frames"]), _fmt(r["median_s"]), _fmt(r["s_per_mpx"]),
                              _fmt(r["peak_rss_mb"])] for r in sweep)),
                  ""]
    base = f"impulses={s['base_impulses']}"
    staged = [r for r in ok if r["knob"] != "resolution" and (
        r["backend"] == "gpu" or r["config"] in (base, "reference"))]
    if staged:
        parts += ["## Stage times (median s per frame)", ""]
        parts += [f"- {r['config']} ({r['device']}; {r['timing']}): "
                  + ", ".join(x.replace("=", " ") for x in r["stages_s"].split(";")[:10])
                  for r in staged]
        parts += [""]
    rates = info.get("rates")
    roof = [r for r in ok if r["backend"] == "cpu" and r["knob"] != "resolution"
            and r["config"] in (base, "impulses=12") and r["resolution"] == "x".join(
                str(v) for v in DEFAULT_RESOLUTION)]
    if rates and roof:
        parts += [
            "## CPU roofline (issue 29)", "",
            f"Measured in this run: memory bandwidth {rates['bandwidth_gb_s']:.1f} GB/s (bytes "
            f"read plus written by a {rates['copy_mb']} MB `np.copyto`, one thread, median of "
            f"5), FP32 rate {rates['fp32_gflop_s']:.0f} GFLOP/s (a {rates['gemm_n']}-square "
            "float32 matrix product, BLAS on every core). A stage's floor is the bytes it "
            "must move at that bandwidth (the full-resolution float32 planes it reads and "
            "writes at the least, `CPU_TRAFFIC_PLANES` in fovexp/bench.py); the noise's is "
            "the larger of that and its taps' multiply-adds at the FP32 rate (every impulse "
            "with K > 0, its kernel's fixed-width rows). *x floor* = the stage's median time "
            "over its floor: how far it is from what no implementation can beat on this "
            "machine. Stages left out work per impulse or on small grids. Not modelled: the "
            "transfer function's power per value in `linear` and `output` (a transcendental, "
            "not a memory access), and the foveation's blur stack beyond one pass."
            + parallel_sentence(rates), ""]
        for r in roof:
            parts += [f"{r['config']} ({r['device']}; median {r['median_s']:.3f} s per frame, "
                      "foveation simulated):", "",
                      _md_table(["stage", "the least it moves", "ms", "MB", "arithmetic",
                                 "floor ms", "x floor"], roofline_rows(r, rates)), ""]
    parts += [f"![{p}]({p})" for p in plots] + [""]
    parts += ["Written by `fovexp bench` (fovexp/bench.py); the rows are in bench.csv, the "
              "run's description in bench.json.", ""]
    path.write_text("\n".join(parts))


def sweep_rows(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The resolution knob's rows with the base configuration's at its own size (the same
    configuration: it is measured once), by size."""
    sweep = [r for r in rows if r["knob"] == "resolution" and not r["skipped"]]
    if not sweep:
        return []
    like = (sweep[0]["impulses"], sweep[0]["backend"], "defaults")
    sizes = {r["resolution"] for r in sweep}
    same = [r for r in rows if r["knob"] == "impulses" and not r["skipped"]
            and (r["impulses"], r["backend"], r["options"]) == like
            and r["resolution"] not in sizes]
    return sorted(sweep + same, key=lambda r: r["megapixels"])


def write_plots(rows: list[dict[str, Any]], out: Path) -> list[str]:
    """Pareto plots (time against error) and the time per megapixel against resolution."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ok = [r for r in rows if not r["skipped"]]
    errs = [r for r in ok if r["knob"] != "resolution"]
    written: list[str] = []
    colours = {k: f"C{i}" for i, k in enumerate(("reference", *KNOB_GROUPS))}
    if errs:
        fig, axes = plt.subplots(1, 2, figsize=(13, 5.2))
        for ax, key, label in ((axes[0], "rmse_paired_8bit",
                                "output RMSE against the reference's options\n"
                                "at the same impulse count (8-bit codes)"),
                               (axes[1], "rmse_foveated_8bit",
                                "foveated image RMSE against the exact foveation "
                                "(8-bit codes)")):
            pts = [r for r in errs if math.isfinite(r[key]) and r[key] > 0]
            for r in pts:
                ax.scatter(r["median_s"], r[key], color=colours.get(r["knob"], "k"),
                           label=r["knob"])
                ax.annotate(r["config"], (r["median_s"], r[key]), fontsize=7,
                            xytext=(3, 3), textcoords="offset points")
            front = pareto_front([r["median_s"] for r in pts], [r[key] for r in pts])
            if front:
                ax.plot([pts[i]["median_s"] for i in front], [pts[i][key] for i in front],
                        "k--", lw=0.8, label="Pareto front")
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlabel(f"time per frame, s ({pts[0]['resolution'] if pts else ''})")
            ax.set_ylabel(label)
            handles = dict(zip(*reversed(ax.get_legend_handles_labels()), strict=True))
            ax.legend(handles.values(), handles.keys(), fontsize=8)
            ax.grid(True, which="both", alpha=0.3)
        fig.tight_layout()
        fig.savefig(out / "bench_pareto_rmse.png", dpi=110)
        plt.close(fig)
        written.append("bench_pareto_rmse.png")

        fig, axes = plt.subplots(1, 3, figsize=(16, 5))
        ref = next((r for r in errs if r["knob"] == "reference"), None)
        for ax, key, label in ((axes[0], "excess_kurtosis", "noise excess kurtosis"),
                               (axes[1], "band_frac", "noise power inside [F_L, F_H]"),
                               (axes[2], "std_over_k", "noise std / K (1/6 expected)")):
            for r in errs:
                if math.isfinite(r[key]):
                    ax.scatter(r["median_s"], r[key], color=colours.get(r["knob"], "k"),
                               label=r["knob"])
                    ax.annotate(r["config"], (r["median_s"], r[key]), fontsize=7,
                                xytext=(3, 3), textcoords="offset points")
            if ref is not None and math.isfinite(ref[key]):
                ax.axhline(ref[key], color="k", lw=0.8, ls=":", label="reference")
            ax.set_xscale("log")
            ax.set_xlabel("time per frame, s")
            ax.set_ylabel(label)
            ax.grid(True, which="both", alpha=0.3)
        handles = dict(zip(*reversed(axes[0].get_legend_handles_labels()), strict=True))
        axes[0].legend(handles.values(), handles.keys(), fontsize=8)
        fig.tight_layout()
        fig.savefig(out / "bench_pareto_noise.png", dpi=110)
        plt.close(fig)
        written.append("bench_pareto_noise.png")
    sweep = sweep_rows(ok)
    if sweep:
        fig, axes = plt.subplots(1, 2, figsize=(11, 4.5))
        mpx = [r["megapixels"] for r in sweep]
        axes[0].plot(mpx, [r["s_per_mpx"] for r in sweep], "o-")
        axes[0].set_ylabel("time per megapixel, s")
        axes[1].plot(mpx, [r["peak_rss_mb"] for r in sweep], "o-")
        axes[1].set_ylabel("peak RSS, MB")
        for ax in axes:
            ax.set_xlabel("megapixels")
            ax.set_xscale("log")
            for r in sweep:
                ax.annotate(r["resolution"], (r["megapixels"], ax.lines[0].get_ydata()[
                    sweep.index(r)]), fontsize=7, xytext=(3, 3), textcoords="offset points")
            ax.grid(True, which="both", alpha=0.3)
            ax.set_ylim(bottom=0)
        fig.suptitle(f"{sweep[0]['config'].split('=')[0]} sweep, {sweep[0]['impulses']} "
                     f"impulses, {sweep[0]['device']}", fontsize=9)
        fig.tight_layout()
        fig.savefig(out / "bench_resolution.png", dpi=110)
        plt.close(fig)
        written.append("bench_resolution.png")
    return written


# -------------------------------------------------------------------------------------- CLI
def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: a size is WIDTHxHEIGHT, e.g. 3840x2160"
                                         ) from None
    if not (16 <= w <= 16384 and 16 <= h <= 16384):
        raise argparse.ArgumentTypeError(f"{text!r}: width and height must be in [16, 16384]")
    return w, h


def _sizes(text: str) -> tuple[tuple[int, int], ...]:
    return tuple(_size(t) for t in text.split(",") if t.strip())


def _positive(kind: type) -> Any:
    def parse(text: str) -> Any:
        try:
            v = kind(text)
        except ValueError:
            v = None
        if v is None or not (v > 0) or (kind is float and not math.isfinite(v)):
            raise argparse.ArgumentTypeError(f"{text!r}: must be a positive "
                                             f"{'integer' if kind is int else 'number'}")
        return v

    parse.__name__ = kind.__name__
    return parse


def add_bench_parser(sub: Any) -> argparse.ArgumentParser:
    from .cli import COMMANDS, _parameter

    p = sub.add_parser(
        "bench", help=COMMANDS["bench"][2],
        description="Run time against error of the engine's options (impulse count, exact "
        "foveation, clipping rules, float64, kernel truncation, noise variants, backend) on one "
        f"frame, against a converged reference ({REFERENCE_IMPULSES} impulses, float64, exact "
        "foveation), and the time and peak memory against "
        "resolution. Prints a table; writes bench.csv, BENCH.md, bench.json and Pareto plots "
        "(PNG) into --out. Each configuration runs in its own process. The default run takes "
        "about 10 minutes on a 2-core machine.",
    )
    p.add_argument("--out", type=Path, default=Path("bench"), help="output folder (./bench)")
    p.add_argument("--image", type=Path, help="input frame (default: the shared Sponza render "
                   "../shared/stimuli/sponza-4k.jpg where present, else generated scene-00)")
    p.add_argument("--resolution", type=_size, help="size of the frame the errors are "
                   "measured at (default 3840x2160; --quick 480x270)")
    p.add_argument("--sweep", type=_sizes, help="sizes of the resolution knob (default "
                   "1920x1080,2560x1440,3840x2160,7680x4320; --quick 240x135,480x270,960x540)")
    p.add_argument("--knobs", default=",".join(KNOB_GROUPS),
                   help="comma-separated knob groups (" + ", ".join(KNOB_GROUPS) + ") or "
                   "single items (impulses=12, dtype=float64, truncation=0.1, ...); default "
                   "all. The base configuration (--impulses, defaults) always runs")
    p.add_argument("--repeats", type=_positive(int), help="timed frames per configuration "
                   "(default 3; --quick 2)")
    p.add_argument("--budget-s", type=_positive(float), default=30.0,
                   help="stop repeating a configuration once its frames took this long")
    p.add_argument("--impulses", type=_parameter("impulses"), default=64,
                   help="impulses per kernel of the base configuration and the option knobs")
    p.add_argument("--backend", choices=("cpu", "gpu"), default="cpu",
                   help="backend of the impulse and resolution knobs (the options the GPU "
                   "does not implement run on the CPU); the backend knob runs the other one")
    p.add_argument("--display", default="lg-oled55cx", help="display profile name or path")
    p.add_argument("--blur-rate", type=_parameter("blur_rate"), default=0.34)
    p.add_argument("--seed", type=_parameter("seed"), default=1)
    p.add_argument("--quick", action="store_true",
                   help="CI size: 480x270 and a small sweep, 2 repeats")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=bench_command)
    return p


def bench_command(args: argparse.Namespace) -> int:
    knobs = tuple(k.strip() for k in args.knobs.split(",") if k.strip())
    settings = BenchSettings(
        out=args.out, image=args.image,
        size=args.resolution or (QUICK_RESOLUTION if args.quick else DEFAULT_RESOLUTION),
        sweep=args.sweep or (QUICK_SWEEP if args.quick else SWEEP), knobs=knobs,
        repeats=args.repeats or (2 if args.quick else 3), budget_s=args.budget_s,
        base_impulses=args.impulses, backend=args.backend, display=args.display,
        blur_rate=args.blur_rate, seed=args.seed,
        command=("fovexp " + shlex.join(sys.argv[1:]) if sys.argv[1:2] == ["bench"]
                 else "fovexp bench (called in-process)"),
        progress=not args.no_progress,
    )
    configs_for(knobs, settings.base_impulses, settings.backend, settings.size,
                settings.sweep)  # an unknown knob fails before anything runs
    from .geometry import load_display

    load_display(settings.display)  # likewise a missing display profile
    find_frame(settings.image)  # and a missing image
    args.out.mkdir(parents=True, exist_ok=True)
    # the CSV after every configuration: an interrupted run keeps what it measured
    rows, info = run_all(settings, lambda done: write_csv(done, args.out / "bench.csv"))
    write_csv(rows, args.out / "bench.csv")
    (args.out / "bench.json").write_text(json.dumps({**info, "rows": rows}, indent=1,
                                                    default=str) + "\n")
    plots = write_plots(rows, args.out)
    write_markdown(rows, info, args.out / "BENCH.md", plots)
    print(table_text(rows))
    print(f"wrote {args.out / 'BENCH.md'}, bench.csv, bench.json and {len(plots)} plots "
          f"({info['total_s']:.0f} s)")
    if info.get("interrupted"):
        print(f"fovexp: {info['interrupted']}", file=sys.stderr)
        return 130
    return 0


__all__ = ["Config", "BenchSettings", "band_power_fraction", "configs_for", "excess_kurtosis",
           "noise_statistics", "pareto_front", "rmse_8bit", "run_all"]
