"""The enhancer's frames reuse the pages of the frames before (fovexp.memory), measured in
page faults."""

import subprocess
import sys

import numpy as np
import pytest

SCRIPT = r"""
import resource, sys
import numpy as np
if sys.argv[1] == "enhancer":  # as a user meets it: an Enhancer sets it up
    import fovexp.memory
    from fovexp import Enhancer, load_display
    Enhancer(load_display("lg-oled55cx"))
    if not fovexp.memory._done:  # -2: the Enhancer did not set it; -1: the C library refused
        print(-2 if fovexp.memory.retain_freed_memory() else -1)
        sys.exit()
faults = []
for _ in range(3):
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    a = np.empty(200 << 20, np.uint8)
    a.fill(1)  # every page written
    del a
    faults.append(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
print(faults[-1])
"""


def _faults(mode: str) -> int:
    out = subprocess.run([sys.executable, "-c", SCRIPT, mode], capture_output=True, text=True,
                         check=True, env={"PATH": "/usr/bin:/bin"})
    return int(out.stdout.strip())


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt only")
def test_a_frame_sized_array_reuses_the_freed_pages():
    """A 200 MB array written, freed and written again: once an Enhancer has been made, the
    third costs (almost) no page faults; with glibc's defaults it faults again every time
    (4 KB or 2 MB pages: at least 100 faults)."""
    assert _faults("default") >= 100
    retained = _faults("enhancer")
    assert retained != -2, "an Enhancer did not call fovexp.memory.retain_freed_memory"
    if retained == -1:
        pytest.skip("this C library refused the setting (fovexp.memory)")
    assert retained < 50


def test_the_setting_is_left_alone_on_request(monkeypatch):
    import fovexp.memory as memory

    monkeypatch.setattr(memory, "_done", False)
    monkeypatch.setenv("FOVEXP_MALLOC_DEFAULTS", "1")
    assert memory.retain_freed_memory() is False


# ----------------------------------------------------------------------- the frame pool
def _address(a):
    return a.__array_interface__["data"][0]


def test_a_pool_hands_a_buffer_out_again_only_once_no_array_uses_it():
    from fovexp.memory import POOL_MIN_BYTES, FramePool, frame_empty

    pool = FramePool()
    shape = (POOL_MIN_BYTES // 4, 2)
    with pool.active():
        a = frame_empty(shape, np.float32)
        b = frame_empty(shape, np.float32)
        assert _address(a) != _address(b)  # a is in use
        first = _address(a)
        view = a[::2]
        del a
        assert _address(frame_empty(shape, np.float32)) not in (first, _address(b))  # the view
        del view
        again = frame_empty((shape[0] * 2,), np.int32)  # the same size, another shape and dtype
        assert _address(again) == first and again.shape == (shape[0] * 2,)
        small = frame_empty((4,), np.float32)  # NumPy's own below POOL_MIN_BYTES
    assert small.base is None
    assert frame_empty(shape, np.float32).base is None  # no pool active: NumPy's own
    assert pool.nbytes == 3 * shape[0] * shape[1] * 4


def test_a_pool_gives_back_what_went_unused_for_its_frames():
    from fovexp.memory import POOL_IDLE_FRAMES, POOL_MIN_BYTES, FramePool

    pool = FramePool()
    kept = pool.empty((POOL_MIN_BYTES,), np.uint8)
    pool.empty((POOL_MIN_BYTES,), np.uint8)  # dropped at once: free
    for _ in range(POOL_IDLE_FRAMES):
        pool.next_frame()
    assert pool.nbytes == 2 * POOL_MIN_BYTES
    pool.next_frame()
    assert pool.nbytes == POOL_MIN_BYTES  # the free one given back, the one in use kept
    del kept
    pool.next_frame()
    assert pool.nbytes == 0
    z = pool.zeros((POOL_MIN_BYTES // 8,), np.float64)
    assert not z.any()


def test_a_pools_zeros_are_zeros_in_a_buffer_written_before():
    """:meth:`FramePool.zeros` reuses a buffer the last frame filled, and zeroes all of it on
    the threads (fovexp._parallel.zero_fill), its odd-sized tail included."""
    from fovexp._parallel import zero_fill
    from fovexp.memory import POOL_MIN_BYTES, FramePool

    pool = FramePool()
    shape = (3, POOL_MIN_BYTES // 4 + 7)  # not a multiple of the fill's parts
    dirty = pool.empty(shape, np.float32)
    dirty.fill(np.nan)
    address = dirty.__array_interface__["data"][0]
    del dirty
    pool.next_frame()
    z = pool.zeros(shape, np.float32)
    assert z.__array_interface__["data"][0] == address  # the same buffer, reused
    assert np.array_equal(z, np.zeros(shape, np.float32))
    with pytest.raises(ValueError, match="C-contiguous"):
        zero_fill(np.zeros((4, 4))[:, ::2])


def test_an_enhancers_frames_reuse_their_buffers_and_never_touch_a_kept_output():
    """From the second frame on, a frame's large arrays are the last frame's buffers (the pool
    does not grow), and an output the caller kept is not one of them: it still holds its
    frame's values after later frames (of other images) are computed."""
    from fovexp import EnhanceParams, Enhancer, load_display

    from engine_helpers import textured_image

    enh = Enhancer(load_display("lg-oled55cx"))
    params = EnhanceParams(blur_rate=0.34, impulses=12)
    images = [textured_image(540, 960, seed=s) for s in (1, 2, 3)]
    kept = enh.enhance((0.5, 0.5), params, image=images[0]).output
    copy = kept.copy()
    sizes = []
    for j in range(4):
        enh.enhance((0.45 + 0.05 * (j % 2), 0.5), params, image=images[1 + j % 2])
        sizes.append(enh._c.pool.nbytes)
    assert sizes[0] > 0 and sizes[1:] == sizes[1:2] * 3, sizes
    assert np.array_equal(kept, copy)
    fresh = Enhancer(load_display("lg-oled55cx"))
    assert np.array_equal(fresh.enhance((0.5, 0.5), params, image=images[0]).output, copy)


def test_written_rows_are_completed_with_zeros_outside_their_spans_once():
    """WrittenRows.full() writes 0 outside each row's span (every column of a row whose span
    is empty), keeps what was written, and does it once; a map written everywhere is whole."""
    from fovexp.memory import WrittenRows

    values = np.full((4, 6), np.nan, np.float32)
    spans = np.array([[1, 3], [0, 6], [5, 2], [0, 0]])
    values[0, 1:3], values[1] = 1.0, 2.0
    rows = WrittenRows(values, spans)
    want = np.zeros((4, 6), np.float32)
    want[0, 1:3], want[1] = 1.0, 2.0
    assert np.array_equal(rows.full(), want) and rows.full() is values
    values[2, 0] = 7.0  # written after: not zeroed again
    assert rows.full()[2, 0] == 7.0
    assert WrittenRows.whole(np.ones((2, 3)))._complete
    with pytest.raises(ValueError, match="spans of shape"):
        WrittenRows(values, spans[:2])
