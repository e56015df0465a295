"""The backend choice: :func:`make_enhancer` gives an :class:`~fovexp.pipeline.Enhancer` on the
CPU (NumPy/Numba, :mod:`fovexp.pipeline`) or on the GPU (OpenGL 4.5 compute shaders,
:mod:`fovexp.gpu`). It sits above both: the pipeline does not know the GPU backend exists.
"""

from __future__ import annotations

from .errors import FovexpError
from .geometry import Display, GeometryModel
from .params import EngineOptions, ParameterTable, get_preset
from .pipeline import Enhancer

#: Backends :func:`make_enhancer` accepts.
BACKENDS: tuple[str, ...] = ("auto", "cpu", "gpu")


def make_enhancer(
    display: Display, preset: str = "paper", geometry: GeometryModel | None = None,
    table: ParameterTable | None = None, backend: str = "auto",
    options: EngineOptions | None = None,
) -> Enhancer:
    """An :class:`Enhancer` on ``backend``: ``"cpu"`` (NumPy/Numba), ``"gpu"`` (OpenGL 4.5
    compute shaders, :class:`fovexp.gpu.GpuEnhancer`; a clear error when there is no context),
    or ``"auto"``: the GPU when a hardware OpenGL 4.5 context is available and the preset is
    ``paper``, else the CPU (a software renderer such as Mesa's llvmpipe is slower than the CPU
    backend: benchmarks/GPU.md). Create it on the thread that will use it."""
    if backend not in BACKENDS:
        raise FovexpError(f"unknown backend {backend!r} (choose from {', '.join(BACKENDS)})")
    if backend == "cpu" or (backend == "auto" and get_preset(preset).name != "paper"):
        return Enhancer(display, preset, geometry, table, options)
    from .gpu import GpuEnhancer, create_context, is_software, release_context

    if backend == "auto" and GpuEnhancer.unsupported(options or EngineOptions()):
        return Enhancer(display, preset, geometry, table, options)
    if backend == "gpu":  # no context (or no moderngl): a FovexpError that says so
        return GpuEnhancer(display, preset, geometry, table, options=options)
    try:
        ctx = create_context()
    except FovexpError:  # no moderngl, no EGL, no OpenGL 4.5
        return Enhancer(display, preset, geometry, table, options)
    if is_software(ctx):
        release_context(ctx)
        return Enhancer(display, preset, geometry, table, options)
    try:  # GpuEnhancer compiles every shader: a driver that cannot falls back to the CPU
        return GpuEnhancer(display, preset, geometry, table, ctx=ctx, owns_context=True,
                           options=options)
    except FovexpError:
        return Enhancer(display, preset, geometry, table, options)
