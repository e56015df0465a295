"""How the process gives memory back: a 4K frame's stages are arrays of 33-100 MB.

glibc's malloc hands an allocation above its mmap threshold (at most 32 MB, however it adapts)
its own fresh pages and returns them to the system when it is freed, so every frame's arrays
start in new pages, each first written through a page fault. On the 2-core machine of
benchmarks/CPU_FLOOR.md a 100 MB array written by a compiled kernel took 12-34 ms longer in
fresh pages than in kept ones, and an already-foveated 4K frame 44-108 ms longer (two runs of
the same tree with and without it: 0.54 -> 0.49 s, 0.55 -> 0.44 s).
:func:`retain_freed_memory` raises the threshold and the heap's trim threshold, so that a
frame's arrays reuse the previous frame's pages: the process keeps what its largest frame
needed (the peak is unchanged; it is not given back between frames).
:class:`fovexp.Enhancer` calls it; ``FOVEXP_MALLOC_DEFAULTS=1`` leaves glibc's defaults.
Elsewhere than glibc (macOS, Windows, musl) it does nothing.

The heap still fragments: a frame's arrays freed in another order than the last frame's leave
holes that the next frame's 100 MB arrays do not fit, and the heap grows into fresh pages for
several frames after the first (measured on that machine, an already-foveated 4K frame at 12
impulses: frames 3-8 of a run 170-355 ms, the slow ones those that grew the heap, against
160-170 ms for the others). A :class:`FramePool` keeps each large stage array's buffer for the
next frame's array of the same size, so from the second frame on a frame's arrays are the
last frame's buffers: no page fault and no heap growth, whatever the allocator. The Enhancer's
stage cache makes its pool the active one (:meth:`FramePool.active`) while it computes a
stage, and the stages take their large arrays with :func:`frame_empty` and
:func:`frame_zeros` (plain ``np.empty`` and ``np.zeros`` where no pool is active: the modules'
functions called on their own).
"""

from __future__ import annotations

import contextlib
import contextvars
import ctypes
import ctypes.util
import math
import os
import sys
import threading
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from ._parallel import zero_fill, zero_outside_rows

#: mallopt's parameters (malloc.h).
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
#: Allocations up to this size come from the heap and are reused (an 8K RGB float32 frame is
#: 400 MB); larger ones keep their own pages.
MMAP_THRESHOLD_BYTES = 1 << 30
#: Free memory at the heap's top up to this size is kept for the next frame.
TRIM_THRESHOLD_BYTES = 2 << 30

_done = False
_lock = threading.Lock()


def retain_freed_memory() -> bool:
    """Keep freed large arrays' pages in the process for reuse (see the module docstring);
    once per process. True where glibc took the settings."""
    global _done
    with _lock:
        if _done:
            return True
        if os.environ.get("FOVEXP_MALLOC_DEFAULTS", "0") == "1":
            return False
        try:
            libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
            mallopt = libc.mallopt
        except (OSError, AttributeError):  # not glibc
            return False
        mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
        _done = bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES)) and bool(
            mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES))
        return _done


#: Arrays below this size are NumPy's own: a pool's bookkeeping would cost more than their pages.
POOL_MIN_BYTES = 1 << 20
#: A buffer no array has used for this many frames is given back (a frame of another size, an
#: array the stages no longer ask for).
POOL_IDLE_FRAMES = 2

_ACTIVE: contextvars.ContextVar[FramePool | None] = contextvars.ContextVar(
    "fovexp_frame_pool", default=None)


def _refs(buffers: list[np.ndarray], i: int) -> int:
    return sys.getrefcount(buffers[i])


#: :func:`_refs` of a buffer that only a pool's list holds: every array made from a buffer
#: (a view of it, and any view of that) holds a reference to it. Measured, not assumed: how
#: CPython counts a call's arguments differs between its versions.
_IDLE_REFS = _refs([np.empty(1, np.uint8)], 0)


class FramePool:
    """Large arrays' buffers kept from one frame to the next (see the module docstring).

    :meth:`empty` hands out a view of a kept buffer of exactly the size asked for that no
    array uses any more (CPython's reference count of the buffer: every view holds one), else
    of a new one. An array the caller still holds, the previous frame's output a user kept
    say, keeps its buffer out of the pool's hands until it is gone. :meth:`next_frame` gives
    back the buffers unused for :data:`POOL_IDLE_FRAMES` frames."""

    def __init__(self) -> None:
        self._buffers: list[np.ndarray] = []
        self._used: list[int] = []  # the frame each buffer was last handed out in
        self._frame = 0
        self._lock = threading.Lock()

    def empty(self, shape: tuple[int, ...], dtype: np.dtype | type) -> np.ndarray:
        """An uninitialised C-contiguous array, in a kept buffer where one is free."""
        dt = np.dtype(dtype)
        nbytes = math.prod(shape) * dt.itemsize
        if nbytes < POOL_MIN_BYTES:
            return np.empty(shape, dt)
        with self._lock:
            # by index: a loop variable holding a buffer would count as one of its users
            for i in range(len(self._buffers)):
                if (self._buffers[i].nbytes == nbytes
                        and _refs(self._buffers, i) == _IDLE_REFS):
                    self._used[i] = self._frame
                    return self._buffers[i].view(dt).reshape(shape)
            buf = np.empty(nbytes, np.uint8)
            self._buffers.append(buf)
            self._used.append(self._frame)
            return buf.view(dt).reshape(shape)

    def zeros(self, shape: tuple[int, ...], dtype: np.dtype | type) -> np.ndarray:
        """:meth:`empty`, zeroed (on the threads: :func:`fovexp._parallel.zero_fill`)."""
        out = self.empty(shape, dtype)
        if out.nbytes < POOL_MIN_BYTES:
            out.fill(0)
            return out
        return zero_fill(out)

    def next_frame(self) -> None:
        """Count a frame; give back the free buffers unused for :data:`POOL_IDLE_FRAMES`."""
        with self._lock:
            self._frame += 1
            keep = [i for i in range(len(self._buffers))
                    if self._frame - self._used[i] <= POOL_IDLE_FRAMES
                    or _refs(self._buffers, i) != _IDLE_REFS]
            self._buffers = [self._buffers[i] for i in keep]
            self._used = [self._used[i] for i in keep]

    def clear(self) -> None:
        """Give back every buffer (those still in use live on with their arrays)."""
        with self._lock:
            self._buffers.clear()
            self._used.clear()

    @property
    def nbytes(self) -> int:
        """The bytes of the buffers kept (in use or free)."""
        return sum(b.nbytes for b in self._buffers)

    @contextlib.contextmanager
    def active(self) -> Iterator[FramePool]:
        """Make this the pool :func:`frame_empty` and :func:`frame_zeros` take from, in this
        thread (and context), until the block ends."""
        token = _ACTIVE.set(self)
        try:
            yield self
        finally:
            _ACTIVE.reset(token)


def frame_empty(shape: tuple[int, ...], dtype: np.dtype | type) -> np.ndarray:
    """``np.empty(shape, dtype)``, from the active :class:`FramePool` if there is one."""
    pool = _ACTIVE.get()
    return np.empty(shape, dtype) if pool is None else pool.empty(shape, dtype)


def frame_zeros(shape: tuple[int, ...], dtype: np.dtype | type) -> np.ndarray:
    """``np.zeros(shape, dtype)``, from the active :class:`FramePool` if there is one."""
    pool = _ACTIVE.get()
    return np.zeros(shape, dtype) if pool is None else pool.zeros(shape, dtype)


@dataclass
class WrittenRows:
    """An (H, W) frame map written only on one span of columns per row, 0 elsewhere by
    definition: what the stages that skip flat regions (the contrast change, the noise) give
    the output stage, which reads each row on its spans only, so that neither the zeros of a
    flat region are written nor read back (a 4K map is 33 MB). :meth:`full` writes them,
    once, for a reader of the whole map (the maps, the other clipping rules)."""

    values: np.ndarray  # (H, W); outside the spans, not initialised until :meth:`full`
    spans: np.ndarray  # (H, 2) int64: each row's [start, stop) written; empty where stop <= start

    @classmethod
    def whole(cls, values: np.ndarray) -> WrittenRows:
        """A map written everywhere."""
        spans = np.empty((values.shape[0], 2), np.int64)
        spans[:, 0], spans[:, 1] = 0, values.shape[1]
        return cls(values, spans)

    def full(self) -> np.ndarray:
        """The whole map: 0 written outside the spans (in place, the first time)."""
        if not self._complete:
            zero_outside_rows(self.values, self.spans)
            self._complete = True
        return self.values

    def __post_init__(self) -> None:
        h, w = self.values.shape
        if self.spans.shape != (h, 2):
            raise ValueError(f"spans of shape ({h}, 2) for a map of {h} rows")
        self._complete = bool((self.spans[:, 0] <= 0).all() and (self.spans[:, 1] >= w).all())
