
"""Work order of the compiled kernels' parallel loops.

Numba splits a ``prange`` statically, one contiguous chunk of iterations per thread. Where the
work per iteration depends on the content (rows, bands or tiles the enhancer skips because
they are flat or carry no noise), one thread can get all of it: a frame whose top half is
textured and bottom half flat would run on one core. So such loops visit their items in an
interleaved order, item ``(i * stride) % n`` at iteration ``i`` (:func:`interleave`), which
spreads every contiguous chunk over the whole frame. (Numba's dynamic chunking,
``set_parallel_chunksize``, costs far more than the work here: measured 20x on the |L| tiles.)
The results do not depend on the order: the items are independent.
"""

from __future__ import annotations

import math

import numba

from .jit import FASTMATH

#: The golden ratio's fractional part: multiples of it modulo 1 are spread the most evenly.
_GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0


@numba.njit(cache=True, fastmath=FASTMATH, nogil=True)
def interleave(n: int) -> int:
    """A stride coprime with ``n`` (so ``i -> (i * stride) % n`` visits every item once) near
    ``0.618 n``, so that consecutive iterations land far apart. Compiled: the kernels call
    it."""
    if n <= 2:
        return 1
    s = max(int(_GOLDEN * n + 0.5), 1)
    while math.gcd(s, n) != 1:
        s += 1
    return s
