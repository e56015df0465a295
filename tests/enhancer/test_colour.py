"""Colour transfer functions (paper section 4.5; docs/METHOD.md, 5.1)."""

import numpy as np
import pytest

from fovexp.colour import encode, linearize


@pytest.mark.parametrize("transfer", ["power", "release"])
def test_transfer_round_trip(transfer):
    v = np.linspace(0, 1, 101, dtype=np.float32)
    assert np.abs(encode(linearize(v, 2.2, transfer), 2.2, transfer) - v).max() < 1e-5


@pytest.mark.parametrize("n", [7, 65536 * 2 + 3, 3 * 1000 * 777])
def test_the_power_on_threads_is_one_call_bit_for_bit(n):
    import numba

    from fovexp._parallel import power

    x = np.random.default_rng(n).random(n, dtype=np.float32)
    want = np.power(x, np.float32(1 / 2.2))
    before = numba.get_num_threads()
    try:
        for threads in range(1, numba.config.NUMBA_NUM_THREADS + 1):
            numba.set_num_threads(threads)
            got = x.copy()
            assert power(got, np.float32(1 / 2.2), got) is got
            assert np.array_equal(got.view(np.uint32), want.view(np.uint32))
            assert np.array_equal(power(x, np.float32(1 / 2.2)).view(np.uint32),
                                  want.view(np.uint32))
    finally:
        numba.set_num_threads(before)
    block = x[: n // 6 * 6].reshape(-1, 6)
    strided = np.array(block, order="F")  # not C-contiguous (past one row): one call
    assert np.array_equal(power(strided, np.float32(2.2), strided),
                          np.power(block, np.float32(2.2)))


def test_the_power_works_in_a_forked_child():
    """A process forked after the power ran on threads (scene generation forks workers) gets
    its own threads: the work is done, not left waiting for the parent's."""
    import multiprocessing

    from fovexp._parallel import power

    x = np.random.default_rng(1).random(1 << 18, dtype=np.float32)
    want = np.power(x, np.float32(2.2))
    assert np.array_equal(power(x, np.float32(2.2)), want)  # the parent's pool exists now
    ctx = multiprocessing.get_context("fork")
    with ctx.Pool(1) as pool:
        got = pool.apply_async(power, (x, np.float32(2.2))).get(timeout=60)
    assert np.array_equal(got, want)
