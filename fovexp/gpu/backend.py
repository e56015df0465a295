"""The GPU backend: :class:`GpuEnhancer`, the pipeline's stages as OpenGL 4.5 compute shaders.

It is a :class:`fovexp.Enhancer` (same ``set_image`` / ``enhance`` / ``EnhanceResult``, and a
stage cache of the same kind: a wheel step recomputes only the stages the changed parameter
invalidates) whose stages dispatch the entries of ``shaders/<stage>.glsl`` instead of
NumPy/Numba code. Its stage graph differs in one place: the CPU's six per-impulse stages
(band, frequency, |L| sample, headroom sample, amplitude, orientation) are one ``imp_params``
dispatch, so an s_f or s_k step recomputes every per-impulse parameter (one invocation per
impulse: cheap next to the noise synthesis that follows either way). Every stage
keeps its result in GPU buffers; only the finished frame (and any map asked for) is read
back, besides one 4-byte read of the largest sigma when the gaze or the blur-rate changes (it
sizes the blur stack). What is not per-pixel work stays in Python and is shared with the CPU
backend: the viewing geometry's constants, the blur-stack plan, the impulses (generated once
per image size, impulse count and seed) and the noise normalisation.

The backend implements the ``paper`` preset; the ``release`` preset (kept to compare with the
authors' prototype) runs on the CPU backend. A context is used from the thread that created
it: create the enhancer on the thread that renders.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import gabor
from ..amplitude import MAX_LAPLACIAN_LEVEL
from ..contrast import check_sat_fits, sat_pad_px
from ..errors import FovexpError
from ..foveation import blur_stack_plan, sigma_bound_px
from ..geometry import Display, GeometryModel, ViewingGeometry
from ..orientation import ORIENTATION_LEVEL
from ..params import EngineOptions, ParameterTable, get_preset
from ..pipeline import POINT_MAPS, Enhancer, EnhanceResult
from ..pyramids import level_scale
from .programs import (
    BINDINGS,
    GEOMETRY_MODELS,
    IMPULSE_FIELDS,
    LOCAL_1D,
    LOCAL_2D,
    create_context,
    drop_user,
    made_current,
    programs_for,
    release_context,
    renderer_name,
)

_F4 = 4  # bytes per float32


@dataclass(frozen=True)
class _Grid:
    """One level of a packed pyramid: ``offset`` in values (floats) into its buffer."""

    offset: int
    height: int
    width: int


@dataclass(frozen=True)
class _GpuImpulses:
    impulses: gabor.Impulses
    order: np.ndarray  # GPU record i is impulse order[i] of ``impulses``
    cells_xy: tuple[int, int]
    count: int


#: GpuEnhancer's ``profile`` values
PROFILE_MODES: tuple[Any, ...] = (False, True, "wall", "gpu")
#: the timing methods (GpuEnhancer.timing_method)
GL_TIMER_PER_DISPATCH = "GL_TIME_ELAPSED per dispatch"
WALL_PER_DISPATCH = "wall clock per dispatch, glFinish after each"
WALL_PER_STAGE = "wall clock per stage, glFinish after each"


class _DispatchTimer:
    """``profile="gpu"``: each dispatch timed by a GL timer query (GL_TIME_ELAPSED, from the
    dispatch's start to its end on the GPU: the GPU waits for nothing else in between), or,
    where the driver's query is unusable, by the wall clock between a glFinish before and one
    after. :meth:`clock` is the running sum, which the stage cache times its stages with."""

    def __init__(self, ctx: Any, query: Any, method: str) -> None:
        self.ctx, self.query, self.method = ctx, query, method
        self.total_s = 0.0
        self.entries_s: dict[str, float] = {}
        self.counts: dict[str, int] = {}

    @classmethod
    def for_context(cls, ctx: Any, programs: Any) -> _DispatchTimer:
        """A timer that uses the query where a probe dispatch shows it usable (the context
        must be current): a 1024 x 1024 RGB colour.glsl LINEARIZE, timed both ways."""
        n = 1024
        bufs = [ctx.buffer(reserve=n * n * 3 * _F4) for _ in range(2)]
        try:
            query = ctx.query(time=True)
            prog = programs.get("colour.glsl", "LINEARIZE")
            for name, buf in zip(("IMAGE", "LINEAR"), bufs, strict=True):
                buf.bind_to_storage_buffer(BINDINGS[name])
            prog["image_hwc"].value, prog["gamma"].value = (n, n, 3), 2.2
            groups = (n // LOCAL_2D[0], n // LOCAL_2D[1], 1)
            ctx.finish()
            t0 = time.perf_counter()
            with query:
                prog.run(*groups)
            gpu_s = query.elapsed * 1e-9
            ctx.finish()
            wall_s = time.perf_counter() - t0
        except Exception as exc:  # moderngl.Error: no timer queries on this context
            return cls(ctx, None, f"{WALL_PER_DISPATCH} (no GL timer query: {exc})")
        finally:
            for buf in bufs:
                buf.release()
        # a dispatch that kept the CPU waiting 1 ms or more shows at least 1 % of it on the
        # GPU's clock; llvmpipe reports 1 ns for anything
        if gpu_s > 0.0 and (gpu_s >= 0.01 * wall_s or wall_s < 1e-3):
            return cls(ctx, query, GL_TIMER_PER_DISPATCH)
        return cls(ctx, None, f"{WALL_PER_DISPATCH} (the driver's GL_TIME_ELAPSED gave "
                              f"{gpu_s * 1e9:.0f} ns for a dispatch that took "
                              f"{wall_s * 1e3:.1f} ms: unusable)")

    def run(self, prog: Any, groups: tuple[int, ...], entry: str) -> None:
        if self.query is not None:
            with self.query:
                prog.run(*groups)
            dt = self.query.elapsed * 1e-9  # waits for the dispatch's result
        else:
            self.ctx.finish()
            t0 = time.perf_counter()
            prog.run(*groups)
            self.ctx.finish()
            dt = time.perf_counter() - t0
        self.total_s += dt
        self.entries_s[entry] = self.entries_s.get(entry, 0.0) + dt
        self.counts[entry] = self.counts.get(entry, 0) + 1

    def clock(self) -> float:
        return self.total_s


class GpuEnhancer(Enhancer):
    """:class:`fovexp.Enhancer` on the GPU (OpenGL 4.5 compute shaders through moderngl).

    ``ctx``: a moderngl context to run in (e.g. a window's, from ``moderngl.create_context()``);
    by default a standalone one through EGL. ``profile`` sets what ``EnhanceResult.timings_s``
    holds (otherwise the times of submitting the work; the frame read-back waits for all of
    it): ``True`` or ``"wall"``, each stage's wall-clock time with a glFinish after it;
    ``"gpu"``, each stage's GPU time, the sum of its dispatches' GL timer queries
    (GL_TIME_ELAPSED, one per dispatch; transfers are not dispatches and count 0), also per
    compute entry in :attr:`dispatch_timings_s`. Where the driver's timer query is unusable
    (Mesa llvmpipe reports 1 ns for any dispatch) ``"gpu"`` times each dispatch by the wall
    clock to a glFinish instead; :attr:`timing_method` says which, and why.

    :meth:`close` (or a ``with`` block) releases its GPU buffers, and the context when the
    enhancer created it; a closed enhancer refuses every call.
    """

    backend = "gpu"
    #: The :class:`EngineOptions` this backend implements other than at their defaults.
    SUPPORTED_OPTIONS: frozenset[str] = frozenset({"skip", "clipping"})
    #: The clipping rules (``EngineOptions.clipping``) its shaders implement.
    SUPPORTED_CLIPPING: frozenset[str] = frozenset({"paper", "widened"})

    @classmethod
    def unsupported(cls, options: EngineOptions) -> dict[str, object]:
        """The options (name: value) this backend does not implement."""
        bad = {k: v for k, v in options.non_default().items() if k not in cls.SUPPORTED_OPTIONS}
        if options.clipping is not None and options.clipping not in cls.SUPPORTED_CLIPPING:
            bad["clipping"] = options.clipping
        return bad

    def __init__(
        self, display: Display, preset: str = "paper", geometry: GeometryModel | None = None,
        table: ParameterTable | None = None, ctx: Any = None, profile: bool | str = False,
        owns_context: bool | None = None, options: EngineOptions | None = None,
    ) -> None:
        if profile not in PROFILE_MODES:
            raise FovexpError(f"profile must be one of {', '.join(map(repr, PROFILE_MODES))}, "
                              f"not {profile!r}")
        if get_preset(preset).name != "paper":
            raise FovexpError(
                f"the GPU backend implements the paper preset, not {preset!r}: the release "
                "preset runs on the CPU backend (backend='cpu')"
            )
        bad = self.unsupported(options or EngineOptions())
        if bad:
            name, value = next(iter(bad.items()))
            raise FovexpError(
                f"the GPU backend does not implement the engine option {name}={value!r}: it "
                "runs on the CPU backend (backend='cpu')"
            )
        #: release the context in close() (default: when this enhancer created it)
        self._owns_context = ctx is None if owns_context is None else owns_context
        self._closed = False
        self._buffers: dict[str, Any] = {}
        self._programs = None
        #: how EnhanceResult.timings_s is measured (None: submission times, no waiting)
        self.timing_method: str | None = None
        self._timer: _DispatchTimer | None = None
        self.ctx = create_context(ctx)
        try:
            self.renderer = renderer_name(self.ctx)
            #: None, "wall" (glFinish after each stage) or "gpu" (each dispatch timed)
            self.profile: str | None = {False: None, True: "wall"}.get(profile, profile)
            self._programs = programs_for(self.ctx, self)
            self._max_block_bytes = int(
                self.ctx.info.get("GL_MAX_SHADER_STORAGE_BLOCK_SIZE") or 2**27)
            self._max_groups = self._programs.max_groups_xyz
            with made_current(self.ctx):
                # every entry now: a driver that cannot compile one fails here, not mid-session
                self._programs.compile_all()
                if self.profile == "gpu":
                    self._timer = _DispatchTimer.for_context(self.ctx, self._programs)
            super().__init__(display, preset, geometry, table, options)
            if self._timer is not None:
                self._c.clock = self._timer.clock
                self.timing_method = self._timer.method
            elif self.profile == "wall":
                self.timing_method = WALL_PER_STAGE
        except BaseException:
            self.close()
            raise

    # Every public method that touches the GPU makes this enhancer's context current for its
    # duration (and then the one current before, if any): several enhancers (contexts) may
    # share a thread, and a caller's own context stays current across a call.
    def _check_open(self) -> None:
        if self._closed:
            raise FovexpError("this GPU enhancer has been closed")

    def _current(self) -> Any:
        """A ``with`` block with this enhancer's context current; refused once it is closed."""
        self._check_open()
        return made_current(self.ctx)

    def set_image(self, *args: Any, **kwargs: Any) -> None:  # noqa: D102 - Enhancer.set_image
        self._check_open()
        super().set_image(*args, **kwargs)

    set_image.__doc__ = Enhancer.set_image.__doc__

    def _checked_stages(self, image: np.ndarray, already_foveated: bool) -> None:
        return None  # linearised on the GPU (the "linear" stage): the values checked apart

    def enhance(self, *args: Any, **kwargs: Any) -> EnhanceResult:  # noqa: D102
        with self._current():
            if self._timer is not None:
                self._timer.entries_s.clear()
                self._timer.counts.clear()
            return super().enhance(*args, **kwargs)

    enhance.__doc__ = Enhancer.enhance.__doc__

    def __enter__(self) -> GpuEnhancer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------------- stage graph
    def _define_stages(self) -> None:
        c, t = self._c, self._timed
        c.stage("geometry", ("shape", "viewport"), self._geometry)
        c.stage("upload", ("image",), t(self._upload))
        c.stage("linear", ("upload",), t(self._gpu_linear))
        c.stage("sigma", ("sigma_given", "geometry", "gaze", "blur_rate"), t(self._gpu_sigma))
        c.stage("foveated", ("linear", "sigma", "already_foveated"), t(self._gpu_foveated))
        c.stage("luma", ("foveated",), t(self._gpu_luma))
        c.stage("pyramid", ("luma",), t(self._gpu_pyramid))
        c.stage("abs_laplacian", ("pyramid",), t(self._gpu_abs_laplacian))
        c.stage("gradients", ("pyramid",), t(self._gpu_gradients))
        c.stage("sat", ("luma", "sigma"), t(self._gpu_sat))
        c.stage("contrast", ("sat", "f_e"), t(self._gpu_contrast))
        c.stage("headroom", ("foveated", "contrast"), t(self._gpu_headroom))
        c.stage("impulses", ("shape", "n_impulses", "seed"), t(self._gpu_impulses))
        c.stage("imp_params", ("impulses", "geometry", "gaze", "sigma", "blur_rate", "s_f",
                               "s_k", "abs_laplacian", "gradients", "headroom"),
                t(self._gpu_imp_params))
        c.stage("noise", ("impulses", "imp_params"), t(self._gpu_noise))
        c.stage("output", ("method", "foveated", "?contrast", "?noise", "upload",
                           "already_foveated"), t(self._gpu_output))

    @property
    def dispatch_timings_s(self) -> dict[str, float]:
        """``profile="gpu"``: seconds per compute entry (``"BLUR"``, ``"NOISE"``, ...), summed
        over its dispatches since the last :meth:`enhance` began (maps read since included);
        measured as :attr:`timing_method` says. Empty otherwise."""
        return dict(self._timer.entries_s) if self._timer is not None else {}

    @property
    def dispatch_counts(self) -> dict[str, int]:
        """``profile="gpu"``: dispatches per compute entry, counted as
        :attr:`dispatch_timings_s` sums them. Empty otherwise."""
        return dict(self._timer.counts) if self._timer is not None else {}

    def _timed(self, fn):
        if self.profile != "wall":
            return fn

        def run(*args):
            out = fn(*args)
            self.ctx.finish()
            return out

        return run

    # ------------------------------------------------------------------------- plumbing
    def _buffer(self, name: str, nbytes: int, sigma_px: float | None = None) -> Any:
        """The buffer ``name`` of at least ``nbytes`` (reallocated, zeroed, when it grows).

        Every buffer is bound whole, so none may pass the driver's
        GL_MAX_SHADER_STORAGE_BLOCK_SIZE (128 MiB on llvmpipe and other drivers): one that
        would is refused by name. ``sigma_px``: the buffer's size grows with the largest blur
        (the foveation's and the contrast's borders), which the refusal then names."""
        nbytes = max(int(nbytes), 16)
        buf = self._buffers.get(name)
        if buf is None or buf.size < nbytes:
            if nbytes > self._max_block_bytes:
                what = "the image" if sigma_px is None else (
                    f"the image with a blur of up to {sigma_px:.0f} px (a lower blur-rate or a "
                    "gaze nearer the centre needs less)")
                raise FovexpError(
                    f"{what} is too large for this GPU: buffer {name} needs "
                    f"{nbytes / 2**20:.1f} MiB, the driver binds at most "
                    f"{self._max_block_bytes / 2**20:.1f} MiB ({self.renderer})"
                )
            if buf is not None:
                buf.release()
                del self._buffers[name]
            try:
                buf = self.ctx.buffer(reserve=nbytes)
            except Exception as exc:  # moderngl.Error: out of GPU memory
                raise FovexpError(f"cannot allocate {nbytes / 2**20:.0f} MiB on the GPU "
                                  f"for {name}: {exc}") from None
            buf.clear()
            self._buffers[name] = buf
        return buf

    def _run(self, file: str, entry: str, groups: tuple[int, ...], buffers: dict[str, Any],
             **uniforms: Any) -> None:
        if any(n > top for n, top in zip(groups, self._max_groups, strict=True)):
            raise FovexpError(
                f"the image is too large for this GPU: {file} {entry} needs "
                f"{' x '.join(map(str, groups))} work groups, the driver dispatches at most "
                f"{' x '.join(map(str, self._max_groups))} ({self.renderer})"
            )
        prog = self._programs.get(file, entry)
        for name, buf in buffers.items():
            buf.bind_to_storage_buffer(BINDINGS[name])
        for key, value in uniforms.items():
            if key not in prog:  # unused by this entry: the compiler removed it
                continue
            if isinstance(value, np.ndarray):
                prog[key].write(value.tobytes())
            else:
                prog[key].value = value
        if self._timer is None:
            prog.run(*groups)
        else:
            self._timer.run(prog, groups, entry)
        self.ctx.memory_barrier()

    @staticmethod
    def _groups_2d(height: int, width: int) -> tuple[int, int, int]:
        return (-(-width // LOCAL_2D[0]), -(-height // LOCAL_2D[1]), 1)

    @staticmethod
    def _groups_1d(n: int) -> tuple[int, int, int]:
        return (max(-(-n // LOCAL_1D), 1), 1, 1)

    def _hwc(self) -> tuple[int, int, int]:
        img = self._c.get("image")
        return img.shape[0], img.shape[1], (img.shape[2] if img.ndim == 3 else 1)

    def _read(self, name: str, count: int, dtype: str = "f4") -> np.ndarray:
        if count == 0:  # moderngl cannot map 0 bytes
            return np.empty(0, dtype)
        return np.frombuffer(self._buffers[name].read(size=count * np.dtype(dtype).itemsize),
                             dtype=dtype).copy()

    def _geometry_uniforms(self) -> dict[str, Any]:
        geom: ViewingGeometry = self._c.get("geometry")
        gx, gy = geom.gaze_px(self._c.get("gaze"))
        ppd_c = geom.ppd_constant if math.isfinite(geom.ppd_constant) else 0.0
        return dict(
            geom_model=GEOMETRY_MODELS[geom.model],
            geom_pitch_cm=(geom.pitch_x_cm, geom.pitch_y_cm),
            geom_distance_cm=geom.distance_cm, geom_ppd_constant=ppd_c,
            geom_screen_px=(float(geom.screen_width_px), float(geom.screen_height_px)),
            geom_origin_px=(float(geom.x0_px), float(geom.y0_px)), gaze_px=(gx, gy),
            blur_rate_arcmin_per_deg=float(self._c.get("blur_rate")),
            fovea_deg=float(self.preset.fovea_deg),
        )

    # ------------------------------------------------------------------------- stages
    def _upload(self, image: np.ndarray) -> Any:
        data = np.ascontiguousarray(image, dtype=np.float32)
        buf = self._buffer("IMAGE", data.nbytes)
        buf.write(data.tobytes())
        return buf

    def _gpu_linear(self, image_buf: Any) -> Any:
        h, w, c = self._hwc()
        lin = self._buffer("LINEAR", h * w * c * _F4)
        self._run("colour.glsl", "LINEARIZE", self._groups_2d(h, w),
                  {"IMAGE": image_buf, "LINEAR": lin}, image_hwc=(h, w, c), gamma=self._gamma())
        return lin

    def _gpu_sigma(self, given, geom, gaze, blur_rate) -> float:
        """The sigma map in its buffer; returns what sizes the blur stack and the contrast's
        boxes (px): the given map's maximum, else the CPU's bound of the map
        (:func:`fovexp.foveation.sigma_bound_px`; no read-back)."""
        h, w, _ = self._hwc()
        sigma = self._buffer("SIGMA", h * w * _F4)
        tx, ty, _ = self._groups_2d(h, w)  # one tile per full-resolution work group
        tiles = self._buffer("TILES", tx * ty * 2 * _F4)
        if given is not None:
            sigma.write(np.ascontiguousarray(given, np.float32).tobytes())
            t = LOCAL_2D[0]
            padded = np.pad(given, ((0, ty * t - h), (0, tx * t - w)), mode="edge")
            blocks = padded.reshape(ty, t, tx, t)
            ranges = np.stack([blocks.min(axis=(1, 3)), blocks.max(axis=(1, 3))], axis=-1)
            tiles.write(ranges.astype(np.float32).tobytes())
            return float(given.max())
        self._run("foveation.glsl", "SIGMA", (tx, ty, 1),
                  {"SIGMA": sigma, "TILES": tiles}, size_wh=(w, h),
                  **self._geometry_uniforms())
        return sigma_bound_px(geom, geom.gaze_px(gaze), blur_rate, self.preset.fovea_deg)

    def _gpu_foveated(self, linear: Any, max_sigma: float, already_foveated: bool) -> Any:
        """foveation.foveate: the blur stack of foveation.blur_stack_plan."""
        if already_foveated or max_sigma <= 0.0:
            return linear
        h, w, c = self._hwc()
        plan = blur_stack_plan(max_sigma)
        pad = plan.pad_px
        # levels 1..top of the padded image's pyramid, packed; level 0 is `linear` itself
        grids = [_Grid(0, h, w)]
        ph, pw, offset = h + 2 * pad, w + 2 * pad, 0
        for _ in range(plan.top):
            ph, pw = (ph + 1) // 2, (pw + 1) // 2
            grids.append(_Grid(offset, ph, pw))
            offset += ph * pw * c
        pyr = self._buffer("FOV_PYR", offset * _F4, max_sigma)
        for m in range(1, plan.top + 1):
            src, g = (linear, grids[0]) if m == 1 else (pyr, grids[m - 1])
            self._run("pyramids.glsl", "REDUCE", self._groups_2d(grids[m].height, grids[m].width),
                      {"REDUCE_SRC": src, "REDUCE_DST": pyr}, src_hwc=(g.height, g.width, c),
                      src_offset=g.offset, src_pad=pad if m == 1 else 0,
                      dst_hw=(grids[m].height, grids[m].width), dst_offset=grids[m].offset)
        levels = self._buffer("LEVELS", plan.sigmas_px.size * _F4)
        levels.write(plan.sigmas_px.astype(np.float32).tobytes())
        kernels = np.concatenate(plan.kernels).astype(np.float32)
        kbuf = self._buffer("KERNELS", kernels.nbytes)
        kbuf.write(kernels.tobytes())
        bracket = self._buffer("BRACKET", h * w * 2 * _F4)
        fov = self._buffer("FOVEATED", h * w * c * _F4)
        sigma = self._buffers["SIGMA"]
        tx, ty, _ = self._groups_2d(h, w)
        flags = self._buffer("FLAT_FLAGS", tx * ty * 4)
        flat_bufs, skip = self._flat_tiles("LINEAR_TILES", linear, c)
        self._run("foveation.glsl", "STACK_INIT", self._groups_2d(h, w),
                  {"LINEAR": linear, "SIGMA": sigma, "LEVELS": levels, "BRACKET": bracket,
                   "FOVEATED": fov, "FLAT_FLAGS": flags, **flat_bufs}, image_hwc=(h, w, c),
                  n_levels=int(plan.sigmas_px.size), reach_px=plan.reach_px(), **skip)
        largest = max(grids[int(m)].height * grids[int(m)].width for m in plan.pyramid_level)
        tmp = self._buffer("BLUR_TMP", largest * c * _F4, max_sigma)
        out = self._buffer("BLUR_OUT", largest * c * _F4, max_sigma)
        tiles = self._buffers["TILES"]
        tile_grid = self._groups_2d(h, w)[:2]
        sig = plan.sigmas_px.astype(np.float32)
        k_offset = 1  # kernels[0] is stack level 0's (the image itself)
        for lv in range(1, sig.size):
            m = int(plan.pyramid_level[lv])
            g = grids[m]
            src = linear if m == 0 else pyr
            radius = plan.kernels[lv].size // 2
            level = dict(level_scale=level_scale(m), level_pad_px=pad if m > 0 else 0,
                         need_lo=float(sig[lv - 1]),
                         need_hi=float(sig[lv + 1]) if lv + 1 < sig.size else float("inf"),
                         tile_grid_wh=tile_grid)
            groups = self._groups_2d(g.height, g.width)
            for along_y, (a, b, off) in ((1, (src, tmp, g.offset)), (0, (tmp, out, 0))):
                self._run("foveation.glsl", "BLUR", groups, {"BLUR_SRC": a, "BLUR_DST": b,
                          "KERNELS": kbuf, "TILES": tiles, "FLAT_FLAGS": flags},
                          grid_hwc=(g.height, g.width, c),
                          src_offset=off, kernel_offset=k_offset, kernel_radius=radius,
                          along_y=along_y, **level)
            k_offset += plan.kernels[lv].size
            self._run("foveation.glsl", "STACK_ACCUMULATE", self._groups_2d(h, w),
                      {"BLUR_DST": out, "BRACKET": bracket, "FOVEATED": fov, "TILES": tiles,
                       "FLAT_FLAGS": flags, "LINEAR": linear},
                      image_hwc=(h, w, c), stack_level=lv, level_hw=(g.height, g.width), **level)
        return fov

    def _luma_grids(self) -> list[_Grid]:
        """Levels of pyramids.gaussian_pyramid(luma, MAX_LAPLACIAN_LEVEL), packed."""
        h, w, _ = self._hwc()
        grids, offset = [_Grid(0, h, w)], h * w
        while len(grids) <= MAX_LAPLACIAN_LEVEL and min(h, w) >= 2:
            h, w = (h + 1) // 2, (w + 1) // 2
            grids.append(_Grid(offset, h, w))
            offset += h * w
        return grids

    def _gpu_luma(self, fov: Any) -> list[_Grid]:
        h, w, c = self._hwc()
        grids = self._luma_grids()
        last = grids[-1]
        pyr = self._buffer("LUMA_PYR", (last.offset + last.height * last.width) * _F4)
        self._run("colour.glsl", "LUMINANCE", self._groups_2d(h, w),
                  {"FOVEATED": fov, "LUMA_PYR": pyr}, image_hwc=(h, w, c))
        self._flat_tiles("LUMA_TILES", pyr, 1)  # the luminance is level 0 of its pyramid
        return grids

    def _flat_tiles(self, name: str, image: Any, channels: int) -> tuple[dict, dict]:
        """With skipping (EngineOptions.skip), each tile's extremes of ``image`` (H, W,
        ``channels``) into buffer ``name``, which the early exits read; the buffer and
        uniforms to bind them with (an unused buffer and skip = 0 without skipping)."""
        h, w, _ = self._hwc()
        tx, ty, _ = self._groups_2d(h, w)
        if not self.options.skip:
            return self._no_skip()
        assert channels <= 4, channels  # the shader's TILE_MAX_CHANNELS
        tiles = self._buffer(name, tx * ty * channels * 2 * _F4)
        self._run("pyramids.glsl", "TILE_EXTREMES", (tx, ty, 1),
                  {"TILE_SRC": image, "FLAT_TILES": tiles}, image_hwc=(h, w, channels))
        return {"FLAT_TILES": tiles}, dict(skip=1, flat_tiles_hwc=(ty, tx, channels))

    def _no_skip(self) -> tuple[dict, dict]:
        return {"FLAT_TILES": self._buffer("UNUSED", 16)}, dict(skip=0, flat_tiles_hwc=(1, 1, 1))

    def _skip_uniforms(self) -> tuple[dict[str, Any], dict[str, Any]]:
        """The luminance's tile extremes (made by the luma stage) and the uniforms of the
        stages' early exits (EngineOptions.skip)."""
        h, w, _ = self._hwc()
        tx, ty, _ = self._groups_2d(h, w)
        if not self.options.skip:
            return self._no_skip()
        return ({"FLAT_TILES": self._buffers["LUMA_TILES"]},
                dict(skip=1, flat_tiles_hwc=(ty, tx, 1)))

    def _gpu_pyramid(self, grids: list[_Grid]) -> list[_Grid]:
        pyr = self._buffers["LUMA_PYR"]
        for m in range(1, len(grids)):
            s, d = grids[m - 1], grids[m]
            self._run("pyramids.glsl", "REDUCE", self._groups_2d(d.height, d.width),
                      {"REDUCE_SRC": pyr, "REDUCE_DST": pyr}, src_hwc=(s.height, s.width, 1),
                      src_offset=s.offset, src_pad=0, dst_hw=(d.height, d.width),
                      dst_offset=d.offset)
        return grids

    def _gpu_abs_laplacian(self, grids: list[_Grid]) -> dict[str, Any]:
        """pyramids.smoothed_abs_laplacian: |L_k|, k = 1..top, each on G_{k-1}'s grid."""
        top = min(MAX_LAPLACIAN_LEVEL, len(grids) - 1)
        offsets = np.zeros(MAX_LAPLACIAN_LEVEL + 1, np.int32)
        sizes = np.zeros((MAX_LAPLACIAN_LEVEL + 1, 2), np.int32)
        total = 0
        for k in range(1, top + 1):
            g = grids[k - 1]
            offsets[k], sizes[k] = total, (g.width, g.height)
            total += g.height * g.width
        lap = self._buffer("ABSLAP", total * _F4)
        tmp = self._buffer("LAP_TMP", grids[0].height * grids[0].width * _F4)
        pyr = self._buffers["LUMA_PYR"]
        skip_bufs, skip = self._skip_uniforms()
        for k in range(1, top + 1):
            f, co = grids[k - 1], grids[k]
            groups = self._groups_2d(f.height, f.width)
            self._run("pyramids.glsl", "ABS_LAPLACIAN", groups,
                      {"LUMA_PYR": pyr, "LAP_TMP": tmp, **skip_bufs},
                      fine_hw=(f.height, f.width), fine_offset=f.offset,
                      coarse_hw=(co.height, co.width), coarse_offset=co.offset,
                      level_scale=level_scale(k - 1), **skip)
            self._run("pyramids.glsl", "BOX3", groups, {"LAP_TMP": tmp, "ABSLAP": lap,
                                                        **skip_bufs},
                      grid_hw=(f.height, f.width), dst_offset=int(offsets[k]),
                      level_scale=level_scale(k - 1), **skip)
        return dict(lap_top=top, lap_offset=offsets, lap_size_wh=sizes)

    def _gpu_gradients(self, grids: list[_Grid]) -> dict[str, Any]:
        g = grids[ORIENTATION_LEVEL]
        grad = self._buffer("GRADIENTS", 2 * g.height * g.width * _F4)
        self._run("orientation.glsl", "SOBEL", self._groups_2d(g.height, g.width),
                  {"LUMA_PYR": self._buffers["LUMA_PYR"], "GRADIENTS": grad},
                  level_hw=(g.height, g.width), level_offset=g.offset)
        return dict(gradient_size_wh=(g.width, g.height))

    def _gpu_sat(self, grids: list[_Grid], max_sigma: float) -> int | None:
        """contrast._sat: the exact summed-area table (64-bit fixed point) of the padded
        luminance."""
        if max_sigma <= 0.0:
            return None
        h, w, _ = self._hwc()
        pad = sat_pad_px(max_sigma)
        check_sat_fits((h, w), pad, 1.0)  # linear luminance: at most 1
        hp, wp = h + 2 * pad, w + 2 * pad
        sat = self._buffer("SAT", (hp + 1) * (wp + 1) * 8, max_sigma)
        pyr = self._buffers["LUMA_PYR"]
        self._run("contrast.glsl", "SAT_ROWS", self._groups_1d(hp), {"LUMA_PYR": pyr, "SAT": sat},
                  image_hw=(h, w), pad_px=pad)
        self._run("contrast.glsl", "SAT_COLS", self._groups_1d(wp), {"SAT": sat},
                  image_hw=(h, w), pad_px=pad)
        return pad

    def _gpu_contrast(self, pad: int | None, f_e: float) -> Any:
        """contrast.contrast_change: the luminance change, added later to every channel."""
        h, w, _ = self._hwc()
        delta = self._buffer("CONTRAST", h * w * _F4)
        if pad is None:  # no blur anywhere: no change
            delta.clear()
            return delta
        skip_bufs, skip = self._skip_uniforms()
        self._run("contrast.glsl", "CONTRAST_CHANGE", self._groups_2d(h, w),
                  {"LUMA_PYR": self._buffers["LUMA_PYR"], "SIGMA": self._buffers["SIGMA"],
                   "SAT": self._buffers["SAT"], "CONTRAST": delta, **skip_bufs},
                  image_hw=(h, w), pad_px=pad, f_e=float(f_e), **skip)
        return delta

    def _gpu_headroom(self, fov: Any, delta: Any) -> dict[str, Any]:
        """Enhancer._headroom (amplitude.clipping_extremes): level-3 block extremes of the
        image the noise is added to, of its luminance (rule "paper") or over its channels and
        widened to every block a kernel reaches (rule "widened")."""
        h, w, c = self._hwc()
        p = self.preset
        block = level_scale(p.minmax_level)
        paper = self.clipping == "paper"
        radius = 0 if paper else int(np.ceil(gabor.kernel_radius_px(p.gabor_a_cpp) / block))
        bh, bw = -(-h // block), -(-w // block)
        ext = self._buffer("EXTREMES", 2 * bh * bw * _F4)
        head = self._buffer("HEADROOM", 2 * bh * bw * _F4)
        self._run("pyramids.glsl", "BLOCK_EXTREMES", self._groups_2d(bh, bw),
                  {"FOVEATED": fov, "LUMA_PYR": self._buffers["LUMA_PYR"], "CONTRAST": delta,
                   "EXTREMES": ext},
                  image_hwc=(h, w, c), block=block, grid_hw=(bh, bw), over_luma=int(paper))
        self._run("pyramids.glsl", "EXTREMES_FILTER", self._groups_2d(bh, bw),
                  {"EXTREMES": ext, "HEADROOM": head}, grid_hw=(bh, bw), radius=radius)
        return dict(headroom_size_wh=(bw, bh), headroom_block=block)

    def _gpu_impulses(self, shape: tuple[int, int], n: int, seed: int) -> _GpuImpulses:
        """gabor.generate_impulses (the same impulses as the CPU backend), grouped by cell."""
        h, w = shape
        a = self.preset.gabor_a_cpp
        imp = gabor.generate_impulses(w, h, n, a, seed)
        cell = imp.cell_px
        nx, ny = gabor.cell_counts(w, h, cell)
        cx = np.clip(gabor.cell_index(imp.x_px, cell), 0, nx - 1)
        cy = np.clip(gabor.cell_index(imp.y_px, cell), 0, ny - 1)
        cell_id = cy * nx + cx
        order = np.argsort(cell_id, kind="stable")
        starts = np.searchsorted(cell_id[order], np.arange(nx * ny + 1)).astype(np.int32)
        rec = np.zeros((len(imp), 4), np.float32)
        rec[:, 0], rec[:, 1], rec[:, 2] = imp.x_px[order], imp.y_px[order], imp.weight[order]
        q = np.stack([imp.quantile[order], 1.0 - imp.quantile[order]], axis=1).astype(np.float32)
        for name, data in (("IMPULSES", rec), ("QUANTILES", q), ("CELLS", starts)):
            self._buffer(name, data.nbytes).write(data.tobytes())
        self._buffer("IMP_PARAMS", len(imp) * len(IMPULSE_FIELDS) * _F4)
        return _GpuImpulses(imp, order, (nx, ny), len(imp))

    def _gpu_imp_params(self, imp: _GpuImpulses, geom, gaze, max_sigma, blur_rate, s_f, s_k,
                        lap: dict[str, Any], grad: dict[str, Any], head: dict[str, Any]) -> int:
        """Per impulse: band, frequency, amplitude, orientation (pipeline.glsl). The arguments
        are the stages this one depends on; their data are in the GPU buffers. Dispatched in
        slices of at most the driver's work-group count (x)."""
        b = self._buffers
        bufs = {"IMPULSES": b["IMPULSES"], "QUANTILES": b["QUANTILES"], "SIGMA": b["SIGMA"],
                "ABSLAP": b["ABSLAP"], "GRADIENTS": b["GRADIENTS"], "HEADROOM": b["HEADROOM"],
                "IMP_PARAMS": b["IMP_PARAMS"]}
        uniforms = self._point_uniforms(lap, grad, head)
        per_dispatch = self._max_groups[0] * LOCAL_1D
        for first in range(0, imp.count, per_dispatch):  # none for no impulses
            self._run("pipeline.glsl", "IMPULSES",
                      self._groups_1d(min(per_dispatch, imp.count - first)), bufs,
                      n_impulses=imp.count, first_impulse=first, **uniforms)
        return imp.count

    def _point_uniforms(self, lap, grad, head) -> dict[str, Any]:
        h, w, _ = self._hwc()
        c = self._c
        return dict(
            image_wh=(w, h), sigma_from_map=int(c.get("sigma_given") is not None),
            s_f=float(c.get("s_f")), s_k=float(c.get("s_k")),
            noise_norm=gabor.normalisation(int(c.get("n_impulses")), self.preset.gabor_a_cpp),
            attenuation=float(self.preset.attenuation), **self._geometry_uniforms(),
            **(lap or {}), **(grad or {}), **(head or {}),
        )

    def _gpu_noise(self, imp: _GpuImpulses, _count: int) -> Any:
        h, w, _ = self._hwc()
        a = self.preset.gabor_a_cpp
        b = self._buffers
        noise = self._buffer("NOISE", h * w * _F4)
        self._run("gabor.glsl", "NOISE", self._groups_2d(h, w),
                  {"IMPULSES": b["IMPULSES"], "CELLS": b["CELLS"], "IMP_PARAMS": b["IMP_PARAMS"],
                   "NOISE": noise},
                  image_hw=(h, w), gabor_a_cpp=a, kernel_radius_px=gabor.kernel_radius_px(a),
                  cell_px=imp.impulses.cell_px, cell_count_xy=imp.cells_xy,
                  skip=int(self.options.skip))
        return noise

    def _gpu_output(self, method: str, fov: Any, contrast, noise, upload: Any,
                    already_foveated: bool) -> Any:
        """Enhancer._compose: the grey change and noise on every channel, clipped, encoded;
        an already-foveated frame's own pixel where nothing changes."""
        h, w, c = self._hwc()
        out = self._buffer("OUTPUT", h * w * c * _F4)
        delta = contrast() if method in ("contrast", "ours") else None
        nz = noise() if method == "ours" else None
        unused = self._buffer("UNUSED", 16)
        self._run("colour.glsl", "COMPOSE", self._groups_2d(h, w),
                  {"FOVEATED": fov, "CONTRAST": unused if delta is None else delta,
                   "NOISE": unused if nz is None else nz,
                   "IMAGE": upload if already_foveated else unused, "OUTPUT": out},
                  image_hwc=(h, w, c), add_contrast=int(delta is not None),
                  add_noise=int(nz is not None), keep_unchanged=int(already_foveated),
                  gamma=self._gamma())
        return out

    # ------------------------------------------------------------------------- read-back
    def _image_shape(self) -> tuple[int, ...]:
        h, w, c = self._hwc()
        return (h, w, c) if self._c.get("image").ndim == 3 else (h, w)

    def _output(self) -> np.ndarray:
        self._c.get("output")
        h, w, c = self._hwc()
        return self._read("OUTPUT", h * w * c).reshape(self._image_shape())

    def write_output_to(self, texture: Any, gaze: tuple[float, float] = (0.5, 0.5),
                        params: Any = None) -> Any:
        """:meth:`enhance`, the frame going into ``texture`` on the GPU instead of host memory.

        ``texture``: a moderngl texture of this enhancer's context (or of one sharing objects
        with it), of the image's size, with as many components as the image has channels and
        dtype ``f4``. The OUTPUT buffer (interleaved float32, row 0 the image's top row) is
        copied into it as a pixel-unpack transfer, GPU to GPU; texture row 0 is then the
        image's top row. Nothing is read back. Returns the resolved parameters. The copy is
        queued, not finished: call ``ctx.finish()`` (or fence) before another context draws
        the texture. The experiment runner draws it in its window this way (docs/GPU.md).
        """
        with self._current():
            # enhance() without its read-back: the same checks, stage graph and cache
            resolved = self._prepare(gaze, params, None)
            h, w, c = self._hwc()
            got = (tuple(texture.size), int(texture.components), str(texture.dtype))
            if got != ((w, h), c, "f4"):
                raise FovexpError(f"write_output_to: the texture is {got[0][0]}x{got[0][1]}, "
                                  f"{got[1]} components, {got[2]}; the output needs {w}x{h}, "
                                  f"{c} components, f4")
            texture.write(self._c.get("output"))
            return resolved

    def linear(self, name: str) -> np.ndarray:  # noqa: D102 - Enhancer.linear
        with self._current():
            return super().linear(name)

    linear.__doc__ = Enhancer.linear.__doc__

    def _linear_image(self, name: str) -> np.ndarray:
        fov = self._c.get("foveated")
        h, w, c = self._hwc()
        img = np.frombuffer(fov.read(size=h * w * c * _F4), np.float32).reshape(
            self._image_shape()).copy()
        if name == "contrast":
            delta = self._contrast_change()
            img += delta[..., None] if img.ndim == 3 else delta
        return img

    def _contrast_change(self) -> np.ndarray:
        self._c.get("contrast")
        h, w, _ = self._hwc()
        return self._read("CONTRAST", h * w).reshape(h, w)

    def impulse_params(self) -> dict[str, np.ndarray]:
        """Per-impulse parameters of the last frame, in the order of the impulses (``x_px``,
        ``y_px``, then ``K``, ``F`` (cycles/px), ``OMEGA`` (rad), ``F_LOW``, ``F_HIGH``, and
        ``AMP``, ``KX``, ``KY`` of the synthesis), for comparison with the CPU backend."""
        with self._current():
            return self._impulse_params()

    def _impulse_params(self) -> dict[str, np.ndarray]:
        imp: _GpuImpulses = self._c.get("impulses")
        self._c.get("imp_params")
        fields = len(IMPULSE_FIELDS)
        rec = self._read("IMP_PARAMS", imp.count * fields).reshape(imp.count, fields)
        back = np.empty_like(rec)
        back[imp.order] = rec
        out = {name: back[:, i] for i, name in enumerate(IMPULSE_FIELDS)}
        out["x_px"], out["y_px"] = imp.impulses.x_px, imp.impulses.y_px
        return out

    def _map(self, name: str) -> np.ndarray:
        with self._current():
            return super()._map(name)

    def _read_map(self, name: str) -> np.ndarray:
        """Enhancer._read_map: sigma and noise from their buffers; a map of POINT_MAPS by one
        dispatch of pipeline.glsl MAPS into a buffer of one map (32 MiB at 4K, within the
        128 MiB that llvmpipe and other drivers bind), for the map asked for only."""
        c = self._c
        h, w, _ = self._hwc()
        if name in ("sigma_px", "noise"):
            stage, buffer = {"sigma_px": ("sigma", "SIGMA"), "noise": ("noise", "NOISE")}[name]
            c.get(stage)
            return self._read(buffer, h * w).reshape(h, w)
        c.get("sigma")  # the band reads the sigma map when it is given
        b = self._buffers
        bufs = {"SIGMA": b["SIGMA"], "MAP": self._buffer("MAP", h * w * _F4)}
        grad = lap = head = None
        if name == "orientation_rad":
            grad = c.get("gradients")
            bufs["GRADIENTS"] = b["GRADIENTS"]
        elif name == "amplitude":
            lap, head = c.get("abs_laplacian"), c.get("headroom")
            bufs.update(ABSLAP=b["ABSLAP"], HEADROOM=b["HEADROOM"])
        self._run("pipeline.glsl", "MAPS", self._groups_2d(h, w), bufs,
                  map_field=POINT_MAPS.index(name), **self._point_uniforms(lap, grad, head))
        return self._read("MAP", h * w).reshape(h, w)

    def close(self) -> None:
        """Release the GPU buffers, and the context if this enhancer created it; in a given
        context (which stays with its owner) also the compiled programs when no other
        enhancer runs there. Later calls raise :class:`FovexpError`; closing twice is a no-op.
        Call it on the thread that created the enhancer."""
        if self._closed:
            return
        self._closed = True
        cache = getattr(self, "_c", None)  # absent when __init__ failed early
        if cache is not None:  # its stages hold the buffers released below
            cache.clear()
        try:
            if self._buffers or (self._programs is not None and not self._owns_context):
                with made_current(self.ctx):
                    for buf in self._buffers.values():
                        buf.release()
                    if self._programs is not None and not self._owns_context:
                        drop_user(self.ctx, self)
        finally:
            self._buffers.clear()
            self._programs = None
            if self._owns_context:
                release_context(self.ctx)
                self._owns_context = False

