"""Per-stage GPU time of the GPU backend on a frame: what ``benchmarks/gpu.py`` records, and
what a lab runs on its own GPU (one call, or one command: ``benchmarks/gpu.py --stages-only``).

Every stage of every frame is recomputed (a new image each repeat, and the gaze moved by
1e-4 of the screen's width and back, so that the sigma map is recomputed too), with the
enhancer's ``profile="gpu"``: each dispatch is timed by a GL timer query (GL_TIME_ELAPSED),
or, where the driver's query is unusable (Mesa llvmpipe), by the wall clock with a glFinish
before and after it; :attr:`StageProfile.timing_method` says which, and why. A stage's time
is the sum of its dispatches'; transfers (the upload, the impulses' records, the read-back)
are not dispatches and are left out. Medians of ``repeats`` frames after ``warmup`` frames.
"""

from __future__ import annotations

import statistics
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from ..geometry import Display
from ..params import EnhanceParams
from .backend import GpuEnhancer


@dataclass(frozen=True)
class StageProfile:
    """Median GPU milliseconds of one frame's stages and compute entries."""

    device: str  #: GL_RENDERER
    timing_method: str  #: GpuEnhancer.timing_method: the timer query, or why not
    frame: str  #: size, channels and whether the foveation was simulated
    params: dict[str, Any]  #: the EnhanceParams used
    repeats: int
    warmup: int
    #: per stage (those that dispatch work), in the order they ran
    stages_ms: dict[str, float]
    #: per compute entry ("BLUR", "NOISE", ...), summed over its dispatches in a frame
    dispatches_ms: dict[str, float]
    #: the frame's dispatches in all (median over the repeats of each frame's sum)
    frame_ms: float
    #: dispatches per compute entry in a frame (each is followed by a memory barrier)
    dispatch_counts: dict[str, int]

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


def _median_ms(runs: list[dict[str, float]]) -> dict[str, float]:
    keys = list(dict.fromkeys(k for run in runs for k in run))
    return {k: statistics.median(run.get(k, 0.0) for run in runs) * 1e3 for k in keys}


def profile_stages(
    display: Display, image: np.ndarray, params: EnhanceParams | None = None,
    gaze: tuple[float, float] = (0.5, 0.5), simulate_foveation: bool = True,
    repeats: int = 11, warmup: int = 2, ctx: Any = None,
) -> StageProfile:
    """Time every stage of ``image`` (display-encoded, as :meth:`Enhancer.set_image` takes
    it) on the GPU, ``repeats`` times after ``warmup`` frames. ``simulate_foveation=False``:
    the frame is taken as already foveated (the paper's setting: its timings start from a
    foveated rendering). ``ctx``: a moderngl context to run in (default: a new one)."""
    if repeats < 1 or warmup < 0:
        raise ValueError("profile_stages needs repeats >= 1 and warmup >= 0")
    params = (params or EnhanceParams()).resolved(None)
    frames = [image, np.array(image, copy=True)]  # a new array is a new frame to the cache
    nudged = (gaze[0] + (1e-4 if gaze[0] <= 0.5 else -1e-4), gaze[1])
    stage_runs: list[dict[str, float]] = []
    entry_runs: list[dict[str, float]] = []
    with GpuEnhancer(display, ctx=ctx, profile="gpu") as enh:
        for i in range(warmup + repeats):
            enh.set_image(frames[i % 2], foveated=not simulate_foveation)
            res = enh.enhance((gaze, nudged)[i % 2], params)
            if i >= warmup:
                stage_runs.append({k: v for k, v in res.timings_s.items() if v > 0.0})
                entry_runs.append(enh.dispatch_timings_s)
                counts = enh.dispatch_counts
        method, device = str(enh.timing_method), enh.renderer
    h, w = image.shape[:2]
    colour = "RGB" if np.ndim(image) == 3 else "grey"
    how = "foveation simulated" if simulate_foveation else "already foveated"
    return StageProfile(
        device=device, timing_method=method, frame=f"{w}x{h} {colour}, {how}",
        params=params.model_dump(), repeats=repeats, warmup=warmup,
        stages_ms=_median_ms(stage_runs), dispatches_ms=_median_ms(entry_runs),
        frame_ms=statistics.median(sum(run.values()) for run in entry_runs) * 1e3,
        dispatch_counts=counts,
    )
