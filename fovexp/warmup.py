"""Compile every Numba kernel ahead of the first run (``fovexp compile``; ``./dev setup`` runs it).

Numba compiles a kernel at its first call and keeps the machine code in an on-disk cache
(``cache=True``); compiling all of them takes about 20 s on a 2-core machine, which the first
``fovexp enhance`` after installing would otherwise spend. :func:`compile_kernels` runs the
enhancer through every path that reaches a kernel, on small frames, so that each kernel is
compiled for the argument types a real run passes (a cached kernel is found by its types).

Where the cache goes is numba's choice: ``$NUMBA_CACHE_DIR`` when set; else a ``__pycache__``
folder beside the package's modules when it is writable (a virtual environment, an editable
install); else numba's per-user cache (``~/.cache/numba``). A lab that installs fovexp with pip
runs ``fovexp compile`` once, as the user who runs the experiments, after each install.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ._parallel import zero_fill


@dataclass
class CompileReport:
    """What :func:`compile_kernels` did: of the package's ``total`` kernels, those compiled in
    this call, those loaded from the cache, and those in neither (``inlined``: a kernel called
    only by other kernels, once its callers come from the cache, is compiled into them and
    never loaded on its own); the three add up to ``total``. Also the cache folders and the
    seconds it took."""

    total: int = 0
    compiled: list[str] = field(default_factory=list)
    loaded: list[str] = field(default_factory=list)
    inlined: list[str] = field(default_factory=list)
    cache_dirs: set[str] = field(default_factory=set)
    seconds: float = 0.0


def _textured(h: int, w: int, channels: int) -> np.ndarray:
    rng = np.random.default_rng(0)
    img = rng.random((h, w, channels), dtype=np.float32)
    return img[..., 0] if channels == 1 else img


def _exercise() -> Iterator[str]:
    """Every path of the CPU enhancer that reaches a kernel, on small frames: foveation
    (simulated, given as a blur-rate or a sigma map), contrast, noise, every map, both presets
    and the viewing-geometry models, colour and grey, full screen and a viewport, a frame with
    flat regions (skipping), the engine options' float64 and variant paths, and the stereo
    warp of ``fovexp stereo``. A generator: it yields after each path, so that the caller
    counts the kernels ready so far."""
    from .foveation import foveate_exact
    from .geometry import load_display
    from .params import EngineOptions, EnhanceParams
    from .pipeline import MAP_NAMES, Enhancer

    display = load_display("lg-oled55cx")
    w, h = display.width_px, display.height_px
    # a corner of the screen, gaze at the centre: far enough out that the band is open
    viewport = (0, 0, w, h)
    for preset, geometry in (("paper", "exact"), ("paper", "linear"), ("release", None)):
        enh = Enhancer(display, preset=preset, geometry=geometry)
        params = EnhanceParams(preset=preset, impulses=4, seed=1)
        for channels in (3, 1):
            enh.set_image(_textured(96, 160, channels), viewport=viewport)
            res = enh.enhance((0.5, 0.5), params)
            for name in MAP_NAMES:
                res.map(name)
            yield f"{preset} preset, {channels} channel(s)"
        enh.set_image(_textured(48, 80, 3))  # the frame fills the screen
        enh.enhance((0.3, 0.6), params)
        for method in ("foveated", "contrast"):
            enh.enhance((0.5, 0.5), params.model_copy(update={"method": method}))
        yield f"{preset} preset, full screen"
    enh = Enhancer(display)
    frame = _textured(96, 160, 3)
    enh.set_image(frame, foveated=True, viewport=viewport)
    enh.enhance((0.5, 0.5), EnhanceParams(impulses=4))
    sigma = np.full(frame.shape[:2], 2.0, np.float32)
    enh.set_image(frame, sigma_px=sigma, viewport=viewport)
    enh.enhance((0.5, 0.5), EnhanceParams(impulses=4))
    foveate_exact(frame[:8, :8], sigma[:8, :8])  # the reference the benchmarks measure against
    yield "foveated input"
    # Skipping's own kernels (flat blocks left out of the contrast and the foveation) run only
    # on a frame with flat regions: sky, walls, black borders.
    # (A frame filling the screen: its blur is small enough in its own pixels that whole
    # blocks with their boxes lie in the flat half.)
    mixed = _textured(96, 160, 3)
    mixed[:, :80] = 0.5
    enh.set_image(mixed)
    enh.enhance((0.5, 0.5), EnhanceParams(impulses=4))
    yield "flat regions"
    # The engine options' other paths (fovexp bench, the reference configuration): float64
    # stages, the exact clipping extremes, the noise variants.
    for options in (EngineOptions(dtype="float64", clipping="exact"),
                    EngineOptions(impulse_count="jittered", weights="sign", cell_scale=0.5)):
        enh = Enhancer(display, options=options)
        for img, vp in ((frame, viewport), (mixed, None)):
            enh.set_image(img, viewport=vp)
            enh.enhance((0.5, 0.5), EnhanceParams(impulses=4))
        yield "engine options"

    # the impulses' cells (the GPU backend's grid of them; the CPU's noise compiles the same
    # gabor._cell_of into its set-up)
    from .gabor import cell_index
    cell_index(np.zeros(2), 20.0)
    yield "impulse cells"

    # the frame pool's zero fill (fovexp.memory.FramePool.zeros, of arrays larger than these
    # frames')
    zero_fill(np.empty(16, np.float32))
    yield "zero fill"

    # fovexp stereo's warp (section 6.4), a kernel of the evaluation package
    from .evaluation.stereo import forward_warp
    forward_warp(np.zeros((4, 8), np.float32), np.ones((4, 8)))
    yield "stereo warp"


def load_frame_kernels(enh: Any, params: Any, foveated: bool = False) -> None:
    """Load (or compile) the kernels a frame of CPU enhancer ``enh`` calls with ``params``: a
    small frame through an enhancer like it (the same display, preset, geometry, table and
    options; ``enh`` itself keeps its stages). Loading a 4K frame's 25 kernels from the cache,
    Numba's first load included, with the small frame took 0.40-0.47 s (three runs), mostly
    Python: ``fovexp enhance`` does it while its image is read and decoded, which releases
    the GIL. Nothing for a GPU enhancer
    (its shaders are built with it)."""
    from .pipeline import Enhancer

    if getattr(enh, "backend", "cpu") != "cpu":
        return
    twin = Enhancer(enh.display, enh.preset.name, enh.geometry_model, enh.table, enh.options)
    # a corner of the screen with the gaze at its centre (:func:`_exercise`): far enough out
    # that the blur takes the pyramid and the band is open; flat in part, as most frames are
    # (skipping's kernels)
    w, h = enh.display.width_px, enh.display.height_px
    frame = _textured(min(96, h), min(160, w), 3)  # a display smaller than that: all of it
    frame[frame.shape[0] * 2 // 3:, :] = 0.5
    viewport = (0, 0, w, h)
    twin.set_image(frame, foveated=foveated, viewport=viewport)
    twin.enhance((0.5, 0.5), params)


def kernels() -> dict[str, object]:
    """``{module.name: dispatcher}`` of every Numba kernel in the loaded ``fovexp`` modules."""
    from numba.core.dispatcher import Dispatcher

    out: dict[str, object] = {}
    for mod_name, mod in sorted(sys.modules.items()):
        if not mod_name.startswith("fovexp.") or mod is None:
            continue
        for name, obj in vars(mod).items():
            if isinstance(obj, Dispatcher) and obj.__module__ == mod_name:
                out[f"{mod_name}.{name}"] = obj
    return out


def _import_kernel_modules() -> None:
    """Every module that defines a kernel, so that :func:`kernels` knows them all before the
    first is compiled (the count the progress shows)."""
    from . import foveation, pipeline  # noqa: F401 (pipeline imports every stage module)
    from .evaluation import stereo  # noqa: F401


def _is_ready(dispatcher: Any) -> bool:
    """Compiled or loaded in this process (a kernel compiled into its callers is neither)."""
    return bool(dispatcher.overloads)


def compile_kernels(show_progress: bool = False) -> CompileReport:
    """Compile (or load from the cache) every kernel; see the module docstring. With
    ``show_progress``, a bar on stderr counts the kernels ready, kernel by kernel
    (:mod:`fovexp.progress`), naming each as Numba compiles it."""
    from numba.core import event

    from .progress import progress_bar

    t0 = time.perf_counter()
    _import_kernel_modules()
    every = kernels()
    by_dispatcher = {id(d): name for name, d in every.items()}
    bar = progress_bar(total=len(every), desc="fovexp compile", unit="kernel") \
        if show_progress else None

    def recount() -> None:
        if bar is not None:  # update(), not a redraw: a log gets a line every few seconds
            bar.update(sum(_is_ready(d) for d in every.values()) - bar.n)

    class _Compiling(event.Listener):
        """Names the kernel Numba is compiling (its callees compile inside it)."""

        def on_start(self, ev: Any) -> None:
            name = by_dispatcher.get(id(ev.data.get("dispatcher")))
            if bar is not None and name is not None:
                bar.set_postfix_str(name.removeprefix("fovexp."), refresh=False)
                recount()

        def on_end(self, ev: Any) -> None:
            recount()

    with event.install_listener("numba:compile", _Compiling()):
        for _path in _exercise():
            recount()
    report = CompileReport(total=len(every))
    for name, disp in every.items():
        stats = disp.stats  # type: ignore[attr-defined]
        if stats.cache_misses:
            report.compiled.append(name)
        elif stats.cache_hits:
            report.loaded.append(name)
        else:
            report.inlined.append(name)
        cache = getattr(disp, "_cache", None)
        path = getattr(cache, "cache_path", None)
        if path:
            report.cache_dirs.add(str(path))
    if bar is not None:  # the kernels inside their callers are done with them
        bar.set_postfix_str(f"{len(report.compiled)} compiled, {len(report.loaded)} loaded, "
                            f"{len(report.inlined)} inside their callers", refresh=False)
        bar.update(report.total - bar.n)
        bar.close()
    report.seconds = time.perf_counter() - t0
    return report
