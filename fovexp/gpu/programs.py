"""OpenGL context and compute programs of the GPU backend.

Each stage of the method has one GLSL file in ``shaders/`` (``geometry.glsl``,
``foveation.glsl``, ... as the Python modules); a file holds the stage's functions and, behind
``#ifdef ENTRY_<NAME>``, its compute entry points. A program is one entry of one file, with the
files it ``#include``s pasted in once each. The constants the shaders use are not written in
GLSL: the header is generated from the Python modules, so each constant has one definition.
"""

from __future__ import annotations

import ctypes
import re
from pathlib import Path
from typing import Any

import numpy as np

from ..acuity import THIBOS_ECC_DEG, THIBOS_T_HIGH_CPD, THIBOS_T_LOW_CPD
from ..amplitude import MAX_LAPLACIAN_LEVEL, RELEASE_AMPLITUDE_GAIN
from ..colour import LUMA_BT601
from ..errors import FovexpError
from ..frequency import CUTOFF_SIGMAS_F, NYQUIST_CPP
from ..orientation import GRADIENT_EPS, ORIENTATION_LEVEL
from ..pyramids import BINOMIAL_5, KEYS_A

SHADER_DIR = Path(__file__).resolve().parent / "shaders"

#: Storage-buffer binding points, one per buffer the stages exchange.
BINDINGS: dict[str, int] = {name: i for i, name in enumerate((
    "IMAGE", "LINEAR", "SIGMA", "SIGMA_MAX", "BLUR_SRC", "BLUR_DST", "KERNELS", "LEVELS",
    "BRACKET", "FOVEATED", "REDUCE_SRC", "REDUCE_DST", "LUMA_PYR", "LAP_TMP", "ABSLAP",
    "GRADIENTS", "SAT", "CONTRAST", "EXTREMES", "HEADROOM", "IMPULSES", "QUANTILES", "CELLS",
    "IMP_PARAMS", "NOISE", "OUTPUT", "MAPS", "TILES",
))}

#: Fields of the per-impulse record the impulse stage writes and the synthesis reads.
IMPULSE_FIELDS: tuple[str, ...] = ("AMP", "KX", "KY", "K", "F", "OMEGA", "F_LOW", "F_HIGH")

#: Geometry models as the shaders number them.
GEOMETRY_MODELS: dict[str, int] = {"exact": 0, "linear": 1, "release": 2}

#: Work-group sizes: 16 x 16 pixels (a full-resolution group is one tile of the sigma
#: ranges that let the foveation skip work), or 64 rows / columns / impulses.
LOCAL_2D = (16, 16)
LOCAL_1D = 64

_SOFTWARE_RENDERERS = ("llvmpipe", "softpipe", "swrast", "swiftshader", "lavapipe")


def _floats(values: np.ndarray) -> str:
    return ", ".join(f"{float(v):.9g}" for v in np.ravel(values))


def _header(entry: str) -> str:
    lines = [
        "#version 450",
        f"#define ENTRY_{entry} 1",
        f"#define LOCAL_2D layout(local_size_x = {LOCAL_2D[0]}, local_size_y = {LOCAL_2D[1]}) in;",
        f"#define LOCAL_1D layout(local_size_x = {LOCAL_1D}) in;",
        f"#define LOCAL_2D_SIZE {LOCAL_2D[0] * LOCAL_2D[1]}",
        f"#define TILE_PX {LOCAL_2D[0]}",
        *(f"#define B_{name} {i}" for name, i in BINDINGS.items()),
        f"#define IMP_STRIDE {len(IMPULSE_FIELDS)}",
        *(f"#define IMP_{name} {i}" for i, name in enumerate(IMPULSE_FIELDS)),
        *(f"#define GEOM_{name.upper()} {i}" for name, i in GEOMETRY_MODELS.items()),
        "const float PI = 3.14159265358979;",
        f"const int THIBOS_N = {THIBOS_ECC_DEG.size};",
        f"const float THIBOS_ECC_DEG[THIBOS_N] = float[]({_floats(THIBOS_ECC_DEG)});",
        f"const float THIBOS_T_LOW_CPD[THIBOS_N] = float[]({_floats(THIBOS_T_LOW_CPD)});",
        f"const float THIBOS_T_HIGH_CPD[THIBOS_N] = float[]({_floats(THIBOS_T_HIGH_CPD)});",
        f"const float BINOMIAL_5[5] = float[]({_floats(BINOMIAL_5)});",
        f"const vec3 LUMA_BT601 = vec3({_floats(LUMA_BT601)});",
        f"const float NYQUIST_CPP = {NYQUIST_CPP!r};",
        f"const float CUTOFF_SIGMAS_F = {CUTOFF_SIGMAS_F!r};",
        f"const float RELEASE_AMPLITUDE_GAIN = {RELEASE_AMPLITUDE_GAIN!r};",
        f"const float KEYS_A = {KEYS_A!r};",
        f"const int MAX_LAPLACIAN_LEVEL = {MAX_LAPLACIAN_LEVEL};",
        f"const int ORIENTATION_LEVEL = {ORIENTATION_LEVEL};",
        f"const float GRADIENT_EPS = {GRADIENT_EPS!r};",
    ]
    return "\n".join(lines) + "\n"


_INCLUDE = re.compile(r'^\s*#include\s+"([\w.]+)"\s*$', re.M)


def shader_source(file: str, entry: str) -> str:
    """The full source of entry ``entry`` of ``shaders/<file>``, includes resolved once each."""
    seen: set[str] = set()

    def expand(name: str) -> str:
        if name in seen:
            return ""
        seen.add(name)
        path = SHADER_DIR / name
        if not path.is_file():
            raise FovexpError(f"GPU backend: shader {name} is missing from {SHADER_DIR}")
        text = path.read_text()
        return _INCLUDE.sub(lambda m: expand(m.group(1)), text)

    return _header(entry) + expand(file)


def create_context(ctx: Any = None) -> Any:
    """A moderngl context with OpenGL 4.5 (compute shaders, float64): ``ctx`` itself when one
    is given (e.g. attached to a window's context with ``moderngl.create_context()``), else a
    standalone context through EGL (no window or display server needed)."""
    try:
        import moderngl
    except ImportError:
        raise FovexpError(
            "the GPU backend needs moderngl: install fovexp with the 'gpu' extra"
        ) from None
    if ctx is None:
        try:
            ctx = moderngl.create_standalone_context(backend="egl", require=450)
        except Exception as exc:  # moderngl reports missing EGL/drivers with several types
            raise FovexpError(f"no OpenGL 4.5 context through EGL: {exc}") from None
    if ctx.version_code < 450:
        raise FovexpError(f"the GPU backend needs OpenGL 4.5, this context has {ctx.version_code}")
    bindings = int(ctx.info.get("GL_MAX_SHADER_STORAGE_BUFFER_BINDINGS") or 0)
    if bindings < len(BINDINGS):
        raise FovexpError(f"the GPU backend binds {len(BINDINGS)} storage buffers, this driver "
                          f"{bindings} ({renderer_name(ctx)})")
    return ctx


def detach_thread() -> None:
    """Leave no EGL context current on the calling thread (``eglMakeCurrent`` with no context,
    then ``eglReleaseThread``). With libglvnd, a thread that has made an EGL context current
    cannot create a GLX context (a PsychoPy window) until it does; releasing the moderngl
    context alone is not enough (measured under Xvfb: "invalid operation")."""
    try:
        egl = ctypes.CDLL("libEGL.so.1")
    except OSError:
        return
    egl.eglGetCurrentDisplay.restype = ctypes.c_void_p
    egl.eglMakeCurrent.argtypes = [ctypes.c_void_p] * 4
    display = egl.eglGetCurrentDisplay()
    if display:
        egl.eglMakeCurrent(display, None, None, None)
    egl.eglReleaseThread()


def release_context(ctx: Any) -> None:
    """Release a context this package created (and its compiled programs), and detach the
    thread from EGL (any enhancer still using the thread makes its own context current again
    on its next call)."""
    _PROGRAMS.pop(id(ctx), None)
    ctx.release()
    detach_thread()


def renderer_name(ctx: Any) -> str:
    """``GL_RENDERER`` (e.g. "NVIDIA H100 80GB HBM3/PCIe/SSE2", "llvmpipe (LLVM 15.0.6, ...)")."""
    return str(ctx.info.get("GL_RENDERER", "unknown"))


def is_software(ctx: Any) -> bool:
    """Whether the context renders on the CPU (Mesa llvmpipe and the like)."""
    name = renderer_name(ctx).lower()
    return any(s in name for s in _SOFTWARE_RENDERERS)


#: Every compute entry, by file: what Programs.compile_all builds.
ENTRIES: dict[str, tuple[str, ...]] = {
    "foveation.glsl": ("SIGMA", "BLUR", "STACK_INIT", "STACK_ACCUMULATE"),
    "pyramids.glsl": ("REDUCE", "ABS_LAPLACIAN", "BOX3", "BLOCK_EXTREMES", "EXTREMES_FILTER"),
    "contrast.glsl": ("SAT_ROWS", "SAT_COLS", "CONTRAST_CHANGE"),
    "orientation.glsl": ("SOBEL",),
    "gabor.glsl": ("NOISE",),
    "colour.glsl": ("LINEARIZE", "LUMINANCE", "COMPOSE"),
    "pipeline.glsl": ("IMPULSES", "MAPS"),
}


class Programs:
    """Compiled entry points of one context."""

    def __init__(self, ctx: Any) -> None:
        self.ctx = ctx
        self._cache: dict[tuple[str, str], Any] = {}

    def compile_all(self) -> None:
        for file, entries in ENTRIES.items():
            for entry in entries:
                self.get(file, entry)

    def get(self, file: str, entry: str) -> Any:
        key = (file, entry)
        if key not in self._cache:
            src = shader_source(file, entry)
            try:
                self._cache[key] = self.ctx.compute_shader(src)
            except Exception as exc:
                raise FovexpError(
                    f"GPU backend: {file} entry {entry} does not compile: {exc}"
                ) from None
        return self._cache[key]


#: Programs per context (keyed by the context object; contexts are few and long-lived).
_PROGRAMS: dict[int, tuple[Any, Programs]] = {}


def programs_for(ctx: Any) -> Programs:
    """The compiled programs of ``ctx``, shared by every enhancer that runs in it."""
    held = _PROGRAMS.get(id(ctx))
    if held is None or held[0] is not ctx:
        held = _PROGRAMS[id(ctx)] = (ctx, Programs(ctx))
    return held[1]
