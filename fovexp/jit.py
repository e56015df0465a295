"""How every Numba kernel of the package is compiled (one definition for all stage modules).

``FASTMATH`` is off, for bit-identical output: the same seed gives the same bytes however
the kernels were compiled (in this process, loaded from the cache, one thread or many).

Why (measured, issue 10): with ``fastmath=True`` the first run after installing differed from
every later run by 1 LSB in about 700 pixels of a 4K frame. Numba compiles the body of a
``prange`` loop as a separate library (the parfor gufunc) that is JIT-compiled and optimised
on its own, and also linked into the kernel's library and optimised a second time there. The
process that compiles a kernel runs the first copy; the on-disk cache holds, and every later
process runs, the second. Fast-math lets LLVM reassociate and fuse (FMA) floating-point
operations, and the two optimisations did so differently (``pyramids._reduce_2d`` alone:
451,900 of 2.07 M level-1 values differ between a fresh and a cached compile). With IEEE
semantics the optimiser may not change any result, so every copy computes the same bits.
The kernels are memory-bound: fast-math saved no measurable time (CPU seconds of the 4K
enhancement with 12 impulses, three interleaved rounds on the shared 2-core VM: 1.65-1.90 s
with it, 1.86-1.94 s without; end to end against the landed main: benchmarks/CLI.md).

Large outputs (whole frames, the contrast's summed-area table) are allocated by NumPy and
passed into the kernels, not allocated inside them: NumPy asks Linux for transparent huge pages
on large arrays (``madvise``), Numba's allocator does not, and the first writes to fresh 4 KiB
pages cost several times more (measured on the 2-core VM: a 33 MB array written once took
12-17 ms from a kernel's own allocation, 4-5 ms from NumPy's, 1.1-1.5 ms written again).

Formulas evaluated at arbitrary points (the eccentricity, px/deg and sigma of a few corners or
samples) are plain kernels over 1-D arrays (:func:`flat_broadcast`), not Numba ufuncs: a
ufunc's loop wrapper is built by LLVM in every process, at import for one with signatures
(measured about 0.1 s each on the 2-core VM), where a kernel is loaded from the cache.

Kernels use no cross-thread reductions either, so the thread count does not change a result
(``tests/enhancer/test_determinism.py`` checks both across processes).
"""

from __future__ import annotations

import numba
import numpy as np
from llvmlite import ir
from numba.core import types
from numba.extending import intrinsic
from numpy.typing import ArrayLike

#: Numba's ``fastmath`` flag of every kernel: off (see the module docstring). Numba's cache
#: does not notice a change here (it checks the kernels' own files): after changing it, delete
#: the cached kernels (``fovexp/__pycache__/*.nbi``, ``*.nbc``) and run ``fovexp compile``.
FASTMATH = False


def flat_broadcast(
    *arrays: ArrayLike, dtype: type = np.float64,
) -> tuple[tuple[int, ...], list[np.ndarray]]:
    """The shape ``arrays`` broadcast to (NumPy's rules), and each of them broadcast to it,
    as a contiguous 1-D array of ``dtype``: what a kernel looping over points takes in place
    of a ufunc's broadcasting (its result is reshaped to the shape)."""
    full = np.broadcast_arrays(*(np.asarray(a, dtype=dtype) for a in arrays))
    return full[0].shape, [np.ascontiguousarray(a).reshape(-1) for a in full]


# ---------------------------------------------------------------- exact integer <-> float64
# x86-64 without AVX-512 has no vector instruction converting between int64 and float64: a
# loop with such a conversion stays scalar (the contrast's per-pixel box sums measured 2x
# slower). For integers of magnitude below 2**51 the conversion is exact as an add and a
# reinterpretation of the bits: 1.5 * 2**52 + i is a double whose low mantissa bits are i, and
# IEEE rounding to nearest even in that add is the rounding ``rint`` does. Both vectorise.
#: 1.5 * 2**52, and its bits: the magic constant of :func:`int64_to_float64` and
#: :func:`rint_to_int64`.
MAGIC_F64 = 6755399441055744.0
MAGIC_BITS = int(np.array([MAGIC_F64]).view(np.int64)[0])
#: The magnitude below which the two conversions are exact.
MAGIC_EXACT_BELOW = 2**51


@intrinsic
def _bits_as_float64(typingctx, bits):  # pragma: no cover - compiled
    """The float64 whose bits are the int64 ``bits``."""
    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.DoubleType())
    return types.float64(types.int64), codegen


@intrinsic
def _float64_bits(typingctx, value):  # pragma: no cover - compiled
    """The bits of the float64 ``value``, as an int64."""
    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], ir.IntType(64))
    return types.int64(types.float64), codegen


@intrinsic
def fma(typingctx, a, b, c):  # pragma: no cover - compiled
    """``a * b + c`` rounded once (LLVM's ``llvm.fma``: the FMA instruction on every x86-64
    since 2013, a library call elsewhere), in float32 when all three are float32, else in
    float64. Written out where a polynomial or a multiply-add loop wants it: ``FASTMATH`` is
    off, so LLVM may not fuse a multiply and an add itself, and an explicit FMA is the same
    instruction in every compile of a kernel (the bits do not change between a fresh and a
    cached one, as they did under fast-math)."""
    single = all(t == types.float32 for t in (a, b, c))
    ty = types.float32 if single else types.float64

    def codegen(context, builder, signature, args):
        args = [context.cast(builder, v, t, ty) for v, t in
                zip(args, signature.args, strict=True)]
        return builder.fma(*args)
    return ty(a, b, c), codegen


@intrinsic
def as_dtype_of(typingctx, array, value):  # pragma: no cover - compiled
    """``value`` converted to ``array``'s dtype (a float64 rounded to float32 for a float32
    array), as storing it in the array converts it: a kernel's value that NumPy code had
    held in an array of that dtype keeps its bits."""
    ty = array.dtype

    def codegen(context, builder, signature, args):
        return context.cast(builder, args[1], signature.args[1], ty)
    return ty(array, value), codegen


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def two_to_the(shifted):  # pragma: no cover - compiled
    """``2**n`` as a float64, for the integer ``n`` held in ``shifted = n + MAGIC_F64`` (a
    float rounded to an integer by that addition; ``|n| <= 1022``): its exponent field
    written directly, where ``ldexp`` is a call per value. The exponentials' last step
    (:mod:`fovexp.colour`'s power, :mod:`fovexp.gabor`'s e^x)."""
    return _bits_as_float64((_float64_bits(shifted) - MAGIC_BITS + 1023) << 52)


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def int64_to_float64(i):  # pragma: no cover - compiled
    """``float64(i)``, exact for ``|i| < 2**51``; a conversion that vectorises."""
    return _bits_as_float64(i + MAGIC_BITS) - MAGIC_F64


@numba.njit(cache=True, inline="always", fastmath=FASTMATH, nogil=True)
def rint_to_int64(x):  # pragma: no cover - compiled
    """``int64(rint(x))`` (to nearest, ties to even) for ``|x| < 2**51``; vectorises."""
    return _float64_bits(np.float64(x) + MAGIC_F64) - MAGIC_BITS
