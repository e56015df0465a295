
"""Work order of the compiled kernels' parallel loops.

Numba splits a ``prange`` statically, one contiguous chunk of iterations per thread. Where the
work per iteration depends on the content (rows, bands or tiles the enhancer skips because
they are flat or carry no noise), one thread can get all of it: a frame whose top half is
textured and bottom half flat would run on one core. So such loops visit their items in an
interleaved order, item ``(i * stride) % n`` at iteration ``i`` (:func:`interleave`), which
spreads every contiguous chunk over the whole frame. (Numba's dynamic chunking,
``set_parallel_chunksize``, costs far more than the work here: measured 20x on the |L| tiles.)
The results do not depend on the order: the items are independent.

NumPy's own elementwise loops run on one core; :func:`in_parts` splits one over threads: the
transfer function's power of float64 images (:func:`power`; float32 frames take a compiled
polynomial, :mod:`fovexp.colour`) and the output's conversion to integer codes
(:func:`fovexp.io.write_image`).
"""

from __future__ import annotations

import math
import os
import threading
import time
from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

import numba
import numpy as np

from .jit import FASTMATH

T = TypeVar("T")
R = TypeVar("R")

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


#: Below this many elements one call is faster than handing parts to threads.
_MIN_SPLIT = 1 << 16
#: The largest part :func:`in_parts` hands to a thread (elements).
_PART = 1 << 20
_pool: ThreadPoolExecutor | None = None
_pool_lock = threading.Lock()


def _threads() -> ThreadPoolExecutor:
    global _pool
    with _pool_lock:
        if _pool is None:
            _pool = ThreadPoolExecutor(max_workers=numba.config.NUMBA_NUM_THREADS,
                                       thread_name_prefix="fovexp-parts")
        return _pool


def _forget_threads() -> None:
    """In a forked child: the parent's pool threads do not exist there (work handed to them
    would wait for ever), so the child makes its own."""
    global _pool, _pool_lock
    _pool, _pool_lock = None, threading.Lock()


os.register_at_fork(after_in_child=_forget_threads)


def thread_count() -> int:
    """How many threads the package's parallel work uses: Numba's
    (:func:`numba.get_num_threads`)."""
    return numba.get_num_threads()


def thread_map(fn: Callable[[T], R], items: Iterable[T]) -> list[R]:
    """``[fn(item) for item in items]``, each call on a pool thread (for work that releases
    the GIL: NumPy's loops, zlib)."""
    return list(_threads().map(fn, items))


def in_parts(
    fn: Callable[[np.ndarray, np.ndarray], object], a: np.ndarray, out: np.ndarray,
) -> np.ndarray:
    """``fn(a, out)`` for an elementwise ``fn`` (each output value from the same input value
    alone), done on threads: C-contiguous arrays of the same shape go in contiguous parts of
    at most :data:`_PART` elements, as many parts at least as Numba has threads
    (:func:`numba.get_num_threads`), each part on a pool thread (NumPy's loops release the
    GIL; parts that small keep a part's temporaries in cache). The values are those of one
    call (tested). Returns ``out``."""
    threads = thread_count()
    parts = max(threads, -(-a.size // _PART))
    if threads < 2 or a.size < _MIN_SPLIT or not (
            a.flags.c_contiguous and out.flags.c_contiguous) or a.shape != out.shape:
        fn(a, out)
        return out
    src, dst = a.reshape(-1), out.reshape(-1)  # views: both are C-contiguous
    # part boundaries on 64-element multiples: every part starts aligned as the whole does
    edges = [src.size * i // parts // 64 * 64 for i in range(parts)] + [src.size]
    futures = [_threads().submit(fn, src[lo:hi], dst[lo:hi])
               for lo, hi in zip(edges[:-1], edges[1:], strict=True)]
    for f in futures:
        f.result()
    return out


#: Below this many points :func:`over_points` makes one call.
_MIN_POINTS = 1 << 14


def over_points(fn: Callable[..., R], *arrays: np.ndarray) -> R:
    """``fn(*arrays)`` for a ``fn`` that works point by point along the arrays' first axis
    (each output row from the same row of every input alone) and returns an array or a
    tuple of arrays of the points, done in as many contiguous parts as Numba has threads,
    each on a pool thread, the parts' outputs joined. For the per-impulse stages' NumPy and
    SciPy expressions, which release the GIL (at 4K and 64 impulses, 0.4 M impulses); ``fn``
    must not call a parallel Numba kernel (a threading layer may refuse concurrent calls).
    The values are those of one call (tested)."""
    n = len(arrays[0])
    threads = thread_count()
    if threads < 2 or n < _MIN_POINTS:
        return fn(*arrays)
    edges = [n * i // threads for i in range(threads + 1)]
    parts = thread_map(lambda i: fn(*(a[edges[i]:edges[i + 1]] for a in arrays)),
                       range(threads))
    if isinstance(parts[0], tuple):
        return tuple(np.concatenate(p) for p in zip(*parts, strict=True))  # type: ignore
    return np.concatenate(parts)  # type: ignore[return-value]


def power(a: np.ndarray, exponent: np.floating, out: np.ndarray | None = None) -> np.ndarray:
    """``np.power(a, exponent, out=out)`` (in place when ``out`` is ``a``; a new array when
    it is None), in parts on threads (:func:`in_parts`); measured on a 4K RGB frame, 2 cores:
    23 ms instead of 35."""
    if out is None:
        out = np.empty(a.shape, np.result_type(a, exponent))
    return in_parts(lambda src, dst: np.power(src, exponent, out=dst), a, out)


#: Parts :func:`zero_fill` splits an array into.
_FILL_PARTS = 64


@numba.njit(parallel=True, cache=True, fastmath=FASTMATH, nogil=True)
def _zero_bytes(buf):  # pragma: no cover - compiled
    n = buf.shape[0]
    for p in numba.prange(_FILL_PARTS):
        part = buf[n * p // _FILL_PARTS:n * (p + 1) // _FILL_PARTS]  # indexed from 0
        for i in range(part.shape[0]):
            part[i] = 0


def zero_fill(a: np.ndarray) -> np.ndarray:
    """``a[...] = 0`` of a C-contiguous array, on the threads: one thread wrote a 4K map's
    33 MB in 4.6-4.9 ms inside the enhancer's frame (2 cores), the two in 2.5."""
    if not a.flags.c_contiguous:
        raise ValueError("zero_fill fills a C-contiguous array")
    _zero_bytes(a.reshape(-1).view(np.uint8))
    return a


@numba.njit(parallel=True, cache=True, fastmath=FASTMATH, nogil=True)
def _zero_outside_rows(a, spans):  # pragma: no cover - compiled
    h = a.shape[0]
    stride = interleave(h)  # the spans are often all in one part of the frame
    for i in numba.prange(h):
        y = (i * stride) % h
        row = a[y]
        lo, hi = spans[y, 0], spans[y, 1]
        if hi <= lo:
            lo = hi = row.shape[0]
        head, tail = row[:lo], row[hi:]  # indexed from 0: the loops vectorise
        for x in range(head.shape[0]):
            head[x] = 0.0
        for x in range(tail.shape[0]):
            tail[x] = 0.0


def zero_outside_rows(a: np.ndarray, spans: np.ndarray) -> np.ndarray:
    """``a[y, :lo] = a[y, hi:] = 0`` for each row ``y`` of a 2-D array, ``(lo, hi) =
    spans[y]`` (every column where ``hi <= lo``), on the threads; ``a``, written in place."""
    if a.ndim != 2 or spans.shape != (a.shape[0], 2):
        raise ValueError(f"spans of shape ({a.shape[0]}, 2) for a 2-D array, not {spans.shape}")
    _zero_outside_rows(a, np.ascontiguousarray(spans, np.int64))
    return a


@numba.njit(parallel=True, cache=True, fastmath=FASTMATH, nogil=True)
def _multiply_adds(lanes, reps):  # pragma: no cover - compiled
    """``reps`` multiplies and adds on every value of each row of ``lanes`` (a row per task,
    small enough to stay in the L1 cache): work bound by each core's vector units and L1
    cache, not by the shared memory's bandwidth."""
    for t in numba.prange(lanes.shape[0]):
        row = lanes[t]
        for _ in range(reps):
            for i in range(row.shape[0]):
                row[i] = row[i] * np.float32(0.999) + np.float32(0.001)


def parallel_speedup(reps: int = 20000, repeats: int = 5) -> float:
    """How much faster every thread runs vectorised arithmetic than one thread does (median
    of ``repeats``; the same work, one task per thread): about the thread count where each
    thread has a core of its own, less where the "cores" share their vector units (two
    hardware threads of one core, or a host's other tenants). Measured 1.17 to 1.73 on a
    2-vCPU cloud VM whose lscpu reports 2 cores of one thread each, varying from minute to
    minute: the most the compiled kernels' parallel loops could gain there."""
    n = numba.config.NUMBA_NUM_THREADS
    lanes = np.ones((n, 2048), np.float32)
    before = numba.get_num_threads()
    times = {}
    try:
        for threads in (1, n):
            numba.set_num_threads(threads)
            _multiply_adds(lanes, 2)  # compiled (or loaded) and the threads started
            runs = []
            for _ in range(repeats):
                t0 = time.perf_counter()
                _multiply_adds(lanes, reps)
                runs.append(time.perf_counter() - t0)
            times[threads] = float(np.median(runs))
    finally:
        numba.set_num_threads(before)
    return times[1] / times[n]
