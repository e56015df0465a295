"""OpenGL context and compute programs of the GPU backend.

Each stage of the method has one GLSL file in ``shaders/`` (``geometry.glsl``,
``foveation.glsl``, ... as the Python modules); a file holds the stage's functions and, behind
``#ifdef ENTRY_<NAME>``, its compute entry points. A program is one entry of one file, with the
files it ``#include``s pasted in once each. The constants the shaders use are not written in
GLSL: the header is generated from the Python modules, so each constant has one definition
(derived ones included: the expand taps, the box width per level, arcmin per degree, the
impulse cells' origin).
"""

from __future__ import annotations

import ctypes
import functools
import re
import weakref
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from ..acuity import THIBOS_ECC_DEG, THIBOS_T_HIGH_CPD, THIBOS_T_LOW_CPD
from ..amplitude import MAX_LAPLACIAN_LEVEL, RELEASE_AMPLITUDE_GAIN
from ..colour import LUMA_BT601
from ..contrast import BOX_WIDTH_PX_PER_LEVEL, SAT_FRACTION_BITS
from ..errors import FovexpError
from ..frequency import CUTOFF_SIGMAS_F, NYQUIST_CPP
from ..gabor import CELL_BORDER, CELL_ORIGIN_PX
from ..geometry import ARCMIN_PER_DEG
from ..orientation import GRADIENT_EPS, ORIENTATION_LEVEL
from ..pipeline import POINT_MAPS
from ..pyramids import BINOMIAL_5, EXPAND_EVEN_TAPS, EXPAND_ODD_TAPS, KEYS_A

SHADER_DIR = Path(__file__).resolve().parent / "shaders"

#: Storage-buffer binding points, one per buffer the stages exchange.
BINDINGS: dict[str, int] = {name: i for i, name in enumerate((
    "IMAGE", "LINEAR", "SIGMA", "BLUR_SRC", "BLUR_DST", "KERNELS", "LEVELS",
    "BRACKET", "FOVEATED", "REDUCE_SRC", "REDUCE_DST", "LUMA_PYR", "LAP_TMP", "ABSLAP",
    "GRADIENTS", "SAT", "CONTRAST", "EXTREMES", "HEADROOM", "IMPULSES", "QUANTILES", "CELLS",
    "IMP_PARAMS", "NOISE", "OUTPUT", "MAP", "TILES", "TILE_SRC", "FLAT_TILES", "FLAT_FLAGS",
))}

#: OpenGL extensions a shader file needs, declared in its programs' header. The contrast's
#: exact summed-area table sums 64-bit integers (llvmpipe, NVIDIA, AMD and Intel's Mesa and
#: Windows drivers have GL_ARB_gpu_shader_int64).
EXTENSIONS: dict[str, tuple[str, ...]] = {"contrast.glsl": ("GL_ARB_gpu_shader_int64",)}

#: Fields of the per-impulse record the impulse stage writes and the synthesis reads.
IMPULSE_FIELDS: tuple[str, ...] = ("AMP", "KX", "KY", "K", "F", "OMEGA", "F_LOW", "F_HIGH")

#: Geometry models as the shaders number them.
GEOMETRY_MODELS: dict[str, int] = {"exact": 0, "linear": 1, "release": 2}

#: Work-group sizes: 16 x 16 pixels (a full-resolution group is one tile of the sigma
#: ranges that let the foveation skip work), or 64 rows / columns / impulses.
LOCAL_2D = (16, 16)
LOCAL_1D = 64

#: GL_RENDERER substrings (lower case) of renderers that run on the CPU, forward to a host
#: through a virtual GPU (virgl, VMware SVGA3D) or stand in for a missing driver (Microsoft
#: Basic Render): none is faster than the CPU backend.
_SOFTWARE_RENDERERS = (
    "llvmpipe", "softpipe", "swrast", "swiftshader", "lavapipe", "virgl", "svga3d",
    "microsoft basic render",
)

#: GL_MAX_COMPUTE_WORK_GROUP_COUNT that OpenGL 4.3+ guarantees on each axis.
MIN_WORK_GROUP_COUNT = 65535


def _floats(values: np.ndarray) -> str:
    return ", ".join(f"{float(v):.9g}" for v in np.ravel(values))


def _header(entry: str, extensions: tuple[str, ...] = ()) -> str:
    lines = [
        "#version 450",
        *(f"#extension {name} : require" for name in extensions),
        f"#define ENTRY_{entry} 1",
        f"#define LOCAL_2D layout(local_size_x = {LOCAL_2D[0]}, local_size_y = {LOCAL_2D[1]}) in;",
        f"#define LOCAL_1D layout(local_size_x = {LOCAL_1D}) in;",
        f"#define LOCAL_2D_SIZE {LOCAL_2D[0] * LOCAL_2D[1]}",
        f"#define GROUP_2D ivec2({LOCAL_2D[0]}, {LOCAL_2D[1]})",  # gl_WorkGroupSize, in functions
        f"#define TILE_PX {LOCAL_2D[0]}",
        *(f"#define B_{name} {i}" for name, i in BINDINGS.items()),
        f"#define IMP_STRIDE {len(IMPULSE_FIELDS)}",
        *(f"#define IMP_{name} {i}" for i, name in enumerate(IMPULSE_FIELDS)),
        *(f"#define GEOM_{name.upper()} {i}" for name, i in GEOMETRY_MODELS.items()),
        *(f"#define MAP_{name.upper()} {i}" for i, name in enumerate(POINT_MAPS)),
        "const float PI = 3.14159265358979;",
        f"const int THIBOS_N = {THIBOS_ECC_DEG.size};",
        f"const float THIBOS_ECC_DEG[THIBOS_N] = float[]({_floats(THIBOS_ECC_DEG)});",
        f"const float THIBOS_T_LOW_CPD[THIBOS_N] = float[]({_floats(THIBOS_T_LOW_CPD)});",
        f"const float THIBOS_T_HIGH_CPD[THIBOS_N] = float[]({_floats(THIBOS_T_HIGH_CPD)});",
        f"const float BINOMIAL_5[5] = float[]({_floats(BINOMIAL_5)});",
        f"const vec3 EXPAND_EVEN_TAPS = vec3({_floats(EXPAND_EVEN_TAPS)});",
        f"const vec2 EXPAND_ODD_TAPS = vec2({_floats(EXPAND_ODD_TAPS)});",
        f"const int BOX_WIDTH_PX_PER_LEVEL = {BOX_WIDTH_PX_PER_LEVEL};",
        f"const double SAT_SCALE = {float(2**SAT_FRACTION_BITS)!r}LF;",
        f"const double SAT_STEP = {float(2.0**-SAT_FRACTION_BITS)!r}LF;",
        f"const float ARCMIN_PER_DEG = {ARCMIN_PER_DEG!r};",
        f"const float CELL_ORIGIN_PX = {CELL_ORIGIN_PX!r};",
        f"const int CELL_BORDER = {CELL_BORDER};",
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

    return _header(entry, EXTENSIONS.get(file, ())) + expand(file)


def create_context(ctx: Any = None) -> Any:
    """A moderngl context with OpenGL 4.5 (compute shaders, float64): ``ctx`` itself when one
    is given (e.g. attached to a window's context with ``moderngl.create_context()``), else a
    standalone context through EGL (no window or display server needed)."""
    try:
        import moderngl
    except ImportError:
        raise FovexpError(
            "the GPU backend needs moderngl: pip install 'fovexp[gpu]'"
        ) from None
    if ctx is None:
        try:
            ctx = moderngl.create_standalone_context(backend="egl", require=450)
        except Exception as exc:  # moderngl reports missing EGL/drivers with several types
            raise FovexpError(f"no OpenGL 4.5 context through EGL: {exc}") from None
    if ctx.version_code < 450:
        raise FovexpError(f"the GPU backend needs OpenGL 4.5, this context has {ctx.version_code}")
    missing = [e for names in EXTENSIONS.values() for e in names if e not in ctx.extensions]
    if missing:
        raise FovexpError(f"the GPU backend needs {', '.join(sorted(set(missing)))}, which this "
                          f"driver lacks ({renderer_name(ctx)})")
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
    egl = _libegl()
    if egl is None:
        return
    display = egl.eglGetCurrentDisplay()
    if display:
        egl.eglMakeCurrent(display, None, None, None)
    egl.eglReleaseThread()


_EGL_DRAW, _EGL_READ = 0x3059, 0x305A


@functools.cache
def _libegl() -> Any:
    """libEGL with the signatures used here, or None where there is none."""
    try:
        egl = ctypes.CDLL("libEGL.so.1")
    except OSError:
        return None
    for name in ("eglGetCurrentDisplay", "eglGetCurrentContext", "eglGetCurrentSurface"):
        getattr(egl, name).restype = ctypes.c_void_p
    egl.eglGetCurrentSurface.argtypes = [ctypes.c_int32]
    egl.eglMakeCurrent.argtypes = [ctypes.c_void_p] * 4
    return egl


@contextmanager
def made_current(ctx: Any) -> Iterator[Any]:
    """``ctx`` current for the block, and afterwards the EGL context that was current before
    it, if any. moderngl's EGL backend leaves no context current on leaving ``with ctx:``,
    which would take the context from under a caller who had one current (an enclosing
    ``with ctx:``, a renderer's own EGL context). GLX, WGL and CGL restore it themselves."""
    egl = _libegl()
    saved = None
    if egl is not None and egl.eglGetCurrentContext():
        saved = (egl.eglGetCurrentDisplay(), egl.eglGetCurrentSurface(_EGL_DRAW),
                 egl.eglGetCurrentSurface(_EGL_READ), egl.eglGetCurrentContext())
    try:
        with ctx:
            yield ctx
    finally:
        if saved is not None:
            egl.eglMakeCurrent(*saved)


def release_context(ctx: Any) -> None:
    """Release a context this package created (and its compiled programs), and detach the
    thread from EGL (any enhancer still using the thread makes its own context current again
    on its next call)."""
    if hasattr(ctx, _PROGRAMS_ATTR):
        delattr(ctx, _PROGRAMS_ATTR)  # its shaders go with the context
    ctx.release()
    detach_thread()


def renderer_name(ctx: Any) -> str:
    """``GL_RENDERER`` (e.g. "NVIDIA H100 80GB HBM3/PCIe/SSE2", "llvmpipe (LLVM 15.0.6, ...)")."""
    return str(ctx.info.get("GL_RENDERER", "unknown"))


def is_software(ctx: Any) -> bool:
    """Whether the context renders on the CPU (Mesa llvmpipe and the like) or on a virtual or
    fallback device (virgl, VMware SVGA3D, Microsoft Basic Render)."""
    name = renderer_name(ctx).lower()
    return any(s in name for s in _SOFTWARE_RENDERERS)


def max_work_groups(ctx: Any) -> tuple[int, int, int]:
    """GL_MAX_COMPUTE_WORK_GROUP_COUNT: the most work groups one dispatch may have along x, y
    and z (OpenGL's guaranteed minimum where the driver does not report it)."""
    raw = ctx.info.get("GL_MAX_COMPUTE_WORK_GROUP_COUNT")
    try:
        x, y, z = (max(int(v), 1) for v in raw)
    except (TypeError, ValueError):
        return (MIN_WORK_GROUP_COUNT,) * 3
    return x, y, z


#: Every compute entry, by file: what Programs.compile_all builds.
ENTRIES: dict[str, tuple[str, ...]] = {
    "foveation.glsl": ("SIGMA", "BLUR", "STACK_INIT", "STACK_ACCUMULATE"),
    "pyramids.glsl": ("REDUCE", "ABS_LAPLACIAN", "BOX3", "BLOCK_EXTREMES", "EXTREMES_FILTER",
                      "TILE_EXTREMES"),
    "contrast.glsl": ("SAT_ROWS", "SAT_COLS", "CONTRAST_CHANGE"),
    "orientation.glsl": ("SOBEL",),
    "gabor.glsl": ("NOISE",),
    "colour.glsl": ("LINEARIZE", "LUMINANCE", "COMPOSE"),
    "pipeline.glsl": ("IMPULSES", "MAPS"),
}


class Programs:
    """Compiled entry points of one context, and the dispatch limits of its driver."""

    def __init__(self, ctx: Any) -> None:
        self.ctx = ctx
        self.max_groups_xyz = max_work_groups(ctx)
        #: the enhancers running in the context (weakly: one dropped unclosed is no user)
        self.users: weakref.WeakSet[Any] = weakref.WeakSet()
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

    def release(self) -> None:
        """Delete the compiled shaders (the context must be current)."""
        for prog in self._cache.values():
            prog.release()
        self._cache.clear()


# The programs are kept on the context object itself, not in a module registry: compiled
# shaders hold their context, so a registry (even a weak-keyed one) would keep every context
# alive; on the context they are collected with it.
_PROGRAMS_ATTR = "_fovexp_programs"


def programs_for(ctx: Any, user: Any = None) -> Programs:
    """The compiled programs of ``ctx``, shared by every enhancer that runs in it; ``user``
    (an enhancer) counts as one of them until :func:`drop_user`."""
    progs = getattr(ctx, _PROGRAMS_ATTR, None)
    if progs is None:
        progs = Programs(ctx)
        setattr(ctx, _PROGRAMS_ATTR, progs)
    if user is not None:
        progs.users.add(user)
    return progs


def drop_user(ctx: Any, user: Any) -> None:
    """``user`` no longer runs in ``ctx``: when no other enhancer does, delete the compiled
    programs and forget them (the context itself stays with its owner). ``ctx`` must be
    current."""
    progs = getattr(ctx, _PROGRAMS_ATTR, None)
    if progs is None:
        return
    progs.users.discard(user)
    if not progs.users:
        delattr(ctx, _PROGRAMS_ATTR)
        progs.release()
