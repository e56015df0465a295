"""The enhancer: the paper's stages composed, with a cache that knows what a change invalidates.

Stages and what each depends on (a parameter change recomputes only what lies downstream)::

    image ─ linear ─┬─ foveated ─┬─ luma ─┬─ pyramid ─┬─ laplacian ──── amplitude ─┐
                    │            │        │           └─ gradients ─── orientation ┤
                    │            │        └─ luma_flat (where it is flat) ───┐     │
    gaze, blur_rate ┴─ sigma ────┴─ contrast (f_e) ─ headroom ─────────── K (s_k) ─┤
    impulses, seed ─ impulses ─ band ─ active (not flat) ─ frequency (s_f) ────────┴─ noise ─ output

The noise parameters are evaluated at the impulses only (the paper's per-impulse reading,
section 4.4). With ``EngineOptions.skip`` (the default) work whose result is known is left
out, exactly: impulses whose band is empty (F_L >= F_H: the fovea and its surround, section
4.1) and impulses whose |L| neighbourhood is one constant luminance (flat regions: |L|, hence K,
is exactly 0 there, section 4.2) get no amplitude, frequency or orientation and add no noise;
|L| is computed only on the tiles such impulses read; the contrast change is not computed on
blocks whose boxes are flat (it is exactly 0); the foveation leaves flat regions as they are;
the pyramid's first level takes flat blocks as their constant, unread.
The arithmetic of each stage is written so that these results are exact (pyramids and blurs
as "centre + weighted differences", an integer summed-area table), so the output is the same
bit for bit with ``skip=False`` (tested). Full-resolution maps of the parameters are computed
on demand (:meth:`EnhanceResult.map`), by the same functions evaluated on the pixel grid.

Stages that do not depend on the image (geometry, grids, sigma, impulses, per-impulse band)
are kept across the frames of a sequence as across parameter steps: :meth:`Enhancer.set_image`
invalidates only what depends on the image.

References
----------
.. [tariq] Tariq, T., Tursun, C., Didyk, P. (2022). Noise-based Enhancement for Foveated
   Rendering. ACM Transactions on Graphics 41(4) (SIGGRAPH 2022). doi:10.1145/3528223.3530101
.. [patney] Patney, A., Salvi, M., Kim, J., Kaplanyan, A., Wyman, C., Benty, N., Luebke, D.,
   Lefohn, A. (2016). Towards Foveated Rendering for Gaze-Tracked Virtual Reality. ACM
   Transactions on Graphics 35(6). doi:10.1145/2980179.2980246
.. [lagae] Lagae, A., Lefebvre, S., Drettakis, G., Dutré, P. (2009). Procedural Noise using
   Sparse Gabor Convolution. ACM Transactions on Graphics 28(3) (SIGGRAPH 2009).
   doi:10.1145/1531326.1531360
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numba
import numpy as np

from . import amplitude as amp
from . import colour, frequency, gabor, orientation, pyramids
from ._parallel import over_points, thread_map
from .contrast import contrast_change, contrast_change_where_needed, unchanged_blocks
from .errors import FovexpError
from .foveation import (
    SigmaOnBlocks,
    foveate,
    foveate_exact,
    sigma_bound_px,
    sigma_on_blocks,
    sigma_px,
)
from .geometry import Display, GeometryModel, ViewingGeometry
from .jit import FASTMATH
from .memory import FramePool, WrittenRows, frame_empty, retain_freed_memory
from .params import EngineOptions, EnhanceParams, ParameterTable, Preset, get_preset
from .pyramids import FLAT_BLOCK_LEVEL

MAP_NAMES: tuple[str, ...] = (
    "eccentricity_deg", "sigma_px", "f_low_cpp", "f_high_cpp", "amplitude", "orientation_rad",
    "noise", "foveated", "contrast", "output",
)
#: The maps that evaluate the per-impulse functions at every pixel (section 4.4's parameters on
#: the pixel grid), computed when asked for.
POINT_MAPS: tuple[str, ...] = (
    "eccentricity_deg", "f_low_cpp", "f_high_cpp", "amplitude", "orientation_rad",
)


def split_alpha(image: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """``(colour, alpha)`` of an image: grey + alpha (H, W, 2) and RGBA (H, W, 4) give their
    last channel as ``alpha`` (H, W), which the enhancer passes through unchanged (renderers'
    frames often carry one); grey and RGB give ``alpha = None``."""
    a = np.asarray(image)
    if a.ndim == 3 and a.shape[2] in (2, 4):
        return np.ascontiguousarray(a[..., :-1]), np.ascontiguousarray(a[..., -1])
    return a, None


def with_alpha(colour: np.ndarray, alpha: np.ndarray | None) -> np.ndarray:
    """``colour`` with ``alpha`` attached as its last channel (inverse of :func:`split_alpha`)."""
    if alpha is None:
        return colour
    c = colour if colour.ndim == 3 else colour[..., None]
    return np.concatenate([c, alpha[..., None].astype(c.dtype, copy=False)], axis=2)


#: Elements per part of :func:`_finite_range` (a part's three passes stay in the cache).
_CHECK_PART = 1 << 18


def _finite_range(flat: np.ndarray) -> tuple[int, float, float]:
    """``(non-finite count, min, max)`` of a flat float array, in parts on threads, each part's
    NumPy passes in the cache (three passes and a mask over a whole 4K frame were 50 ms of its
    set-up). A part's min and max are finite only when all its values are (NumPy's min and
    max propagate NaN; an infinity is an extreme), so its non-finite values are counted only
    when they are not (two passes, not four: a 4K frame 17 -> 11 ms). The extremes are
    meaningful only when the count is 0."""
    def part(i: int) -> tuple[int, float, float]:
        seg = flat[i:i + _CHECK_PART]
        lo, hi = float(seg.min()), float(seg.max())
        bad = 0 if np.isfinite(lo) and np.isfinite(hi) else int(np.count_nonzero(~np.isfinite(seg)))
        return bad, lo, hi

    parts = thread_map(part, range(0, flat.size, _CHECK_PART))
    return (sum(p[0] for p in parts), min(p[1] for p in parts), max(p[2] for p in parts))


def check_image(image: np.ndarray, what: str = "image", dtype: type = np.float32) -> np.ndarray:
    """Validate a display-encoded float image: (H, W) or (H, W, 3), finite, in [0, 1];
    returned as ``dtype``."""
    a = _image_array(image, what)
    _check_values(a, what)
    return a.astype(dtype, copy=False)


def _image_array(image: np.ndarray, what: str) -> np.ndarray:
    """:func:`check_image`'s checks of the shape and the type: the array, (H, W, 1) as
    (H, W)."""
    a = np.asarray(image)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if a.ndim not in (2, 3) or (a.ndim == 3 and a.shape[2] != 3):
        ch = a.shape[2] if a.ndim == 3 else "?"
        raise FovexpError(
            f"{what} has shape {a.shape}: expected grey (H, W) or RGB (H, W, 3), each with or "
            f"without an alpha channel, got {ch} channels"
        )
    if min(a.shape[:2]) < 16:
        raise FovexpError(f"{what} is {a.shape[1]}x{a.shape[0]} px: at least 16x16 is needed")
    if not np.issubdtype(a.dtype, np.floating):
        raise FovexpError(f"{what} must be a float array in [0, 1], got dtype {a.dtype}")
    return a


def _check_values(a: np.ndarray, what: str) -> None:
    """:func:`check_image`'s check of the values: finite, in [0, 1]."""
    if a.flags.c_contiguous and a.size:
        n_bad, lo, hi = _finite_range(a.reshape(-1))
    else:  # another float type, or a strided view: NumPy's passes
        n_bad = int(np.count_nonzero(~np.isfinite(a)))
        lo, hi = (float(a.min()), float(a.max())) if not n_bad else (0.0, 0.0)
    if n_bad:
        bad = ~np.isfinite(a)
        y, x = np.argwhere(bad.reshape(a.shape[0], a.shape[1], -1).any(axis=2))[0]
        raise FovexpError(f"{what} has {int(n_bad)} NaN/Inf values (first at x={x}, y={y})")
    if lo < 0.0 or hi > 1.0:
        raise FovexpError(f"{what} values must lie in [0, 1], found [{lo:.4g}, {hi:.4g}]")


class _StageCache:
    """Named stages computed lazily from inputs and other stages; setting an input drops
    every stage downstream of it. A dependency written ``"?name"`` is passed as a
    zero-argument getter, so a stage pulls it only if it needs it (the output of the
    ``contrast`` method never computes the noise)."""

    def __init__(self) -> None:
        self._fns: dict[str, tuple[tuple[str, ...], Callable[..., Any]]] = {}
        self._inputs: dict[str, Any] = {}
        self._values: dict[str, Any] = {}
        self.timings_s: dict[str, float] = {}
        self._provided_s: dict[str, float] = {}  # :meth:`provide`'s times, not yet reported
        self._provided_from: dict[str, tuple[str, ...]] = {}  # provided stages' inputs
        self._nested_s = 0.0  # time spent in stages pulled by the stage being computed
        #: what the stages are timed with (seconds); the GPU backend's profiler sets a clock
        #: that advances by the GPU time of each dispatch
        self.clock: Callable[[], float] = time.perf_counter
        #: the stages' large arrays, in the buffers of the last frame's (fovexp.memory)
        self.pool = FramePool()

    def stage(self, name: str, deps: tuple[str, ...], fn: Callable[..., Any]) -> None:
        self._fns[name] = (deps, fn)

    def set(self, **inputs: Any) -> None:
        for k, v in inputs.items():
            old = self._inputs.get(k, _MISSING)
            if old is _MISSING or not _same(old, v):
                self._inputs[k] = v
                self._invalidate(k)

    def _invalidate(self, name: str) -> None:
        for stage, (deps, _) in self._fns.items():
            if ((name in deps or f"?{name}" in deps or name in self._provided_from.get(stage, ()))
                    and stage in self._values):
                del self._values[stage]
                self._provided_from.pop(stage, None)
                self._invalidate(stage)

    def get(self, name: str) -> Any:
        if name in self._inputs:
            return self._inputs[name]
        if name not in self._values:
            deps, fn = self._fns[name]
            args = [
                (lambda d=d[1:]: self.get(d)) if d.startswith("?") else self.get(d) for d in deps
            ]
            outer, self._nested_s = self._nested_s, 0.0
            t0 = self.clock()
            with self.pool.active():
                self._values[name] = fn(*args)
            self._provided_from.pop(name, None)
            elapsed = self.clock() - t0
            # a stage's own time excludes the stages it pulled lazily ("?name" dependencies)
            self.timings_s[name] = self.timings_s.get(name, 0.0) + elapsed - self._nested_s
            self._nested_s = outer + elapsed
        return self._values[name]

    def cached(self, name: str) -> bool:
        return name in self._values

    def provide(self, name: str, value: Any, elapsed_s: float, inputs: tuple[str, ...]) -> None:
        """Set stage ``name``'s value, computed elsewhere from the current ``inputs``, and its
        time, which the next :meth:`start_timing` reports as the stage's. Its stage
        dependencies need not be cached: setting one of ``inputs`` drops it (an
        already-foveated frame's luminance, provided with its linearisation, is kept when
        the gaze changes the ``foveated`` stage it would be computed from, and dropped when
        the frame or its ``already_foveated`` changes)."""
        self._values[name] = value
        self._provided_s[name] = elapsed_s
        self._provided_from[name] = inputs

    def start_timing(self) -> None:
        """Start a frame's timings: the stages provided since the last frame with theirs."""
        self.timings_s = dict(self._provided_s)
        self._provided_s.clear()

    def has_input(self, name: str) -> bool:
        return name in self._inputs

    def clear(self) -> None:
        """Forget every input and stage value (what the stages hold is released with them)."""
        self._inputs.clear()
        self._values.clear()
        self._provided_from.clear()
        self.pool.clear()


_MISSING = object()


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return a is b
    return bool(a == b)


@dataclass
class ImpulseParams:
    """Per-impulse band (section 4.1) of the impulses the later stages evaluate: those whose
    band is open (and, for ``imp_active``, whose neighbourhood is not flat) when skipping;
    every impulse without skipping, ``open_`` telling which have an open band."""

    index: np.ndarray  # into the Impulses arrays
    x_px: np.ndarray
    y_px: np.ndarray
    sigma_px: np.ndarray
    f_low_cpp: np.ndarray
    f_high_cpp: np.ndarray
    open_: np.ndarray  # bool: F_L < F_H
    level: np.ndarray  # the continuous Laplacian level l_a |L| is read at (eq. 8)

    def subset(self, keep: np.ndarray) -> ImpulseParams:
        return ImpulseParams(self.index[keep], self.x_px[keep], self.y_px[keep],
                             self.sigma_px[keep], self.f_low_cpp[keep], self.f_high_cpp[keep],
                             self.open_[keep], self.level[keep])


@dataclass
class EnhanceResult:
    """The output of one :meth:`Enhancer.enhance` call and access to every intermediate map.

    ``output`` has the input's channels: the alpha channel of an input that has one comes back
    unchanged as the last channel (the maps are colour only)."""

    output: np.ndarray
    params: EnhanceParams
    timings_s: dict[str, float]
    _enhancer: Enhancer = field(repr=False)
    _version: int = field(repr=False)

    def map(self, name: str) -> np.ndarray:
        """Full-resolution float32 map ``name`` (one of :data:`MAP_NAMES`), computed on demand.

        ``foveated``, ``contrast`` and ``output`` are display-encoded images in [0, 1];
        ``amplitude`` is K after clipping control (noise std = K / 6); ``orientation_rad``
        uses the release's convention (atan2(Gy, Gx) - pi/2, x right, y down); frequencies are
        in cycles/px and are left as computed where the band is empty (F_L >= F_H).
        """
        self._check_fresh()
        return self._enhancer._map(name)

    def linear(self, name: str) -> np.ndarray:
        """Linear-light ``foveated`` or ``contrast`` image (before noise and clipping)."""
        self._check_fresh()
        return self._enhancer.linear(name)

    def with_noise(self, noise: np.ndarray) -> np.ndarray:
        """The displayed frame with ``noise`` in place of this result's own noise layer: the
        linear contrast-enhanced image plus ``noise`` (linear luminance, (H, W), as
        ``map("noise")``) on every channel, clipped and encoded (section 4.5's composition),
        with the input's alpha channel back. Stereo (section 6.4) shows one eye's noise
        warped to the other eye this way. The method must be ``contrast`` or ``ours``."""
        self._check_fresh()
        enh = self._enhancer
        if self.params.method == "foveated":
            raise FovexpError("with_noise needs the contrast or ours method (foveated has no "
                              "contrast-enhanced image to add noise to)")
        lin = enh.linear("contrast")
        layer = np.asarray(noise)
        if layer.shape != lin.shape[:2]:
            raise FovexpError(f"noise has shape {layer.shape}, the image {lin.shape[:2]}")
        if not np.isfinite(layer).all():
            raise FovexpError("noise must be finite (no NaN or Inf)")
        return with_alpha(colour.encode(lin, enh._gamma(), enh.preset.transfer, layer),
                          enh._alpha)

    def _check_fresh(self) -> None:
        if self._version != self._enhancer._version:
            raise FovexpError("this result is stale: the enhancer has processed another frame")


@numba.njit(cache=True, fastmath=FASTMATH, nogil=True)
def _open_impulses(index, x_px, y_px, s_px, f_low_cpp, f_high_cpp, level, radius, bx, by,
                   reach, top):  # pragma: no cover - compiled
    """The :class:`ImpulseParams` fields of the impulses ``index`` (``x_px``, ``y_px``, and
    ``bx``, ``by`` when given: every impulse's; the others, sigma ``s_px`` included: those
    of ``index``) whose band is open (F_L < F_H), in one pass: NumPy's gathers and seven
    selections took 7.7 ms at 4K and 64 impulses (0.4 M), this pass 3.9.

    With ``radius`` (else of shape (0, 0)): of those, the ones whose |L| samples do not read
    only a constant region, :meth:`Enhancer._imp_active`'s rule: the constant radius of the
    impulse's block (``radius[by, bx]``) below ``reach`` at its bracketing level."""
    flat_rule = radius.shape[0] > 0
    n = index.shape[0]
    keep = np.empty(n, np.bool_)
    m = 0
    for i in range(n):
        ok = f_low_cpp[i] < f_high_cpp[i]
        if ok and flat_rule:
            k = index[i]
            ok = radius[by[k], bx[k]] < reach[amp.bracket(level[i], top)[0]]
        keep[i] = ok
        m += ok
    # one slot more than kept: each impulse is written, and the next kept one overwrites
    # the others (no branch in the loop)
    out_index = np.empty(m + 1, np.int64)
    x, y = np.empty(m + 1), np.empty(m + 1)
    s, lo, hi, lv = np.empty(m + 1), np.empty(m + 1), np.empty(m + 1), np.empty(m + 1)
    j = 0
    for i in range(n):
        k = index[i]
        out_index[j], x[j], y[j] = k, x_px[k], y_px[k]
        s[j], lo[j], hi[j], lv[j] = s_px[i], f_low_cpp[i], f_high_cpp[i], level[i]
        j += keep[i]
    return (out_index[:m], x[:m], y[:m], s[:m], lo[:m], hi[:m], np.ones(m, np.bool_),
            lv[:m])


#: :func:`_open_impulses` without the flat rule.
_NO_RULE = (np.zeros((0, 0), np.int32), np.zeros(0, np.int64), np.zeros(0, np.int64),
            np.zeros(1, np.int64), 1)


class _SigmaBlocks:
    """The sigma map (px, section 5.2) of one geometry, gaze and blur-rate, evaluated block by
    block as stages ask for blocks (:meth:`on`) and kept: the pixels evaluated are the whole
    map's, bit for bit, and a frame sequence with the same gaze evaluates each block once.
    :attr:`bound_px` bounds the whole map from above without evaluating it
    (:func:`fovexp.foveation.sigma_bound_px`). Float32, the ``exact`` geometry model."""

    def __init__(self, geom: ViewingGeometry, gaze, blur_rate: float, fovea_deg: float,
                 ppd_map: Callable[[], np.ndarray]) -> None:
        self._geom, self._gaze_px = geom, geom.gaze_px(gaze)
        self._blur_rate, self._fovea_deg = blur_rate, fovea_deg
        self._ppd_map = ppd_map  # the geometry's px/deg map, asked for with the first block
        self.bound_px = sigma_bound_px(geom, self._gaze_px, blur_rate, fovea_deg)
        self._sigma = np.zeros((0, 0), np.float32)  # allocated when first asked for
        self.done = np.zeros((0, 0), np.bool_)  # the blocks evaluated
        self._shift = -1

    def on(self, need: np.ndarray, shift: int) -> np.ndarray:
        """The map, evaluated (at least) on the ``2**shift`` px blocks ``need`` marks; not
        initialised where nothing asked for it yet, so a stage reads it only on the blocks
        it asked for (no zeros written first: one thread's 33 MB write at 4K, 4.9 ms of a
        three-quarters-flat frame; tests/enhancer/test_skipping.py fills the rest with NaN)."""
        if shift != self._shift or self.done.shape != need.shape:
            self._sigma = frame_empty(self._geom.shape, np.float32)
            self.done, self._shift = np.zeros(need.shape, np.bool_), shift
        todo = need & ~self.done
        if todo.any():
            sigma_on_blocks(self._geom, self._gaze_px, self._blur_rate, self._fovea_deg, todo,
                            shift, self._sigma, self._ppd_map())
            self.done |= todo
        return self._sigma


class _ImpulseBands:
    """F_L, F_H, sigma (section 4.1) and the Laplacian level (eq. 8) at the impulses, for one
    geometry, gaze, blur-rate and sigma map, evaluated for the impulses asked for
    (:meth:`at`) and kept: the values are those of evaluating every impulse (elementwise),
    and a frame sequence with the same gaze evaluates each impulse once."""

    def __init__(self, band_at: Callable[[np.ndarray, np.ndarray], tuple], x_px: np.ndarray,
                 y_px: np.ndarray) -> None:
        self._band_at, self._x, self._y = band_at, x_px, y_px
        self._values = tuple(np.empty(len(x_px)) for _ in range(4))
        self.done = np.zeros(len(x_px), dtype=np.bool_)

    def at(self, index: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(sigma_px, f_low_cpp, f_high_cpp, level)`` of the impulses ``index`` (float64)."""
        if not self.done.any() and len(index) == len(self.done):  # every impulse, at once
            values = self._band_at(self._x, self._y)
            for kept, v in zip(self._values, values, strict=True):
                kept[:] = v
            self.done[:] = True
            return values
        todo = index[~self.done[index]]
        if todo.size:
            for kept, v in zip(self._values, self._band_at(self._x[todo], self._y[todo]),
                               strict=True):
                kept[todo] = v
            self.done[todo] = True
        s, f_lo, f_hi, level = (v[index] for v in self._values)
        return s, f_lo, f_hi, level


class Enhancer:
    """Foveation simulation, contrast enhancement and noise enhancement of frames.

    One enhancer per display (and image size); it keeps the stages of the last frame so that
    a parameter change recomputes only what depends on it. ``options``
    (:class:`~fovexp.params.EngineOptions`) are the implementation choices, fixed for the
    enhancer's life.

    A 96 x 64 patch shown 25 deg right of the screen centre of the paper's display (a
    viewport of the 4K frame), gaze at the centre:

    >>> import numpy as np
    >>> from fovexp import Enhancer, load_display, make_params
    >>> yy, xx = np.mgrid[0:64, 0:96]
    >>> patch = (0.5 + 0.3 * np.sin(xx / 1.5) * np.cos(yy / 2.5)).astype(np.float32)
    >>> enh = Enhancer(load_display("lg-oled55cx"))
    >>> enh.set_image(patch, viewport=(2900, 1048, 3840, 2160))
    >>> res = enh.enhance((0.5, 0.5), make_params(blur_rate=0.57, impulses=12))
    >>> res.output.shape, res.output.dtype
    ((64, 96), dtype('float32'))
    >>> bool(res.map("sigma_px").min() > 0), bool(np.abs(res.map("noise")).max() > 0)
    (True, True)
    >>> step = enh.enhance((0.5, 0.5), res.params.model_copy(update={"s_k": 5.0}))
    >>> sorted(step.timings_s)  # a wheel step on s_k recomputes only what depends on it
    ['imp_amplitude', 'noise', 'output']
    """

    #: which implementation runs the stages ("cpu": NumPy/Numba; "gpu": fovexp.gpu)
    backend = "cpu"

    def __init__(
        self, display: Display, preset: str = "paper", geometry: GeometryModel | None = None,
        table: ParameterTable | None = None, options: EngineOptions | None = None,
    ) -> None:
        self.display = display
        self.preset: Preset = get_preset(preset)
        self.options: EngineOptions = options if options is not None else EngineOptions()
        if not isinstance(self.options, EngineOptions):
            raise FovexpError(f"options must be EngineOptions, not {type(options).__name__}")
        #: where the clipping control takes its extremes (the option, else the preset's rule)
        self.clipping: str = self.options.clipping or self.preset.clipping
        self._dtype = np.dtype(self.options.dtype).type
        if self.preset.name == "release" and geometry not in (None, "release"):
            raise FovexpError(
                f"the release preset has its own geometry; geometry {geometry!r} is for the paper"
            )
        self.geometry_model: GeometryModel = (
            "release" if self.preset.name == "release" else (geometry or self.preset.geometry)
        )
        self.table = table
        self._version = 0
        self._alpha: np.ndarray | None = None
        self._c = _StageCache()
        self._define_stages()
        retain_freed_memory()  # each frame's arrays in the last frame's pages (fovexp.memory)

    def _define_stages(self) -> None:
        c = self._c
        c.stage("geometry", ("shape", "viewport"), self._geometry)
        c.stage("linear", ("image",), self._linear)
        c.stage("grids", ("geometry", "gaze"), self._grids)
        # px/deg of every pixel (frame- and gaze-free: kept for the geometry), read by the
        # exact model's float32 sigma map
        c.stage("ppd_map", ("geometry",), self._ppd_map)
        c.stage("sigma", ("sigma_given", "?grids", "blur_rate", "geometry", "gaze", "?ppd_map"),
                self._sigma)
        c.stage("foveated", ("linear", "?sigma", "already_foveated", "?sigma_blocks"),
                self._foveated)
        # the luminance and, when skipping, its level-3 block extremes (where it is flat),
        # taken in the same pass
        c.stage("luma_and_blocks", ("foveated",), self._luma_and_blocks)
        c.stage("luma", ("luma_and_blocks",), lambda lb: lb[0])
        c.stage("luma_blocks", ("luma_and_blocks",), lambda lb: lb[1] if lb[1] is not None
                else tuple(e[..., 0] for e in pyramids.channel_block_extremes(
                    lb[0][..., None], FLAT_BLOCK_LEVEL)))
        # how far around each block the luminance is one constant (skipping only)
        c.stage("luma_flat", ("luma_blocks",), lambda b: pyramids.constant_radius_blocks(*b))
        c.stage("pyramid", ("luma", "?luma_flat", "?luma_blocks"), self._pyramid)
        c.stage("abs_laplacian", ("pyramid", "imp_active"), self._abs_laplacian)
        c.stage("abs_laplacian_full", ("pyramid",), lambda pyr: (
            pyramids.smoothed_abs_laplacian(pyr, len(pyr) - 1)))  # the maps'
        c.stage("gradients", ("pyramid",), lambda pyr: orientation.sobel_gradients(
            pyr[orientation.ORIENTATION_LEVEL]))
        # the sigma map's bound, and the map block by block as the stages that skip ask for it
        c.stage("sigma_blocks", ("geometry", "gaze", "blur_rate", "?ppd_map"), self._sigma_blocks)
        c.stage("contrast", ("luma", "?sigma", "f_e", "?luma_flat", "?sigma_blocks"),
                self._contrast)
        c.stage("headroom", ("foveated", "luma", "contrast", "?luma_blocks", "?luma_flat",
                             "?sigma", "?sigma_blocks"), self._headroom)
        c.stage("impulses", ("shape", "n_impulses", "seed"), self._impulses)
        # the band per impulse, evaluated for the impulses asked for and kept (frame-free)
        c.stage("imp_bands", ("impulses", "geometry", "gaze", "sigma_given", "blur_rate"),
                self._imp_bands)
        c.stage("imp_band", ("impulses", "imp_bands"), self._imp_band)
        c.stage("imp_blocks", ("impulses", "shape"), self._imp_blocks)
        c.stage("imp_active", ("impulses", "?imp_band", "?imp_bands", "?luma_flat", "imp_blocks",
                               "shape", "sigma_given", "?sigma_blocks"), self._imp_active)
        c.stage("imp_frequency", ("imp_active", "impulses", "s_f"), self._imp_frequency)
        c.stage("imp_laplacian", ("imp_active", "abs_laplacian"), lambda b, lap:
                amp.laplacian_amplitude_at(lap, b.level, b.x_px, b.y_px))
        c.stage("imp_headroom", ("imp_active", "headroom"), lambda b, hr:
                self._headroom_at(hr, b.x_px, b.y_px))
        c.stage("imp_amplitude", ("imp_active", "imp_laplacian", "imp_headroom", "s_k"),
                self._amplitude)
        c.stage("imp_orientation", ("imp_active", "gradients"), lambda b, g:
                orientation.orientation_at(g[0], g[1], b.x_px, b.y_px, dtype=self._dtype))
        c.stage("noise", ("shape", "impulses", "imp_active", "imp_amplitude", "imp_frequency",
                          "imp_orientation", "n_impulses"), self._noise)
        c.stage("output", ("method", "foveated", "?contrast", "?noise", "image",
                           "already_foveated"), self._compose)

    # ----------------------------------------------------------------------------- public API
    def set_image(
        self, image: np.ndarray, foveated: bool = False, sigma_px: np.ndarray | None = None,
        viewport: tuple[int, int, int, int] | None = None,
    ) -> None:
        """Set the frame: a full-resolution reference to foveate (default), or an already
        foveated frame described by the blur-rate (``foveated=True``) or a sigma map in px.

        ``image`` is display-encoded, float, in [0, 1], (H, W) or (H, W, 3); with an alpha
        channel, (H, W, 2) or (H, W, 4), the colour is processed and the alpha channel comes
        back in :attr:`EnhanceResult.output` unchanged (:func:`split_alpha`). It fills the
        screen, or, with ``viewport = (x0, y0, screen_width, screen_height)``, only that part
        of a full-screen frame (the gaze stays in the frame's normalised coordinates): the
        experiment runner enhances just the processed half of its split screen this way.
        """
        colour_in, alpha = split_alpha(image)
        img = _image_array(colour_in, "image")
        already_foveated = bool(foveated or sigma_px is not None)
        t0 = time.perf_counter()
        self._c.pool.next_frame()
        with self._c.pool.active():
            provided = self._checked_stages(img, already_foveated)
        provided_s = time.perf_counter() - t0
        if provided is None:
            _check_values(img, "image")
        img = img.astype(self._dtype, copy=False)
        if alpha is not None:
            alpha = check_image(alpha, "alpha channel")
        sigma_given = None
        if sigma_px is not None:
            sigma_given = np.asarray(sigma_px, dtype=self._dtype)
            if np.signbit(sigma_given).any():  # -0.0 is 0 (no blur): + 0.0 makes it +0.0
                sigma_given = sigma_given + self._dtype(0.0)
            if sigma_given.shape != img.shape[:2]:
                raise FovexpError(
                    f"sigma map has shape {sigma_given.shape}, the image {img.shape[:2]}"
                )
            if not np.isfinite(sigma_given).all() or float(sigma_given.min()) < 0:
                raise FovexpError("sigma map must be finite and non-negative (px)")
        if viewport is not None:
            x0, y0, sw, sh = (int(v) for v in viewport)
            viewport = (x0, y0, sw, sh)
            ViewingGeometry.for_image(self.display, img.shape[1], img.shape[0], "exact",
                                      viewport)  # validates it
        self._c.set(image=img, shape=img.shape[:2], sigma_given=sigma_given, viewport=viewport,
                    already_foveated=already_foveated)
        if provided is not None and not self._c.cached("linear"):  # a new frame
            for name, value in provided.items():  # the pass's time is the linear stage's
                self._c.provide(name, value, provided_s if name == "linear" else 0.0,
                                ("image", "already_foveated"))
        self._alpha = alpha  # no stage depends on it
        self._version += 1

    def enhance(
        self, gaze: tuple[float, float] = (0.5, 0.5), params: EnhanceParams | None = None,
        image: np.ndarray | None = None,
    ) -> EnhanceResult:
        """Process the current frame (or ``image``, set first) for ``gaze`` and ``params``."""
        params = self._prepare(gaze, params, image)
        out = with_alpha(self._output(), self._alpha)
        return EnhanceResult(out, params, dict(self._c.timings_s), self, self._version)

    def _prepare(
        self, gaze: tuple[float, float], params: EnhanceParams | None, image: np.ndarray | None,
    ) -> EnhanceParams:
        """:meth:`enhance` up to the output: the frame, gaze and parameters checked and set on
        the stage graph (nothing computed yet); the resolved parameters."""
        if image is not None:
            self.set_image(image)
        if not self._c.has_input("image"):
            raise FovexpError("no image: call set_image() first")
        params = (params or EnhanceParams(preset=self.preset.name)).resolved(self.table)
        if params.preset != self.preset.name:
            raise FovexpError(
                f"params are for preset {params.preset!r}, this enhancer is {self.preset.name!r}"
            )
        gaze_t = (float(gaze[0]), float(gaze[1]))
        self._c.get("geometry").gaze_px(gaze_t)  # validates the gaze
        self._c.start_timing()
        self._c.set(
            gaze=gaze_t, blur_rate=params.blur_rate, f_e=params.f_e, s_k=params.s_k,
            s_f=params.s_f, n_impulses=params.impulses, seed=params.seed, method=params.method,
        )
        self._version += 1
        return params

    def _output(self) -> np.ndarray:
        return self._c.get("output")

    # ------------------------------------------------------------------------------- stages
    def _geometry(self, shape: tuple[int, int], viewport) -> ViewingGeometry:
        return ViewingGeometry.for_image(self.display, shape[1], shape[0], self.geometry_model,
                                         viewport)

    def _gamma(self) -> float:
        return 2.2 if self.preset.transfer == "release" else self.display.gamma

    def _linear(self, image: np.ndarray) -> np.ndarray:
        return colour.linearize(image, self._gamma(), self.preset.transfer, self._dtype)

    def _checked_stages(self, image: np.ndarray, already_foveated: bool) -> dict[str, Any] | None:
        """The stages of a frame being set that are taken in the pass that checks its values,
        the same numbers as the stages compute: ``linear``
        (:func:`fovexp.colour.linearize_checked`) and, of an already-foveated RGB frame
        (whose luminance is its linearisation's), ``luma_and_blocks`` too
        (:func:`fovexp.colour.linearize_luminance_checked`). None where the values need
        :func:`check_image`'s own check (one out of [+0, 1]) or the frame is not float32 in
        one block for a float32 engine. The GPU backend linearises on the GPU: None."""
        if (self._dtype != np.float32 or image.dtype != np.float32
                or not image.flags.c_contiguous or not image.size):
            return None
        gamma, transfer = self._gamma(), self.preset.transfer
        if not already_foveated or image.ndim != 3:
            linear = colour.linearize_checked(image, gamma, transfer)
            return None if linear is None else {"linear": linear}
        taken = colour.linearize_luminance_checked(image, gamma, transfer, FLAT_BLOCK_LEVEL)
        if taken is None:
            return None
        linear, *luma_and_blocks = taken
        return {"linear": linear, "luma_and_blocks": self._luma_value(*luma_and_blocks)}

    def _encode(self, linear: np.ndarray) -> np.ndarray:
        return colour.encode(linear, self._gamma(), self.preset.transfer)

    def _grids(self, geom: ViewingGeometry, gaze) -> tuple[np.ndarray, np.ndarray]:
        """Eccentricity and px/deg of every pixel, maps of the engine's float type."""
        return geom.eccentricity_and_ppd_maps(geom.gaze_px(gaze), self._dtype)

    def _ppd_map(self, geom: ViewingGeometry) -> np.ndarray:
        """px/deg of every pixel (float32; :meth:`~fovexp.geometry.ViewingGeometry.ppd_map`)."""
        return geom.ppd_map()

    def _sigma(self, given, grids, blur_rate, geom: ViewingGeometry, gaze, ppd_map) -> np.ndarray:
        """The sigma map (px, section 5.2): the one given with the frame, else in float32 with
        the exact geometry in one pass (:func:`fovexp.foveation.sigma_on_blocks`, with the
        geometry's kept px/deg), else from the eccentricity and px/deg maps (computed only
        then)."""
        if given is not None:
            return given
        if self._dtype == np.float32 and geom.model == "exact":
            return sigma_on_blocks(geom, geom.gaze_px(gaze), blur_rate, self.preset.fovea_deg,
                                   ppd_map=ppd_map())
        ecc, ppd = grids()
        return sigma_px(ecc, ppd, blur_rate, self.preset.fovea_deg, self._dtype)

    def _luma_and_blocks(
        self, foveated: np.ndarray,
    ) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray] | None]:
        """The luminance the method works on (section 4.5) and, when skipping, its level-3
        block extremes, in one pass (:func:`fovexp.colour.luminance_and_block_extremes`)."""
        if not self.options.skip:
            return colour.luminance(foveated), None
        return self._luma_value(*colour.luminance_and_block_extremes(foveated, FLAT_BLOCK_LEVEL))

    def _luma_value(self, luma: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple:
        """The ``luma_and_blocks`` stage's value: the luminance and, when skipping (which
        alone reads them), its block extremes."""
        return luma, (lo, hi) if self.options.skip else None

    def _foveated(self, linear, sigma, already_foveated, sigma_blocks) -> np.ndarray:
        if already_foveated:
            return linear
        if self.options.foveation == "exact":
            return foveate_exact(linear, sigma())
        # the blur stack covers sigmas up to the map's bound, with skipping and without
        blocks = sigma_blocks()
        source = self._sigma_source(sigma, sigma_blocks) if self.options.skip else sigma()
        return foveate(linear, source, skip=self.options.skip, max_sigma_px=blocks.bound_px)

    def _pyramid(self, luma, luma_flat, luma_blocks) -> list[np.ndarray]:
        """The luminance's Gaussian pyramid (section 4.2); when skipping, its first level
        takes the blocks where the luminance is one constant as that constant, unread (the
        same numbers: :func:`fovexp.pyramids.reduce`)."""
        constant = None
        if self.options.skip:
            constant = (luma_flat(), luma_blocks()[0], pyramids.level_scale(FLAT_BLOCK_LEVEL))
        return pyramids.gaussian_pyramid(luma, amp.MAX_LAPLACIAN_LEVEL, constant=constant)

    def _abs_laplacian(self, pyr: list[np.ndarray], active: ImpulseParams) -> dict[int, np.ndarray]:
        """|L_k| of every level (section 4.2); when skipping, only on the tiles the active
        impulses' samples read (:func:`_laplacian_need`), the others not written: only
        ``imp_laplacian`` reads this stage, at those impulses (the maps have
        ``abs_laplacian_full``)."""
        top = len(pyr) - 1
        need = self._laplacian_need(pyr, active) if self.options.skip else None
        return pyramids.smoothed_abs_laplacian(pyr, top, need, zero_rest=False)

    def _laplacian_need(self, pyr, active: ImpulseParams) -> dict[int, np.ndarray]:
        """Per level k, the tiles of |L_k| that the imp_laplacian stage reads at the active
        impulses: the bilinear taps (one more node each side, as a margin) of levels k0 and
        k0 + 1 (:func:`fovexp.amplitude.bracketing_levels`,
        :func:`fovexp.pyramids.tiles_of_taps`)."""
        top = min(amp.MAX_LAPLACIAN_LEVEL, len(pyr) - 1)
        k0, _ = amp.bracketing_levels(active.level, max(top, 1))
        return pyramids.tiles_of_taps(active.x_px, active.y_px, k0, pyr, top)

    def _contrast(self, luma, sigma, f_e, luma_flat, sigma_blocks) -> WrittenRows:
        """The change of luminance the contrast enhancement makes (grey, linear). The method
        processes luminance only (section 4.5): like the noise, this change is added to
        every channel of the foveated image. Skipping leaves out the blocks whose boxes are
        flat (the change is exactly 0 there), and asks for the sigma map only on the others
        (:meth:`_sigma_source`); their zeros are not written, outside each row's first and
        last block computed (:class:`fovexp.memory.WrittenRows`: the output reads each row
        on its span, the maps ask for the whole)."""
        if not self.options.skip:
            return contrast_change(luma, sigma(), f_e, written=True)
        source = self._sigma_source(sigma, sigma_blocks)
        if not callable(source):
            return contrast_change(luma, source, f_e, luma_flat(), written=True)
        return contrast_change_where_needed(luma, source, sigma_blocks().bound_px, f_e,
                                            luma_flat(), written=True)

    def _sigma_source(self, sigma, sigma_blocks) -> np.ndarray | SigmaOnBlocks:
        """The sigma map for a stage that skips flat blocks: the whole map when it is given,
        already computed, or in float64 or a constant-ppd model; else evaluated block by
        block as the stages ask (:class:`_SigmaBlocks`)."""
        c = self._c
        if (c.get("sigma_given") is not None or c.cached("sigma")
                or self._dtype != np.float32 or c.get("geometry").model != "exact"):
            return sigma()
        return sigma_blocks().on

    def _sigma_blocks(self, geom: ViewingGeometry, gaze, blur_rate: float,
                      ppd_map: Callable[[], np.ndarray]) -> _SigmaBlocks:
        return _SigmaBlocks(geom, gaze, blur_rate, self.preset.fovea_deg, ppd_map)

    def _headroom(self, foveated, luma, delta, luma_blocks, luma_flat, sigma,
                  sigma_blocks) -> amp.Extremes:
        """N_min and N_max of the image the noise is added to (section 4.2), under
        :attr:`clipping` (:func:`fovexp.amplitude.clipping_extremes`; docs/METHOD.md, 6.6).
        When skipping, the paper's rule does not read the blocks the contrast left as they
        were: their luminance is one constant (the luminance's block extremes) and the
        change +0.0 there."""
        p = self.preset
        known = None
        if self.options.skip and self.clipping == "paper" and p.minmax_level == FLAT_BLOCK_LEVEL:
            known = (self._unchanged_by_contrast(luma_flat, sigma, sigma_blocks), *luma_blocks())
        # the paper's rule reads the change on the blocks it does not know only, which the
        # contrast wrote; the others read all of it
        change = delta.values if known is not None else delta.full()
        return amp.clipping_extremes(self.clipping, foveated, luma, change,
                                     kernel_radius_px=self._kernel_radius_px(),
                                     level=p.minmax_level, box_px=p.minmax_box_px, known=known)

    def _unchanged_by_contrast(self, luma_flat, sigma, sigma_blocks) -> np.ndarray:
        """The level-3 blocks :meth:`_contrast` left out when skipping (its change is +0.0
        there): :func:`fovexp.contrast.unchanged_blocks` at the largest sigma it took, the
        map's maximum or the bound it was asked for by blocks with."""
        source = self._sigma_source(sigma, sigma_blocks)
        if callable(source):
            largest = sigma_blocks().bound_px
        else:
            largest = float(source.max()) if source.size else 0.0
        return unchanged_blocks(luma_flat(), largest)

    def _kernel_radius_px(self) -> float:
        """The Gabor kernel's truncation radius (section 4.4; the option's truncation)."""
        return gabor.kernel_radius_px(self.preset.gabor_a_cpp, self.options.kernel_truncation)

    def _impulses(self, shape, n, seed) -> gabor.Impulses:
        o = self.options
        return gabor.generate_impulses(shape[1], shape[0], n, self.preset.gabor_a_cpp, seed,
                                       o.impulse_count, o.weights, o.cell_scale)

    def _band_at(self, geom, gaze, sigma_given, blur_rate, x, y):
        """Sigma, F_L and F_H at points (section 4.1): sigma exactly from the geometry when
        the foveation is simulated here, else sampled from the given sigma map."""
        ecc = geom.eccentricity_deg(x, y, geom.gaze_px(gaze))
        ppd = geom.ppd(x, y)
        if sigma_given is None:
            s = sigma_px(ecc, ppd, blur_rate, self.preset.fovea_deg, self._dtype)
            s = s.astype(np.float64)
        else:
            s = pyramids.sample_bilinear(sigma_given, x, y, 0).astype(np.float64)
        f_lo, f_hi = frequency.frequency_band_cpp(ecc, ppd, s)
        return s, f_lo, f_hi

    def _imp_bands(self, imp, geom, gaze, sigma_given, blur_rate) -> _ImpulseBands:
        # impulses whose kernel cannot reach the image are dropped with the others; the
        # Laplacian level (eq. 8) with the band, in the same parts
        def band_at(x, y):
            s, f_lo, f_hi = self._band_at(geom, gaze, sigma_given, blur_rate, x, y)
            return s, f_lo, f_hi, amp.laplacian_level(s, self.preset.attenuation)

        # in parts on threads, but for a given map: its sampling is a parallel kernel itself
        return _ImpulseBands(
            band_at if sigma_given is not None else (lambda x, y: over_points(band_at, x, y)),
            np.clip(imp.x_px, 0, geom.width_px - 1), np.clip(imp.y_px, 0, geom.height_px - 1))

    def _imp_band(self, imp, bands: _ImpulseBands) -> ImpulseParams:
        """The band at every impulse (section 4.1); when skipping, only the impulses whose
        band is open are kept (the others have no noise)."""
        index = np.arange(len(imp))
        return self._band_params(imp, index, *bands.at(index))

    def _band_params(self, imp, index, s, f_lo, f_hi, level) -> ImpulseParams:
        """:class:`ImpulseParams` of the impulses ``index``; when skipping, of those whose band
        is open (:func:`_open_impulses`)."""
        if self.options.skip:
            return ImpulseParams(*_open_impulses(index, imp.x_px, imp.y_px, s, f_lo, f_hi,
                                                 level, *_NO_RULE))
        return ImpulseParams(index, imp.x_px[index], imp.y_px[index], s, f_lo, f_hi,
                             f_lo < f_hi, level)

    def _imp_active(self, imp, band, bands, luma_flat, imp_blocks, shape, sigma_given,
                    sigma_blocks) -> ImpulseParams:
        """The impulses the amplitude, frequency and orientation are evaluated at. When
        skipping, those whose |L| samples read only a constant region of the luminance are
        left out: |L| is exactly 0 there, and so is K (section 4.2;
        :func:`fovexp.amplitude.laplacian_reach_px`). Judged on the level-3 blocks' constant
        radius (:func:`fovexp.pyramids.constant_radius_blocks`): first at the reach of the
        largest sigma the frame can have (its bound), before the band is evaluated at all (a
        block constant that far is constant nearer), then at each impulse's own level."""
        if not self.options.skip:
            return band()
        radius = luma_flat()
        top = max(min(amp.MAX_LAPLACIAN_LEVEL, pyramids.pyramid_depth(shape, 99)), 1)
        # per bracketing level k0, the block radius its |L| samples reach
        reach = np.asarray(pyramids.blocks_reaching(
            amp.laplacian_reach_px(np.arange(top + 1), top),
            pyramids.level_scale(FLAT_BLOCK_LEVEL)))
        if radius.max() < reach.min():  # nothing flat at the smallest reach: nothing is
            return band()
        bx, by = imp_blocks
        bound = (float(sigma_given.max()) if sigma_given is not None
                 else sigma_blocks().bound_px)
        k0_max, _ = amp.bracketing_levels(
            amp.laplacian_level(np.array([bound]), self.preset.attenuation), top)
        index = np.flatnonzero(radius[by, bx] < reach[k0_max[0]])
        # the open ones, then at each impulse's own level, in one pass
        s, f_lo, f_hi, level = bands().at(index)
        return ImpulseParams(*_open_impulses(index, imp.x_px, imp.y_px, s, f_lo, f_hi, level,
                                             radius, bx, by, reach, top))

    def _imp_blocks(self, imp, shape) -> tuple[np.ndarray, np.ndarray]:
        """The level-3 block (column, row) of each impulse, clamped to the image (frame-free:
        kept across a sequence's frames)."""
        block = pyramids.level_scale(FLAT_BLOCK_LEVEL)
        return (np.clip(imp.x_px, 0, shape[1] - 1).astype(np.int64) // block,
                np.clip(imp.y_px, 0, shape[0] - 1).astype(np.int64) // block)

    def _imp_frequency(self, band: ImpulseParams, imp, s_f: float) -> np.ndarray:
        """The per-impulse frequency draw (section 4.1) where the band is open; 0 elsewhere
        (no noise there)."""
        f = np.zeros(len(band.index))
        o = band.open_
        if self.preset.frequency_draw == "truncated":
            def draw(f_lo, f_hi, u):
                return frequency.draw_truncated(
                    u, *frequency.lognormal_params(f_lo, f_hi, s_f), f_hi)

            f[o] = over_points(draw, band.f_low_cpp[o], band.f_high_cpp[o],
                               imp.quantile[band.index[o]])
            return f
        mu, sig_n = frequency.lognormal_params(band.f_low_cpp[o], band.f_high_cpp[o], s_f)
        rng = np.random.default_rng(imp.seed)
        normals = rng.standard_normal((len(imp), frequency.RELEASE_REJECTION_TRIES))
        f[o] = frequency.draw_release(normals[band.index[o]], mu, sig_n, band.f_high_cpp[o])
        return f

    def _headroom_at(self, headroom: amp.Extremes, x, y) -> np.ndarray:
        return amp.headroom_at(headroom, self._kernel_radius_px(), x, y)

    def _amplitude(self, band: ImpulseParams, lap_amp, limit, s_k) -> np.ndarray:
        """K (eq. 9, with the release's gain), reduced by the clipping control; 0 where the
        band is closed."""
        k = np.minimum(s_k * amp.RELEASE_AMPLITUDE_GAIN * lap_amp, limit)
        return np.where(band.open_, k, 0.0)

    def _noise(self, shape, imp, band, k, f, omega, n) -> WrittenRows:
        # the band's impulses' values as they are (no scatter into every impulse's); written
        # only on the columns each row's kernels span (fovexp.memory.WrittenRows)
        return gabor.synthesize(shape, imp, k, f, omega - 0.5 * np.pi, n, self.preset.gabor_a_cpp,
                                self.options.kernel_truncation, self.options.skip, self._dtype,
                                index=band.index, written=True)

    def _compose(self, method, foveated, contrast, noise, image, already_foveated) -> np.ndarray:
        """The displayed frame: the grey contrast change and noise are added to every channel
        of the linear foveated image, then encoded (section 4.5); values outside [0, 1] clip.
        A pixel of an already-foveated frame that nothing changes is the frame's own
        (:func:`fovexp.colour.encode`'s ``unchanged``)."""
        grey = () if method == "foveated" else (contrast(),) if method == "contrast" else (
            contrast(), noise())
        return colour.encode(foveated, self._gamma(), self.preset.transfer, *grey,
                             unchanged=image if already_foveated else None)

    # ------------------------------------------------------------------------------- maps
    def linear(self, name: str) -> np.ndarray:
        """Linear-light ``foveated`` or ``contrast`` image of the current frame (before the
        noise and before any clipping)."""
        if name not in ("foveated", "contrast"):
            raise FovexpError(f"no linear image {name!r} (choose foveated or contrast)")
        return self._linear_image(name)

    def _map(self, name: str) -> np.ndarray:
        """:meth:`EnhanceResult.map`: what each map is, for every backend; the backend reads
        its data with :meth:`_read_map` (and :meth:`_output`, :meth:`_linear_image`)."""
        if name not in MAP_NAMES:
            raise FovexpError(f"unknown map {name!r} (choose from {', '.join(MAP_NAMES)})")
        if name == "output":
            return self._output()
        if name in ("foveated", "contrast"):
            if not self._c.get("already_foveated"):
                return self._encode(self._linear_image(name))
            # as the output stage composes them: the frame's own pixels where nothing changes
            grey = (self._contrast_change(),) if name == "contrast" else ()
            return colour.encode(self._linear_image("foveated"), self._gamma(),
                                 self.preset.transfer, *grey, unchanged=self._c.get("image"))
        if name in ("noise", "amplitude") and self._c.get("method") != "ours":
            return np.zeros(self._c.get("shape"), self._dtype)  # no noise: K = 0 everywhere
        return self._read_map(name)

    # The read hooks: each backend supplies these four.
    def _linear_image(self, name: str) -> np.ndarray:
        """The linear ``foveated`` image, or ``contrast`` (foveated + the grey change)."""
        foveated = self._c.get("foveated")
        if name == "foveated":
            return foveated
        delta = self._contrast_change()
        return foveated + (delta[..., None] if foveated.ndim == 3 else delta)

    def _contrast_change(self) -> np.ndarray:
        """The contrast's grey change of linear luminance, (H, W)."""
        return self._c.get("contrast").full()

    def _read_map(self, name: str) -> np.ndarray:
        """Map ``name`` of :data:`POINT_MAPS`, ``sigma_px`` or ``noise`` (the method is
        ``ours`` for ``noise`` and ``amplitude``), float32 (H, W)."""
        c = self._c
        if name == "eccentricity_deg":
            return c.get("grids")[0]
        if name == "sigma_px":
            return c.get("sigma")
        if name == "noise":
            return c.get("noise").full()
        geom = c.get("geometry")
        h, w = geom.shape
        yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
        x, y = xx.ravel(), yy.ravel()
        if name == "orientation_rad":
            gx, gy = c.get("gradients")
            return orientation.orientation_at(gx, gy, x, y, dtype=self._dtype).reshape(h, w)
        s, f_lo, f_hi = self._band_at(geom, c.get("gaze"), c.get("sigma_given"),
                                      c.get("blur_rate"), x, y)
        if name == "f_low_cpp":
            # +Inf where the blur removes nothing at this precision (sigma = 0, or so small
            # that 3 / (2 pi sigma) overflows float32): the band is empty there either way
            with np.errstate(over="ignore"):
                return f_lo.reshape(h, w).astype(self._dtype)
        if name == "f_high_cpp":
            return f_hi.reshape(h, w).astype(self._dtype)
        # amplitude, with the method "ours" (Enhancer._map)
        lap = c.get("abs_laplacian_full" if self.options.skip else "abs_laplacian")
        limit = amp.headroom_at(c.get("headroom"), self._kernel_radius_px(),
                                shape=(h, w)).ravel()
        level = amp.laplacian_level(s, self.preset.attenuation)
        pixels = ImpulseParams(np.arange(x.size), x, y, s, f_lo, f_hi, f_lo < f_hi, level)
        k = self._amplitude(pixels, amp.laplacian_amplitude_at(lap, level, x, y), limit,
                            c.get("s_k"))
        return k.reshape(h, w).astype(self._dtype)


def enhance(
    image: np.ndarray, display: Display, gaze: tuple[float, float] = (0.5, 0.5),
    params: EnhanceParams | None = None, preset: str | None = None,
) -> EnhanceResult:
    """One-shot convenience: foveate ``image`` and enhance it (see :class:`Enhancer`).

    >>> import numpy as np
    >>> from fovexp import enhance, load_display, make_params
    >>> grey = np.full((27, 48), 0.5, dtype=np.float32)
    >>> res = enhance(grey, load_display("lg-oled55cx"), params=make_params(method="contrast"))
    >>> # nothing to enhance on a flat image: the grey back, to the float32 rounding of the
    >>> # transfer function's round trip (NumPy's vectorised power differs by CPU)
    >>> bool(np.abs(res.output - grey).max() <= 2e-6)
    True
    """
    params = params or EnhanceParams()
    enh = Enhancer(display, preset=preset or params.preset)
    enh.set_image(image)
    return enh.enhance(gaze, params)
