"""The backend choice: :func:`make_enhancer` gives an :class:`~fovexp.pipeline.Enhancer` on the
CPU (NumPy/Numba, :mod:`fovexp.pipeline`) or on the GPU (OpenGL 4.5 compute shaders,
:mod:`fovexp.gpu`). It sits above both: the pipeline does not know the GPU backend exists.
"""

from __future__ import annotations

import glob
import sys
from typing import Any

from .errors import FovexpError
from .geometry import Display, GeometryModel
from .params import EngineOptions, ParameterTable, get_preset
from .pipeline import Enhancer

#: Backends :func:`make_enhancer` accepts.
BACKENDS: tuple[str, ...] = ("auto", "cpu", "gpu")
#: Why ``auto`` took the CPU where the GPU extra (moderngl) is not installed: the runner says
#: it once ("enhancer on the CPU: ..."), in words a lab can act on (a rig needs the GPU backend
#: for its frame budget: a 4K wheel step takes about 0.4 s on the CPU).
NO_GPU_EXTRA = "the GPU extra is not installed (a rig needs it: pip install 'fovexp[gpu]')"


#: Why ``auto`` took the CPU on a Linux system that exposes no GPU device to user space.
NO_GPU_DEVICE = ("no GPU device (no /dev/dri render node, /dev/nvidia* or /dev/dxg): OpenGL "
                 "would be a software renderer, slower than the CPU backend")
#: The device files through which Linux hands a GPU to user space: DRM render nodes (Mesa's
#: drivers), NVIDIA's driver, WSL's GPU.
_GPU_DEVICE_FILES = ("/dev/dri/renderD*", "/dev/nvidia[0-9]*", "/dev/dxg")


def gpu_device_present() -> bool:
    """Whether the system may have a hardware GPU for OpenGL: on Linux, one of its device
    files exists (:data:`_GPU_DEVICE_FILES`); elsewhere, always (the context decides). Without
    one, ``auto`` does not create an OpenGL context only to find Mesa's software renderer
    (50 ms of every ``fovexp enhance`` on a machine without a GPU)."""
    if not sys.platform.startswith("linux"):
        return True
    return any(glob.glob(pattern) for pattern in _GPU_DEVICE_FILES)


def gpu_extra_installed() -> bool:
    """Whether moderngl, the GPU backend's one extra package (``fovexp[gpu]``), imports."""
    try:
        import moderngl  # noqa: F401
    except ImportError:
        return False
    return True


def _cpu(display: Display, preset: str, geometry: GeometryModel | None,
         table: ParameterTable | None, options: EngineOptions | None,
         why: str | None) -> Enhancer:
    """The CPU enhancer; ``why`` (``auto`` fell back to it) becomes its ``fallback_reason``."""
    enh = Enhancer(display, preset, geometry, table, options)
    enh.fallback_reason = why  # type: ignore[attr-defined]
    return enh


def _gpu(enh: Enhancer) -> Enhancer:
    enh.fallback_reason = None  # type: ignore[attr-defined]
    return enh


def make_enhancer(
    display: Display, preset: str = "paper", geometry: GeometryModel | None = None,
    table: ParameterTable | None = None, backend: str = "auto", ctx: Any = None,
    options: EngineOptions | None = None,
) -> Enhancer:
    """An :class:`Enhancer` on ``backend``: ``"cpu"`` (NumPy/Numba), ``"gpu"`` (OpenGL 4.5
    compute shaders, :class:`fovexp.gpu.GpuEnhancer`; a clear error when there is no context),
    or ``"auto"``: the GPU when a hardware OpenGL 4.5 context is available and the preset is
    ``paper``, else the CPU (a software renderer such as Mesa's llvmpipe is slower than the CPU
    backend: benchmarks/GPU.md). Create it on the thread that will use it.

    ``ctx``: a moderngl context for the GPU backend to run in (e.g. one sharing objects with a
    window's, so that its output can be drawn without a read-back); by default a standalone one
    through EGL. ``auto`` then judges that context (hardware or software).

    ``options``: the :class:`~fovexp.EngineOptions` of either backend; the GPU implements
    ``skip`` only, so ``auto`` takes the CPU for any other non-default option, and ``gpu``
    refuses it by name.

    The enhancer's ``fallback_reason`` says why ``auto`` chose the CPU (None when it did not
    fall back: the GPU was chosen, or the CPU was asked for), so a caller can show it.

    >>> from fovexp import load_display, make_enhancer
    >>> enh = make_enhancer(load_display("lg-oled55cx"), backend="cpu")
    >>> enh.backend, enh.fallback_reason
    ('cpu', None)
    """
    if backend not in BACKENDS:
        raise FovexpError(f"unknown backend {backend!r} (choose from {', '.join(BACKENDS)})")
    if backend == "cpu":
        return _cpu(display, preset, geometry, table, options, None)
    if backend == "auto" and get_preset(preset).name != "paper":
        return _cpu(display, preset, geometry, table, options,
                    f"the {preset!r} preset runs on the CPU backend only")
    if backend == "auto" and not gpu_extra_installed():
        return _cpu(display, preset, geometry, table, options, NO_GPU_EXTRA)
    if backend == "auto" and ctx is None and not gpu_device_present():
        return _cpu(display, preset, geometry, table, options, NO_GPU_DEVICE)
    from .gpu import GpuEnhancer, create_context, is_software, release_context, renderer_name

    unsupported = GpuEnhancer.unsupported(options or EngineOptions())
    if backend == "auto" and unsupported:
        return _cpu(display, preset, geometry, table, options,
                    "the GPU backend does not implement the engine options "
                    + ", ".join(f"{k}={v!r}" for k, v in unsupported.items()))
    if backend == "gpu":  # no context (or no moderngl): a FovexpError that says so
        return _gpu(GpuEnhancer(display, preset, geometry, table, ctx=ctx, options=options))
    try:
        gl = create_context(ctx)
    except FovexpError as exc:  # no moderngl, no EGL, no OpenGL 4.5
        return _cpu(display, preset, geometry, table, options, f"no GPU: {exc}")
    if is_software(gl):
        name = renderer_name(gl)
        if ctx is None:
            release_context(gl)
        return _cpu(display, preset, geometry, table, options,
                    f"the OpenGL renderer is software ({name}), slower than the CPU backend")
    try:  # GpuEnhancer compiles every shader: a driver that cannot falls back to the CPU
        return _gpu(GpuEnhancer(display, preset, geometry, table, ctx=gl,
                                owns_context=ctx is None, options=options))
    except FovexpError as exc:
        return _cpu(display, preset, geometry, table, options, f"the GPU backend failed: {exc}")
