"""Sparse Gabor noise (Lagae et al. 2009; paper section 4.4; docs/METHOD.md, 4 and 5.9).

The noise is a sum of Gabor kernels placed at random impulses::

    n(x) = sum_i w_i K_i g_i(x - x_i),
    g_i(d) = exp(-pi a^2 |d|^2) cos(2 pi F_i (d_x cos t_i + d_y sin t_i))

with weights ``w_i`` uniform in (-1, 1) (or +-1: ``EngineOptions.weights``), and each
impulse's frequency ``F_i``, amplitude ``K_i`` and carrier direction ``t_i = omega_i - pi/2``
read at the impulse's own position. The kernel frequency width is ``a`` (0.06 cycles/px in the
paper); the kernel is truncated where its envelope reaches 1 %, radius
``r = sqrt(-ln 0.01 / pi) / a`` (20.2 px; the cut is ``EngineOptions.kernel_truncation``).

Impulses: the plane is cut into cells of side ``r``; each cell's random stream is seeded from its
coordinates (modulo a period of 256 cells) and the seed, and holds a Poisson number of impulses
with mean ``lambda r^2 = N / pi`` for ``N`` impulses per kernel (``lambda = N / (pi r^2)``), so
every pixel lies inside about N kernels. ``EngineOptions`` offers faster variants with the same
density: a jittered count (floor(m) or floor(m) + 1 impulses, mean m), and cells smaller than
r (side ``cell_scale r``, mean ``m = N cell_scale^2 / pi``) that the synthesis culls more
finely. The impulses depend only on the image size, N, a, these options and the seed: every
frame of a sequence has the same ones (section 4.4).

Normalisation (docs/METHOD.md, 5.9): the sum is divided by ``6 sqrt(V)`` with ``V`` the
variance of the sum for K = 1 at F = 0.0625 cycles/px (docs/METHOD.md, 4)::

    V = lambda E[w^2] (1 / (4 a^2)) (1 + exp(-2 pi F^2 / a^2)),   E[w^2] = 1/3 (uniform), 1 (+-1)

so that the noise's local standard deviation is ``K / 6`` whatever the impulse count, as in the
release (its measured std / K is 0.164 for 12 and 64 impulses). V holds for any arrangement of
impulses with density lambda and independent zero-mean weights (Campbell's theorem: the cross
terms vanish), Poisson or jittered. The release also subtracts the global mean of the noise;
that would shift the fovea, where the noise is zero, so it is not done here (the weights are
symmetric: the expected mean is 0).

Synthesis: each kernel is separable as the real part of a product of two complex 1-D factors,
``exp(-pi a^2 d_x^2 + i 2 pi F cos(t) d_x) * exp(-pi a^2 d_y^2 + i 2 pi F sin(t) d_y)``;
the factors are built by recurrence (no transcendental per pixel), each pixel costs one complex
multiply-add, and bands of rows are summed in parallel without locks.

References
----------
.. [tariq] Tariq, T., Tursun, C., Didyk, P. (2022). Noise-based Enhancement for Foveated
   Rendering. ACM Transactions on Graphics 41(4) (SIGGRAPH 2022). doi:10.1145/3528223.3530101
.. [lagae] Lagae, A., Lefebvre, S., Drettakis, G., Dutré, P. (2009). Procedural Noise using
   Sparse Gabor Convolution. ACM Transactions on Graphics 28(3) (SIGGRAPH 2009).
   doi:10.1145/1531326.1531360
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal, overload

import numba
import numpy as np
from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

from ._parallel import interleave
from .jit import FASTMATH, MAGIC_F64, fma, two_to_the
from .memory import WrittenRows, frame_empty, frame_zeros

#: Envelope value at which the kernel is truncated (docs/METHOD.md, 4).
KERNEL_TRUNCATION = 0.01
#: Frequency used in the normalisation's variance (docs/METHOD.md, 5.9).
NORMALISATION_F_CPP = 0.0625
#: The noise's local standard deviation is K / NOISE_STD_DIVISOR (docs/METHOD.md, 5.9).
NOISE_STD_DIVISOR = 6.0
#: Period of the cell pattern, in cells (docs/METHOD.md, 5.9).
CELL_PERIOD = 256
#: Rows per parallel band of the synthesis.
BAND_ROWS = 128
#: The cell grid reaches this many cells past each edge of the image: impulses there have
#: kernels that reach into it.
CELL_BORDER = 1
#: Cell ``i`` covers ``[i cell + CELL_ORIGIN_PX, (i + 1) cell + CELL_ORIGIN_PX)`` px: cell edges
#: lie on pixel edges (pixel x spans x +- 0.5).
CELL_ORIGIN_PX = -0.5


#: Mean square E[w^2] of the impulse weights: uniform in (-1, 1), or +-1 (docs/METHOD.md, 4).
WEIGHT_MEAN_SQUARE: dict[str, float] = {"uniform": 1.0 / 3.0, "sign": 1.0}


def kernel_radius_px(gabor_a_cpp: float, truncation: float = KERNEL_TRUNCATION) -> float:
    """Truncation radius ``sqrt(-ln t / pi) / a``, t = 0.01 (docs/METHOD.md, 4): 20.2 px at
    a = 0.06, 15.1 at 0.08."""
    return math.sqrt(-math.log(truncation) / math.pi) / gabor_a_cpp


def cell_size_px(gabor_a_cpp: float, cell_scale: float = 1.0) -> float:
    """Side of the impulse cells: ``cell_scale`` times the kernel radius at the paper's
    truncation (Lagae et al.: the radius), whatever truncation the synthesis then uses."""
    return cell_scale * kernel_radius_px(gabor_a_cpp)


@numba.njit(cache=True, fastmath=FASTMATH, nogil=True)
def cell_counts(width_px: int, height_px: int, cell_px: float) -> tuple[int, int]:
    """Cells per row and per column of the grid the impulses are drawn on (borders included);
    compiled, so that :func:`_generate` uses it too."""
    return (int(math.ceil(width_px / cell_px)) + 2 * CELL_BORDER,
            int(math.ceil(height_px / cell_px)) + 2 * CELL_BORDER)


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _cell_of(pos_px, cell_px):  # pragma: no cover - compiled
    """:func:`cell_index` of one coordinate (the kernels' set-up takes it too)."""
    return np.int64(math.floor((pos_px - CELL_ORIGIN_PX) / cell_px)) + CELL_BORDER


@numba.njit(cache=True, fastmath=FASTMATH, nogil=True)
def _cells_into(pos_px, cell_px, out):  # pragma: no cover - compiled
    for i in range(pos_px.shape[0]):
        out[i] = _cell_of(pos_px[i], cell_px)
    return out


def cell_index(pos_px: np.ndarray, cell_px: float) -> np.ndarray:
    """Index along one axis (0: the first border cell) of the cell holding each coordinate."""
    pos = np.asarray(pos_px, np.float64)
    flat = np.ascontiguousarray(pos).reshape(-1)
    return _cells_into(flat, float(cell_px), np.empty(flat.size, np.int64)).reshape(pos.shape)


def impulse_density(impulses_per_kernel: int, gabor_a_cpp: float) -> float:
    """``lambda = N / (pi r^2)`` impulses per px^2."""
    r = kernel_radius_px(gabor_a_cpp)
    return impulses_per_kernel / (math.pi * r * r)


def normalisation(impulses_per_kernel: int, gabor_a_cpp: float, weights: str = "uniform",
                  truncation: float = KERNEL_TRUNCATION) -> float:
    """Factor that makes the local std ``K / 6``: ``1 / (6 sqrt(V))`` (docs/METHOD.md, 5.9),
    V with the weights' mean square.

    A kernel cut closer than the method's 0.01 (``EngineOptions.kernel_truncation``) loses
    part of its energy: the squared envelope exp(-2 pi a^2 (x^2 + y^2)) keeps
    erf(sqrt(2 pi) a r)^2 of it inside the square of half-side r. V is scaled by that share
    relative to the 0.01 cut's, so the std stays K / 6 at any cut (at 0.5 it would otherwise
    be 0.90 K / 6, measured by tests/stress) and the default cut's factor is unchanged.
    """
    a = gabor_a_cpp
    lam = impulse_density(impulses_per_kernel, a)
    v = lam * WEIGHT_MEAN_SQUARE[weights] / (4.0 * a * a) * (
        1.0 + math.exp(-2.0 * math.pi * NORMALISATION_F_CPP**2 / a**2))
    if truncation != KERNEL_TRUNCATION:
        def kept(t: float) -> float:
            return math.erf(math.sqrt(2.0 * math.pi) * a * kernel_radius_px(a, t)) ** 2
        v *= kept(truncation) / kept(KERNEL_TRUNCATION)
    return 1.0 / (NOISE_STD_DIVISOR * math.sqrt(v))


@dataclass(frozen=True)
class Impulses:
    """Impulse positions and per-impulse random numbers, sorted by cell row."""

    x_px: np.ndarray  # float64
    y_px: np.ndarray  # float64
    weight: np.ndarray  # float32, uniform in (-1, 1), or +-1 (``weights == "sign"``)
    quantile: np.ndarray  # float64, uniform in (0, 1): the frequency draw's quantile
    cell_px: float
    seed: int
    weights: str = "uniform"

    def __len__(self) -> int:
        return int(self.x_px.size)


@numba.njit(cache=True, fastmath=FASTMATH, nogil=True)
def _splitmix(state):  # pragma: no cover - compiled
    state = (state + np.uint64(0x9E3779B97F4A7C15)) & np.uint64(0xFFFFFFFFFFFFFFFF)
    z = state
    z = ((z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)) & np.uint64(
        0xFFFFFFFFFFFFFFFF
    )
    z = ((z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)) & np.uint64(
        0xFFFFFFFFFFFFFFFF
    )
    return state, z ^ (z >> np.uint64(31))


@numba.njit(cache=True, fastmath=FASTMATH, nogil=True)
def _uniform(state):  # pragma: no cover - compiled
    state, z = _splitmix(state)
    # 53 random bits, strictly inside (0, 1)
    return state, ((z >> np.uint64(11)) + 0.5) * (1.0 / 9007199254740992.0)


@numba.njit(cache=True, fastmath=FASTMATH, nogil=True)
def _generate(width, height, cell, mean_count, seed, period, jittered, sign):  # pragma: no cover
    x0 = -CELL_BORDER
    y0 = -CELL_BORDER
    nx, ny = cell_counts(width, height, cell)
    cap = int(nx * ny * (mean_count + 6.0 * math.sqrt(mean_count) + 10.0))
    xs = np.empty(cap)
    ys = np.empty(cap)
    ws = np.empty(cap, dtype=np.float32)
    qs = np.empty(cap)
    limit = math.exp(-mean_count)
    n = 0
    for j in range(ny):
        cy = y0 + j
        for i in range(nx):
            cx = x0 + i
            key = (
                np.uint64(seed) * np.uint64(0x100000001B3)
                + np.uint64(cx % period) * np.uint64(period)
                + np.uint64(cy % period)
            )
            state, _ = _splitmix(key)
            count = 0
            state, u = _uniform(state)
            if jittered:  # floor(m) or floor(m) + 1 impulses, mean m
                count = int(mean_count) + (1 if u < mean_count - int(mean_count) else 0)
            else:  # Poisson count (Knuth): multiply uniforms until below exp(-mean)
                p = u
                while p > limit:
                    count += 1
                    state, u = _uniform(state)
                    p *= u
            for _ in range(count):
                state, ux = _uniform(state)
                state, uy = _uniform(state)
                state, uw = _uniform(state)
                state, uq = _uniform(state)
                if n < cap:
                    xs[n] = (cx + ux) * cell + CELL_ORIGIN_PX
                    ys[n] = (cy + uy) * cell + CELL_ORIGIN_PX
                    ws[n] = 2.0 * uw - 1.0
                    if sign:  # the sign of the uniform weight: the same stream, +-1
                        ws[n] = 1.0 if ws[n] >= 0.0 else -1.0
                    qs[n] = uq
                    n += 1
    return xs[:n], ys[:n], ws[:n], qs[:n]


def generate_impulses(
    width_px: int, height_px: int, impulses_per_kernel: int, gabor_a_cpp: float, seed: int,
    count: str = "poisson", weights: str = "uniform", cell_scale: float = 1.0,
) -> Impulses:
    """The impulses of a ``width x height`` image (deterministic from the seed): a
    ``"poisson"`` or ``"jittered"`` count per cell, ``"uniform"`` or ``"sign"`` weights, cells
    of side ``cell_scale`` kernel radii (:class:`fovexp.params.EngineOptions`)."""
    if count not in ("poisson", "jittered") or weights not in WEIGHT_MEAN_SQUARE:
        raise ValueError(f"unknown impulse count {count!r} or weights {weights!r}")
    cell = cell_size_px(gabor_a_cpp, cell_scale)
    mean_count = impulse_density(impulses_per_kernel, gabor_a_cpp) * cell * cell  # N s^2 / pi
    xs, ys, ws, qs = _generate(width_px, height_px, cell, mean_count, seed, CELL_PERIOD,
                               count == "jittered", weights == "sign")
    return Impulses(xs, ys, ws, qs, cell, seed, weights)


#: Kernel window width is rounded up to this many pixels so that the per-row loop has a
#: fixed trip count the compiler vectorises without a scalar remainder.
WINDOW_MULTIPLE = 16


# (sin, cos) without libm: Cody and Waite's reduction by pi/2 (pi/2 in three parts: n P1 is
# exact for |n| < 2**26) and Cephes' polynomials on [-pi/4, pi/4] (sin.c: within 1e-16). A
# loop over it vectorises, where libm's sin and cos are one call per value (about 24 ns each
# here): the set-up takes eight per impulse and band.
_PIO2_1 = 1.57079625129699707031e0
_PIO2_2 = 7.54978941586159635335e-8
_PIO2_3 = 5.39030285815811905290e-15
_SIN_C = (1.58962301576546568060e-10, -2.50507477628578072866e-8, 2.75573136213857245213e-6,
          -1.98412698295895385996e-4, 8.33333333332211858878e-3, -1.66666666666666307295e-1)
_COS_C = (-1.13585365213876817300e-11, 2.08757008419747316778e-9, -2.75573141792967388112e-7,
          2.48015872888517045348e-5, -1.38888888888730564116e-3, 4.16666666666665929218e-2)


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _sincos(x):  # pragma: no cover - compiled
    """``(sin x, cos x)`` for float64 ``|x| < 2**25``, within a few 1e-16 of libm's;
    branch-free (selects)."""
    n = math.floor(x * (2.0 / math.pi) + 0.5)
    r = ((x - n * _PIO2_1) - n * _PIO2_2) - n * _PIO2_3  # in [-pi/4, pi/4]
    z = r * r
    s0, s1, s2, s3, s4, s5 = _SIN_C
    c0, c1, c2, c3, c4, c5 = _COS_C
    sr = r + r * z * (((((s0 * z + s1) * z + s2) * z + s3) * z + s4) * z + s5)
    cr = 1.0 - 0.5 * z + z * z * (((((c0 * z + c1) * z + c2) * z + c3) * z + c4) * z + c5)
    # the quadrant, x = r + q pi/2 (mod 2 pi), as a float: a float to int64 conversion has
    # no vector instruction before AVX-512, and kept the loop scalar
    q = n - 4.0 * math.floor(0.25 * n)
    sin_x = cr if q == 1.0 else (-sr if q == 2.0 else (-cr if q == 3.0 else sr))
    cos_x = -sr if q == 1.0 else (-cr if q == 2.0 else (sr if q == 3.0 else cr))
    return sin_x, cos_x


# e^x without libm, for the same reason: Cody and Waite's reduction by ln 2 (in two parts: n
# LN2_HI is exact for |n| < 2**11) and e^r's Taylor series to r^13 on |r| <= ln(2) / 2 (its
# remainder below 2e-16), by Horner's rule in fused multiply-adds.
_LN2_HI = 6.93147180369123816490e-01
_LN2_LO = 1.90821492927058770002e-10
_EXP_TAYLOR = tuple(1.0 / math.factorial(k) for k in range(12, -1, -1))  # 1/12!, ..., 1


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _exp(x):  # pragma: no cover - compiled
    """``e^x`` for float64 ``x`` <= 0 (the kernels' Gaussian factors), within a few units in
    the last place of libm's; 0 below -708 (e^x is subnormal there). Branch-free."""
    shifted = x * (1.0 / math.log(2.0)) + MAGIC_F64  # rounds x / ln 2 to an integer n
    n = shifted - MAGIC_F64
    r = fma(-n, _LN2_LO, fma(-n, _LN2_HI, x))
    poly = 1.0 / 6227020800.0  # 1 / 13!
    for c in _EXP_TAYLOR:
        poly = fma(r, poly, c)
    two_n = two_to_the(shifted)
    return poly * two_n if x > -708.0 else 0.0


@numba.njit(cache=True, fastmath=FASTMATH, nogil=True)
def _exp_into(x, m):  # pragma: no cover - compiled
    """``x[:m] = e^x[:m]`` in place (:func:`_exp`; a loop of its own: it vectorises)."""
    for j in range(m):
        x[j] = _exp(x[j])


@numba.njit(cache=True, fastmath=FASTMATH, nogil=True)
def _sincos_into(x, sin_x, cos_x, m):  # pragma: no cover - compiled
    """:func:`_sincos` of ``x[:m]`` into ``sin_x``, ``cos_x`` (a loop of its own: it
    vectorises)."""
    for j in range(m):
        sin_x[j], cos_x[j] = _sincos(x[j])


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _x_factor(d, env, q, s, c, rs, rc, step_q, sq6, sq16, r, nwin, er, ei):
    # pragma: no cover - compiled
    """One kernel's x factor ``er + i ei`` over its window of ``nwin`` columns (a multiple
    of 4): ``env_k (c_k + i s_k)`` at offset ``d + k`` from the impulse, 0 outside
    ``|d + k| <= r``, with ``env_{k+1} = env_k q_k``, ``q_{k+1} = q_k step_q`` (the Gaussian's
    ratio) and ``c + i s`` turned by ``rc + i rs`` per column.

    As four chains, one per column mod 4, each stepping four columns at once:
    ``env_{k+4} = env_k q_k^4 step_q^6``, ``q_{k+4}^4 = q_k^4 step_q^16`` (``sq6``, ``sq16``),
    the carrier turned by ``(rc + i rs)^4``. The chains are independent, so their latencies
    overlap where one chain of ``nwin`` steps waited on each (measured, one kernel of 48
    columns: 167 -> 104 ns; the x factors were 40 of 145 ms of the noise at 64 impulses).
    They are stepped as one vector of four lanes (:func:`_four_chains`, the same numbers:
    the synthesis at 4K and 64 impulses, one thread, 133 -> 112-119 ms). The chains stop
    at the cut's last column."""
    # the cut: |d + k| grows away from the impulse, so the columns inside are one run; its
    # ends found by the test itself, from a guess one column out
    lo = max(int(math.ceil(-r - d)) - 1, 0)
    while lo < nwin and not abs(d + lo) <= r:
        lo += 1
    hi = min(max(int(math.floor(r - d)) + 1, lo), nwin - 1)
    while hi >= lo and not abs(d + hi) <= r:
        hi -= 1
    rc2, rs2 = rc * rc - rs * rs, 2.0 * rc * rs
    rc4, rs4 = rc2 * rc2 - rs2 * rs2, 2.0 * rc2 * rs2
    # each chain's first column by the one-column recurrence
    e0, c0, s0, g0 = env, c, s, q * q * q * q * sq6
    env *= q
    q *= step_q
    c, s = c * rc - s * rs, s * rc + c * rs
    e1, c1, s1, g1 = env, c, s, q * q * q * q * sq6
    env *= q
    q *= step_q
    c, s = c * rc - s * rs, s * rc + c * rs
    e2, c2, s2, g2 = env, c, s, q * q * q * q * sq6
    env *= q
    q *= step_q
    c, s = c * rc - s * rs, s * rc + c * rs
    e3, c3, s3, g3 = env, c, s, q * q * q * q * sq6
    # the columns [0, hi] four at a time, the four chains as one vector
    _four_chains(er, ei, (e0, e1, e2, e3), (g0, g1, g2, g3), (c0, c1, c2, c3),
                 (s0, s1, s2, s3), rc4, rs4, sq16, np.int64((hi + 4) // 4 if hi >= 0 else 0))
    for k in range(lo):
        er[k] = 0.0
        ei[k] = 0.0
    for k in range(max(hi + 1, 0), nwin):
        er[k] = 0.0
        ei[k] = 0.0


def _ir_vector(builder: ir.IRBuilder, values: list, vty: ir.VectorType) -> ir.Value:
    """An LLVM vector of ``vty`` from scalar IR values, lane by lane (the intrinsics below)."""
    out = ir.Constant(vty, ir.Undefined)
    for lane, x in enumerate(values):
        out = builder.insert_element(out, x, ir.Constant(ir.IntType(64), lane))
    return out


def _ir_splat(builder: ir.IRBuilder, x: ir.Value, vty: ir.VectorType) -> ir.Value:
    """``x`` in every lane of a vector of ``vty``."""
    one = _ir_vector(builder, [x], vty)
    zeros = ir.Constant(ir.VectorType(ir.IntType(32), vty.count), None)
    return builder.shuffle_vector(one, ir.Constant(vty, ir.Undefined), zeros)


def _ir_vector_at(builder: ir.IRBuilder, ptr: ir.Value, index: ir.Value,
                  vty: ir.VectorType) -> ir.Value:
    """A pointer to the vector of ``vty`` that starts at element ``index`` of ``ptr``."""
    return builder.bitcast(builder.gep(ptr, [index]), vty.as_pointer())


@intrinsic
def _four_chains(typingctx, er, ei, e, g, c, s, rc4, rs4, sq16, steps):
    # pragma: no cover - compiled
    """:func:`_x_factor`'s four chains stepped ``steps`` times, as one vector of four
    float64 lanes (chain ``p`` in lane ``p``; ``e``, ``g``, ``c``, ``s``: tuples of the four
    chains' values): step ``t`` writes ``er[4 t + p] = e_p c_p``, ``ei[4 t + p] = e_p s_p``
    (in ``er``'s dtype), then ``e_p *= g_p``, ``g_p *= sq16``, and ``c_p + i s_p`` turned
    by ``rc4 + i rs4``: each lane the scalar chain's operations, in their order (as
    scalars, 36 multiplies, adds and conversions a step). Measured: the synthesis at 4K and
    64 impulses, one thread, 133 -> 112-119 ms (alternated three times)."""
    dt = er.dtype
    quads = (e, g, c, s)
    if not (dt in (types.float32, types.float64) and ei == er and er.layout == "C"
            and all(isinstance(t, types.UniTuple) and t.count == 4 and t.dtype == types.float64
                    for t in quads)
            and all(t == types.float64 for t in (rc4, rs4, sq16))
            and isinstance(steps, types.Integer) and steps.bitwidth == 64):
        return None
    f64 = ir.DoubleType()
    v4 = ir.VectorType(f64, 4)
    out_elem = ir.FloatType() if dt == types.float32 else f64
    out_v4 = ir.VectorType(out_elem, 4)
    align = 4 if dt == types.float32 else 8
    i64 = ir.IntType(64)

    def codegen(context, builder, signature, args):
        er_v, ei_v, e_t, g_t, c_t, s_t, rc4_v, rs4_v, sq16_v, steps_v = args
        er_p = context.make_array(signature.args[0])(context, builder, er_v).data
        ei_p = context.make_array(signature.args[1])(context, builder, ei_v).data

        def lanes(t):
            return _ir_vector(builder, [builder.extract_value(t, p) for p in range(4)], v4)

        state = [cgutils.alloca_once_value(builder, lanes(t)) for t in (e_t, g_t, c_t, s_t)]
        rc4_4, rs4_4, sq16_4 = (_ir_splat(builder, x, v4) for x in (rc4_v, rs4_v, sq16_v))
        with cgutils.for_range(builder, steps_v) as loop:
            ev, gv, cv, sv = (builder.load(a) for a in state)
            first = builder.mul(loop.index, ir.Constant(i64, 4))
            for ptr, part in ((er_p, cv), (ei_p, sv)):
                value = builder.fmul(ev, part)
                if out_elem != f64:
                    value = builder.fptrunc(value, out_v4)
                builder.store(value, _ir_vector_at(builder, ptr, first, out_v4), align=align)
            builder.store(builder.fmul(ev, gv), state[0])
            builder.store(builder.fmul(gv, sq16_4), state[1])
            builder.store(builder.fsub(builder.fmul(cv, rc4_4), builder.fmul(sv, rs4_4)),
                          state[2])
            builder.store(builder.fadd(builder.fmul(sv, rc4_4), builder.fmul(cv, rs4_4)),
                          state[3])
        return context.get_dummy_value()

    return types.none(er, ei, e, g, c, s, rc4, rs4, sq16, steps), codegen


#: Impulses whose set-up (:func:`_splat_band`) is computed together, in loops that vectorise
#: (a multiple of :data:`_Y_LANES`).
SETUP_GROUP = 64


@numba.njit(cache=True, fastmath=FASTMATH, nogil=True)
def _splat_band(
    out, y0, y1, pad, xs, ys, amp, kf, tf, idx, r, a, nwin, er, ei, yf, su
):  # pragma: no cover - compiled
    """Add the kernels of impulses ``idx`` to rows [y0, y1) of ``out`` (band-local rows,
    columns shifted by ``pad``). The kernel is truncated to the square of half-side ``r``
    (its envelope is at most 1 % on the square's edges), so each row is one fixed-width
    multiply-add over ``nwin`` pixels, in ``out``'s dtype. Impulse ``i`` has angular
    frequency ``kf[i]`` (rad/px) along direction ``tf[i]`` (rad). Each kernel's two factors
    start from their values at the window's first column and row, set up for
    :data:`SETUP_GROUP` impulses at a time into ``su`` (21, group); the y factors of the
    group's rows are then stepped for all of them at once (:func:`_y_factors`, into ``yf``,
    in ``out``'s dtype)."""
    pa2 = math.pi * a * a
    step_q = math.exp(-2.0 * pa2)
    sq6, sq16 = step_q**6, step_q**16
    rr = int(math.ceil(r))
    group = su.shape[1]
    n = idx.shape[0]
    flat = out.reshape(-1)  # the band's rows (C-contiguous), indexed as one (_kernel_rows)
    stride = out.shape[1]
    for g0 in range(0, n, group):
        m = min(n, g0 + group) - g0
        # the carrier's direction, then the factors' phases and the envelopes' exponents,
        # then the phases' sines and cosines and the exponentials (loops that vectorise)
        for j in range(m):
            su[20, j] = tf[idx[g0 + j]]
        _sincos_into(su[20], su[18], su[19], m)
        for j in range(m):
            i = idx[g0 + j]
            kx, ky = kf[i] * su[19, j], kf[i] * su[18, j]
            dx = (math.floor(xs[i]) - rr) - xs[i]
            dy = max(y0, math.ceil(ys[i] - r)) - ys[i]
            su[0, j], su[1, j] = dx, dy
            su[2, j], su[3, j], su[4, j], su[5, j] = kx * dx, kx, ky * dy, ky
            su[14, j] = -pa2 * dx * dx
            su[15, j] = -pa2 * dy * dy
            su[16, j] = -pa2 * (2.0 * dx + 1.0)
            su[17, j] = -pa2 * (2.0 * dy + 1.0)
        for p in range(4):  # rows 6 + 2 p and 7 + 2 p: sin and cos of row 2 + p
            _sincos_into(su[2 + p], su[6 + 2 * p], su[7 + 2 * p], m)
        for p in range(14, 18):  # the envelopes and their ratios: e^ of rows 14 to 17
            _exp_into(su[p], m)
        rows = 0  # the most rows a kernel of the group has in this band
        for j in range(m):
            i = idx[g0 + j]
            su[15, j] *= amp[i]  # the y factor scaled by the impulse's amplitude
            rows = max(rows, min(y1 - 1, int(math.floor(ys[i] + r)))
                       - max(y0, int(math.ceil(ys[i] - r))) + 1)
        _y_factors(su, np.int64(m), np.int64(rows), step_q, yf)
        for j in range(m):
            i = idx[g0 + j]
            yi = ys[i]
            ya = max(y0, int(math.ceil(yi - r)))
            yb = min(y1 - 1, int(math.floor(yi + r)))
            x0 = int(math.floor(xs[i])) - rr  # window start, image columns
            # x factor by recurrence (envelope ratio and carrier rotation), zero outside
            # |d| <= r
            _x_factor(su[0, j], su[14, j], su[16, j], su[6, j], su[7, j], su[8, j], su[9, j],
                      step_q, sq6, sq16, r, nwin, er, ei)
            xo = x0 + pad
            # the window of both presets' kernels (48 px) in vectors held over the rows
            # (_vector_rows); any other width in a loop (one more copy per width costs
            # compile time)
            at = np.uint64((ya - y0) * stride + xo)  # the window's first value in flat
            if nwin == 3 * _VECTOR_LANES:
                _vector_rows(flat, np.uint64(stride), at, np.int64(yb - ya + 1), er, ei,
                             yf[0], yf[1], np.int64(j), 3)
            else:
                _kernel_rows(flat, stride, at, yb - ya + 1, nwin, er, ei, yf[0], yf[1], j)


#: Kernels whose y factors :func:`_y_factors` steps as one vector (two of AVX-512's, four of
#: AVX2's: independent lanes, so one row's steps do not wait on the last's).
_Y_LANES = 16


@intrinsic
def _y_factors(typingctx, su, m, rows, step_q, yf):  # pragma: no cover - compiled
    """The y factors of the first ``rows`` rows of the ``m`` kernels set up in ``su``
    (:func:`_splat_band`: rows 10 to 13 the carrier's sine and cosine at the first row and
    its turn per row, 15 the envelope there times the amplitude, 17 its ratio to the next),
    into ``yf[0, row, j]`` (real) and ``yf[1, row, j]`` (imaginary), in ``yf``'s dtype:
    ``env (c + i s)``, then ``env`` times the ratio, the ratio times ``step_q``, and the
    carrier turned. Each kernel's steps are its own recurrence's, in the same order; the
    kernels go :data:`_Y_LANES` at a time, as the lanes of one vector held in registers
    over the rows (``su`` and ``yf``, C-contiguous, have a multiple of it columns; lanes
    past ``m`` step whatever ``su`` holds there, and their factors are not read). Stepped
    kernel by kernel, each row waited on the last row's carrier turn (a multiply, then a
    subtraction), and the rows' multiply-adds waited with it; in a loop over the kernels,
    each row's state went through memory. Measured against that loop: the synthesis at 4K
    and 64 impulses, one thread, 124-137 -> 112-136 ms (alternated three times: a noisy
    hour, faster in two of three)."""
    dt = yf.dtype
    if not (isinstance(su, types.Array) and su.dtype == types.float64 and su.ndim == 2
            and isinstance(yf, types.Array) and yf.ndim == 3 and su.layout == yf.layout == "C"
            and dt in (types.float32, types.float64) and step_q == types.float64
            and all(isinstance(t, types.Integer) and t.bitwidth == 64 for t in (m, rows))):
        return None
    f64 = ir.DoubleType()
    vty = ir.VectorType(f64, _Y_LANES)
    out_elem = ir.FloatType() if dt == types.float32 else f64
    out_vty = ir.VectorType(out_elem, _Y_LANES)
    align = 4 if dt == types.float32 else 8
    i64 = ir.IntType(64)

    def codegen(context, builder, signature, args):
        su_v, m_v, rows_v, step_v, yf_v = args
        su_a = context.make_array(signature.args[0])(context, builder, su_v)
        yf_a = context.make_array(signature.args[4])(context, builder, yf_v)
        group = builder.extract_value(su_a.shape, 1)  # su's columns
        yf_rows, yf_cols = (builder.extract_value(yf_a.shape, k) for k in (1, 2))

        def su_row(k, j0):
            index = builder.add(builder.mul(ir.Constant(i64, k), group), j0)
            return builder.load(_ir_vector_at(builder, su_a.data, index, vty), align=8)

        step = _ir_splat(builder, step_v, vty)
        blocks = builder.udiv(builder.add(m_v, ir.Constant(i64, _Y_LANES - 1)),
                              ir.Constant(i64, _Y_LANES))
        with cgutils.for_range(builder, blocks) as block:
            j0 = builder.mul(block.index, ir.Constant(i64, _Y_LANES))
            s0, c0, rs, rc = (su_row(k, j0) for k in (10, 11, 12, 13))
            state = [cgutils.alloca_once_value(builder, v)
                     for v in (su_row(15, j0), su_row(17, j0), c0, s0)]
            with cgutils.for_range(builder, rows_v) as loop:
                env, q, c, s = (builder.load(a) for a in state)
                for part, value in enumerate((builder.fmul(env, c), builder.fmul(env, s))):
                    if out_elem != f64:
                        value = builder.fptrunc(value, out_vty)
                    row = builder.add(builder.mul(ir.Constant(i64, part), yf_rows), loop.index)
                    index = builder.add(builder.mul(row, yf_cols), j0)
                    builder.store(value, _ir_vector_at(builder, yf_a.data, index, out_vty),
                                  align=align)
                builder.store(builder.fmul(env, q), state[0])
                builder.store(builder.fmul(q, step), state[1])
                builder.store(builder.fsub(builder.fmul(c, rc), builder.fmul(s, rs)), state[2])
                builder.store(builder.fadd(builder.fmul(s, rc), builder.fmul(c, rs)), state[3])
        return context.get_dummy_value()

    return types.none(su, m, rows, step_q, yf), codegen


assert SETUP_GROUP % _Y_LANES == 0, "_y_factors steps whole vectors of a group's columns"


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def _kernel_rows(flat, stride, at, rows, nwin, er, ei, fr, fi, j):
    # pragma: no cover - compiled
    """``rows`` rows of kernel ``j`` of its group added to the rows of ``stride`` values in
    ``flat``, from its index ``at`` (the window's first column in the kernel's first row):
    the x factor ``er + i ei`` times the row's y factor ``fr[row, j] + i fi[row, j]``
    (:func:`_y_factors`), each value ``fma(cr, er, fma(-ci, ei, v))``. The presets'
    48-column window goes through :func:`_vector_rows` instead (the same operations, the x
    factor held in registers over the rows); any other width through this loop.

    The index is unsigned (``at``, ``k``): an index of unknown sign made Numba wrap negative
    indices and kept the loop scalar (2x slower), and a row slice per row cost its bounds'
    clamping (measured on the rows alone, 4K, 64 impulses: 112 -> 94 ms on one thread)."""
    step = np.uint64(stride)
    for row in range(rows):
        cr, ci = fr[row, j], fi[row, j]
        for k in range(np.uint64(nwin)):  # + cr er - ci ei as two fused multiply-adds
            at_k = at + k
            flat[at_k] = fma(cr, er[k], fma(-ci, ei[k], flat[at_k]))
        at += step


#: Columns of one vector of :func:`_vector_rows` (a kernel window's width is a multiple).
_VECTOR_LANES = WINDOW_MULTIPLE


@intrinsic(prefer_literal=True)
def _vector_rows(typingctx, flat, stride, at, rows, er, ei, fr, fi, j, nvec):
    # pragma: no cover - compiled
    """:func:`_kernel_rows` of a window of ``nvec`` (a constant) vectors of
    :data:`_VECTOR_LANES` columns, float32 or float64 (every array's dtype), the same
    operations on each value. The x factor is loaded into ``2 nvec`` vectors once; each row
    is then ``nvec`` loads, two fused multiply-adds and stores of ``flat``. In the loop, the
    compiler reloaded the x factor on every row, as ``flat``'s stores might have changed it
    (Numba does not tell it that two arrays do not overlap): three loads for each store.
    Measured (2-core VM): the rows alone, one thread, windows spread as in a band, 5.2 ->
    2.8 ns a row; the synthesis at 4K and 64 impulses, with :func:`_y_factors`, alternated
    with the loop four times: 77-89 -> 72-82 ms (one thread 144 -> 128 ms)."""
    dt = flat.dtype
    if not (isinstance(nvec, types.IntegerLiteral) and dt in (types.float32, types.float64)
            and all(isinstance(a, types.Array) and a.dtype == dt and a.layout == "C"
                    for a in (flat, er, ei, fr, fi))
            and all(isinstance(t, types.Integer) and t.bitwidth == 64
                    for t in (stride, at, rows, j))):
        return None
    n = nvec.literal_value
    single = dt == types.float32
    vty = ir.VectorType(ir.FloatType() if single else ir.DoubleType(), _VECTOR_LANES)
    align = 4 if single else 8
    fma_name = f"llvm.fma.v{_VECTOR_LANES}{'f32' if single else 'f64'}"
    i64 = ir.IntType(64)

    def codegen(context, builder, signature, args):
        flat_v, stride_v, at_v, rows_v, er_v, ei_v, fr_v, fi_v, j_v, _ = args
        er_a, ei_a, fr_a, fi_a = (context.make_array(t)(context, builder, v) for t, v in
                                  zip(signature.args[4:8], (er_v, ei_v, fr_v, fi_v),
                                      strict=True))
        cols = builder.extract_value(fr_a.shape, 1)  # fr's and fi's rows (C-contiguous)
        data = context.make_array(signature.args[0])(context, builder, flat_v).data
        fma_v = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(vty, [vty, vty, vty]), fma_name)

        def vector_at(ptr, index):
            return _ir_vector_at(builder, ptr, index, vty)

        def splat(x):
            return _ir_splat(builder, x, vty)

        def offset(v):
            return ir.Constant(i64, _VECTOR_LANES * v)

        xr = [builder.load(vector_at(er_a.data, offset(v)), align=align) for v in range(n)]
        xi = [builder.load(vector_at(ei_a.data, offset(v)), align=align) for v in range(n)]
        with cgutils.for_range(builder, rows_v) as loop:
            row = loop.index
            at_row = builder.add(builder.mul(row, cols), j_v)
            cr = splat(builder.load(builder.gep(fr_a.data, [at_row])))
            minus_ci = splat(builder.fneg(builder.load(builder.gep(fi_a.data, [at_row]))))
            first = builder.add(at_v, builder.mul(row, stride_v))
            for v in range(n):  # fma(cr, er, fma(-ci, ei, value)), as the loop computes it
                ptr = vector_at(data, builder.add(first, offset(v)))
                value = builder.call(fma_v, [minus_ci, xi[v], builder.load(ptr, align=align)])
                builder.store(builder.call(fma_v, [cr, xr[v], value]), ptr, align=align)
        return context.get_dummy_value()

    return types.none(flat, stride, at, rows, er, ei, fr, fi, j, nvec), codegen


def _window(r: float) -> tuple[int, int]:
    """(nwin, pad): the kernel row's fixed width and the columns padded on each side. An
    impulse's window starts ``ceil(r)`` columns left of it, and an impulse as far as ``r``
    left of the image still reaches it: the pad of ``2 ceil(r) + 2`` keeps every window
    inside the padded row (its start at column 0 or later)."""
    rr = int(math.ceil(r))
    return ((2 * rr + 2 + WINDOW_MULTIPLE - 1) // WINDOW_MULTIPLE) * WINDOW_MULTIPLE, 2 * rr + 2


@numba.njit(cache=True, fastmath=FASTMATH, nogil=True)
def _band_impulses(xs, ys, row_start, cell, r, y0, y1, width):  # pragma: no cover - compiled
    """The impulses whose kernel's first row in the image lies in rows [y0, y1) and which
    reach the image at all (their indices). Those whose first row is above the image belong
    to the band at the top."""
    n_rows = row_start.shape[0] - 1
    # cell rows (cell_index) of the impulses with ceil(y - r) in [y0, y1), one more each side
    j0 = max(int(math.floor((y0 - 1 + r - CELL_ORIGIN_PX) / cell)) + CELL_BORDER - 1, 0)
    j1 = min(int(math.floor((y1 + r - CELL_ORIGIN_PX) / cell)) + CELL_BORDER + 1, n_rows - 1)
    if y0 == 0:
        j0 = 0
    # a band whose rows lie past the last cell row's reach (a kernel radius wider than the
    # cells near the image's bottom) holds none: j0 past j1 + 1 read past row_start's end
    j0 = min(j0, j1 + 1)
    idx = np.empty(row_start[j1 + 1] - row_start[j0], dtype=np.int64)
    n = 0
    for i in range(row_start[j0], row_start[j1 + 1]):
        yi, xi = ys[i], xs[i]
        first = max(0, int(math.ceil(yi - r)))
        # a kernel that reaches no row or column of the image adds nothing to it; the border
        # cells' impulses lie up to a cell past the edge, farther than a kernel cut closer
        # than the default reaches, and their window would start past the padded row's end
        if (first < y0 or first >= y1 or int(math.floor(yi + r)) < first
                or xi + r < 0.0 or xi - r > width - 1):
            continue
        idx[n] = i
        n += 1
    return idx[:n]


@numba.njit(cache=True, fastmath=FASTMATH, nogil=True)
def _kernels(x, y, weight, index, amplitude, frequency, carrier, norm, skip, cell, r, band,
             height, nwin, xs, ys, amp, k, t, row_start, touched, cols):
    # pragma: no cover - compiled
    """The kernels :func:`_splat` sums, in one pass over the impulses (``x``, ``y``,
    ``weight``: every impulse's; ``amplitude``, ``frequency``, ``carrier``: those of the
    impulses ``index``, ascending, the others' 0): each one's position, its amplitude
    ``w K norm``, its angular frequency ``2 pi F`` and its carrier direction, into ``xs``,
    ``ys``, ``amp``, ``k``, ``t`` (in impulse order; with ``skip``, those with a zero
    amplitude left out); ``row_start[q]``, how many lie in cell rows below ``q`` (the
    impulses are sorted by cell row: NumPy's ``searchsorted``); and the bands of ``band``
    rows a kernel may reach (``touched``: the band of its first row, and the next) and, per
    band, the image columns its kernels' windows span (``cols[b]``: [start, stop), those of
    the kernels whose first row lies in it or in the band before; empty, stop <= start, for
    none). The same numbers as NumPy's gathers, scatter and passes, which took 25 ms of the
    noise at 4K and 64 impulses (the pipeline's scatter into every impulse's arrays
    included), in one pass. The count kept."""
    n = x.shape[0]
    given = index.shape[0]
    n_rows = row_start.shape[0] - 1
    counts = np.zeros(n_rows + 2, np.int64)  # bucket q + 1: cell row q (clamped)
    first = np.zeros(touched.shape[0], np.bool_)
    nb = touched.shape[0]
    lo = np.full(nb, np.iinfo(np.int64).max, np.int64)  # the windows' columns per band
    hi = np.full(nb, np.iinfo(np.int64).min, np.int64)
    rr = int(math.ceil(r))
    m = 0
    j = 0
    for i in range(n):
        a, f, c = 0.0, 0.0, 0.0
        if j < given and index[j] == i:
            a, f, c = amplitude[j], frequency[j], carrier[j]
            j += 1
        a = np.float64(weight[i]) * a * norm
        if skip and a == 0.0:
            continue
        yi = y[i]
        xs[m], ys[m], amp[m], k[m], t[m] = x[i], yi, a, 2.0 * np.pi * f, c
        row = _cell_of(yi, cell)
        counts[min(max(row + 1, 0), n_rows + 1)] += 1
        y0 = min(max(math.ceil(yi - r), 0.0), height - 1.0)
        b = np.int64(y0) // band
        first[b] = True
        x0 = np.int64(math.floor(x[i])) - rr  # the window's first column (_splat_band)
        lo[b] = min(lo[b], x0)
        hi[b] = max(hi[b], x0 + nwin)
        m += 1
    total = 0
    for q in range(n_rows + 1):
        total += counts[q]
        row_start[q] = total
    for b in range(nb):
        touched[b] = first[b] or (b > 0 and first[b - 1])
        cols[b, 0], cols[b, 1] = lo[b], hi[b]
        if b > 0 and first[b - 1]:
            cols[b, 0] = min(cols[b, 0], lo[b - 1])
            cols[b, 1] = max(cols[b, 1], hi[b - 1])
        if not touched[b]:
            cols[b, 0] = cols[b, 1] = 0
    return m


@numba.njit(parallel=True, cache=True, fastmath=FASTMATH, nogil=True)
def _splat(sums, out, x, y, weight, index, amplitude, frequency, carrier, norm, skip, cell, r, a,
           band, nwin, pad, xs, ys, amp, k, t, row_start, touched, cols, spans):
    # pragma: no cover - compiled
    """The kernels of the impulses (:func:`_kernels`, into ``xs`` .. ``touched``, in this
    kernel: one compiled function to load, not two) summed into the padded rows ``sums``,
    then the image columns copied into ``out`` (H, W). Each kernel is added whole by the
    band of ``band`` rows its first row lies in (:func:`_splat_band`,
    :func:`_band_impulses`): its set-up is done once, where a kernel cut at band edges was
    set up again in each band it crosses (measured: 1.7 set-ups per impulse with noise, at
    4K and 64 impulses). A kernel reaches at most ``2 ceil(r) + 1`` rows into the next band
    (``band`` is taller), so the even bands go in parallel, then the odd ones: no two bands
    running at once write one row. A row's sums are then in the same order whatever the
    thread count. Each odd band copies its rows and the next band's out once they are final
    (the first band copies its own). ``sums`` need not be zeros: the bands ``touched``
    marks (those that may receive a kernel) are zeroed first, on the columns their kernels'
    windows span (``cols``); the others are never read. Of ``out`` only those columns are
    written, in the image, each row's in ``spans`` (the noise is 0 elsewhere:
    :class:`fovexp.memory.WrittenRows`)."""
    height = out.shape[0]
    width = out.shape[1]
    m = _kernels(x, y, weight, index, amplitude, frequency, carrier, norm, skip, cell, r, band,
                 height, nwin, xs, ys, amp, k, t, row_start, touched, cols)
    kx, ky, kamp, kk, kt = xs[:m], ys[:m], amp[:m], k[:m], t[:m]
    nb = (height + band - 1) // band
    reach = 2 * int(math.ceil(r)) + 2  # rows past its band's end a kernel may write
    spread = interleave(nb)  # the touched bands, often all in one part of the frame
    for i in numba.prange(nb):
        b = (i * spread) % nb
        if touched[b]:
            # the padded row's columns the windows span (every window lies inside it)
            p0 = min(max(cols[b, 0] + pad, 0), sums.shape[1])
            p1 = min(max(cols[b, 1] + pad, p0), sums.shape[1])
            for y in range(b * band, min(height, (b + 1) * band)):
                row = sums[y, p0:p1]
                for x in range(row.shape[0]):
                    row[x] = 0.0
    for parity in range(2):
        nbp = (nb - parity + 1) // 2  # bands of this parity
        stride = interleave(nbp)  # bands without impulses cost nothing: spread the others
        for i in numba.prange(nbp):
            b = 2 * ((i * stride) % nbp) + parity
            y0 = b * band
            y1 = min(height, y0 + band)
            ye = min(height, y1 + reach)
            er = np.empty(nwin, dtype=sums.dtype)
            ei = np.empty(nwin, dtype=sums.dtype)
            yf = np.empty((2, 2 * int(math.ceil(r)) + 1, SETUP_GROUP), dtype=sums.dtype)
            # zeros: what _y_factors steps in the lanes past a group's last kernel, at first
            su = np.zeros((21, SETUP_GROUP), dtype=np.float64)
            idx = _band_impulses(kx, ky, row_start, cell, r, y0, y1, width)
            _splat_band(sums[y0:ye], y0, ye, pad, kx, ky, kamp, kk, kt, idx, r, a, nwin, er, ei,
                        yf, su)
            if parity == 0 and b != 0:
                continue
            c1 = min(height, y1 + band) if parity == 1 else y1  # this band and the next
            for y in range(y0, c1):
                bb = y // band
                # the image columns the row's kernels span (none where no kernel reaches it)
                x0 = min(max(cols[bb, 0], 0), width)
                x1 = min(max(cols[bb, 1], x0), width) if touched[bb] else x0
                spans[y, 0], spans[y, 1] = x0, x1
                dst, src = out[y, x0:x1], sums[y, pad + x0:pad + x1]
                for x in range(x1 - x0):
                    dst[x] = src[x]


@overload
def synthesize(
    shape: tuple[int, int],
    impulses: Impulses,
    amplitude: np.ndarray,
    frequency_cpp: np.ndarray,
    carrier_rad: np.ndarray,
    impulses_per_kernel: int,
    gabor_a_cpp: float,
    truncation: float = KERNEL_TRUNCATION,
    skip: bool = True,
    dtype: np.dtype | type = np.float32,
    index: np.ndarray | None = None,
    written: Literal[False] = False,
) -> np.ndarray: ...


@overload
def synthesize(
    shape: tuple[int, int],
    impulses: Impulses,
    amplitude: np.ndarray,
    frequency_cpp: np.ndarray,
    carrier_rad: np.ndarray,
    impulses_per_kernel: int,
    gabor_a_cpp: float,
    truncation: float = KERNEL_TRUNCATION,
    skip: bool = True,
    dtype: np.dtype | type = np.float32,
    index: np.ndarray | None = None,
    *,
    written: Literal[True],
) -> WrittenRows: ...


def synthesize(
    shape: tuple[int, int],
    impulses: Impulses,
    amplitude: np.ndarray,
    frequency_cpp: np.ndarray,
    carrier_rad: np.ndarray,
    impulses_per_kernel: int,
    gabor_a_cpp: float,
    truncation: float = KERNEL_TRUNCATION,
    skip: bool = True,
    dtype: np.dtype | type = np.float32,
    index: np.ndarray | None = None,
    written: bool = False,
) -> np.ndarray | WrittenRows:
    """Sum the Gabor kernels of ``impulses`` into an (H, W) noise image of ``dtype``.

    ``amplitude`` is K per impulse (in the release's units: the local std is K / 6),
    ``frequency_cpp`` F per impulse, ``carrier_rad`` the carrier direction t per impulse;
    with ``index`` (ascending impulse indices), the three are those impulses' and every
    other impulse's K is 0. The kernels are cut where their envelope is ``truncation``.
    With ``skip``, impulses with zero amplitude (empty band, flat surround, no headroom)
    cost nothing; without, every impulse is summed (adding exact zeros: the same result,
    for measuring the saving). ``written``: the noise as a :class:`fovexp.memory.WrittenRows`,
    written only on the columns each row's kernels span (its zeros elsewhere not written).
    """
    h, w = shape
    n = len(impulses)
    if index is None:
        index = np.arange(n)
    index = np.asarray(index, np.int64)
    per = [np.ascontiguousarray(v, np.float64).reshape(-1)
           for v in (amplitude, frequency_cpp, carrier_rad)]
    if any(v.size != index.size for v in per):
        raise ValueError(f"amplitude, frequency and carrier need {index.size} values each")
    if index.size and (index[0] < 0 or index[-1] >= n or (np.diff(index) <= 0).any()):
        raise ValueError("index must hold ascending impulse indices")
    cell = impulses.cell_px
    r = kernel_radius_px(gabor_a_cpp, truncation)
    nwin, pad = _window(r)
    band = max(BAND_ROWS, 2 * int(math.ceil(r)) + 2)  # a kernel reaches into the next band only
    if skip and not per[0].any():  # no kernel: no buffers, no pass
        if not written:
            return frame_zeros(shape, dtype)
        return WrittenRows(frame_empty(shape, dtype), np.zeros((h, 2), np.int64))
    size = index.size if skip else n
    xs, ys, amp, k, t = (np.empty(size) for _ in range(5))
    row_start = np.empty(cell_counts(w, h, cell)[1] + 1, np.int64)
    touched = np.empty(-(-h // band), np.bool_)
    cols = np.empty((touched.shape[0], 2), np.int64)
    spans = np.empty((h, 2), np.int64)
    # the sums in padded rows, zeroed in the touched bands only, on their kernels' columns;
    # those columns of each band copied into the result once the band is done
    sums = frame_empty((h, w + 2 * pad + nwin), dtype)
    noise = WrittenRows(frame_empty(shape, dtype), spans)
    _splat(sums, noise.values, impulses.x_px, impulses.y_px, impulses.weight, index, *per,
           normalisation(impulses_per_kernel, gabor_a_cpp, impulses.weights, truncation), skip,
           cell, r, gabor_a_cpp, band, nwin, pad, xs, ys, amp, k, t, row_start, touched, cols,
           spans)
    return noise if written else noise.full()
