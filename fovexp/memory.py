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
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import threading

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
