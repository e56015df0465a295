"""Colour transfer functions (paper section 4.5; docs/METHOD.md, 5.1)."""

import numpy as np
import pytest

from fovexp.colour import (
    encode,
    linearize,
    linearize_checked,
    linearize_luminance_checked,
    luminance_and_block_extremes,
)


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


def test_linearize_is_the_transfer_function_written_out():
    """power: v ** gamma; release: ((v + 0.055) / 1.055) ** 2.2 (docs/METHOD.md, 5.1), in
    float32 unless asked for float64, against the formulas in float64."""
    v = np.linspace(0, 1, 257)
    assert np.allclose(linearize(v, 2.4), v**2.4, rtol=1e-6, atol=1e-7)
    rel = linearize(v, 2.2, "release", dtype=np.float64)
    assert rel.dtype == np.float64 and np.allclose(rel, ((v + 0.055) / 1.055) ** 2.2, rtol=1e-12)
    assert linearize(v, 2.2).dtype == np.float32
    assert linearize(np.float32(0.5), 1.0) == np.float32(0.5)


@pytest.mark.parametrize("transfer,gamma", [("power", 2.2), ("power", 2.4), ("release", 2.2)])
def test_the_checked_linearisation_is_linearize_or_none_where_a_value_is_out(transfer, gamma):
    """linearize_checked: linearize's numbers bit for bit when every value is in [+0, 1]
    (a textured frame with flat runs, RGB and grey, 0 and 1 themselves), None as soon as
    one value is not: NaN, +-Inf, below 0, above 1, and -0.0 (which the caller's own check
    accepts), wherever it is in the frame (first, last, in a flat run)."""
    rng = np.random.default_rng(29)
    img = rng.random((67, 301, 3), dtype=np.float32)
    img[20:40] = np.float32(0.5)  # flat runs: copied, not raised to the power
    img[0, 0, 0], img[1, 1, 1] = 0.0, 1.0
    for a in (img, np.ascontiguousarray(img[..., 1])):
        got = linearize_checked(a, gamma, transfer)
        assert got is not None and got.dtype == np.float32
        assert np.array_equal(got.view(np.uint32), linearize(a, gamma, transfer).view(np.uint32))
    # with the luminance and its level-3 block extremes (partial blocks at both edges)
    lin = linearize(img, gamma, transfer)
    taken = linearize_luminance_checked(img, gamma, transfer, 3)
    assert taken is not None
    for got, want in zip(taken, (lin, *luminance_and_block_extremes(lin, 3)), strict=True):
        assert np.array_equal(got.view(np.uint32), want.view(np.uint32))
    for bad in (np.nan, np.inf, -np.inf, -1e-30, np.nextafter(np.float32(1), np.float32(2)),
                -0.0):
        for where in ((0, 0, 0), (66, 300, 2), (30, 150, 1)):
            a = img.copy()
            a[where] = bad
            assert linearize_checked(a, gamma, transfer) is None, (bad, where)
            assert linearize_luminance_checked(a, gamma, transfer, 3) is None, (bad, where)


def test_encode_adds_the_grey_images_clips_then_encodes():
    """encode(lin, gamma, transfer, a, b) = transfer^-1(clip(lin + a + b, 0, 1)) on every
    channel; the release's inverse v ** (1 / 2.2) 1.055 - 0.055, clipped to [0, 1]."""
    rng = np.random.default_rng(2)
    lin = rng.uniform(0, 1, (5, 6, 3))
    a = rng.uniform(-0.4, 0.4, (5, 6))
    b = rng.uniform(-0.4, 0.4, (5, 6))
    want = np.clip(lin + (a + b)[..., None], 0, 1) ** (1 / 2.2)
    assert np.allclose(encode(lin, 2.2, "power", a, b), want, rtol=1e-12)
    assert np.allclose(encode(lin, 2.2, "power", a), np.clip(lin + a[..., None], 0, 1)
                       ** (1 / 2.2), rtol=1e-12)
    grey = encode(lin[..., 0], 2.0, "power", a, b)  # a grey image: (H, W)
    assert grey.shape == (5, 6) and np.allclose(grey, np.sqrt(np.clip(lin[..., 0] + a + b, 0, 1)))
    assert np.allclose(encode(lin, 2.2), lin ** (1 / 2.2), rtol=1e-12)
    # without grey images too, values outside [0, 1] clip before the power (no NaN)
    assert encode(np.array([-0.1, 0.25, 1.2]), 2.0).tolist() == [0.0, 0.5, 1.0]
    rel = encode(lin, 2.2, "release", a)
    want = np.clip(np.clip(lin + a[..., None], 0, 1) ** (1 / 2.2) * 1.055 - 0.055, 0, 1)
    assert np.allclose(rel, want, rtol=1e-12, atol=1e-15) and (rel == 0).any()
    f32 = encode(lin.astype(np.float32), 2.2, "power", a)
    assert f32.dtype == np.float32 and np.allclose(f32, encode(lin, 2.2, "power", a), atol=1e-6)
    with pytest.raises(ValueError, match="at most two"):
        encode(lin, 2.2, "power", a, a, a)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("transfer", ["power", "release"])
def test_encode_keeps_the_unchanged_pixels_as_they_were(dtype, transfer):
    """With ``unchanged`` (the encoded image ``linear`` came from), a pixel whose grey images
    add exactly 0 is that image's, bit for bit; every other pixel is encode's without it.
    Whole runs without a change (a copy) and runs with a few changed pixels both occur."""
    rng = np.random.default_rng(5)
    h, w = 6, 700  # rows longer than one run of 256 pixels
    enc = rng.random((h, w, 3)).astype(dtype)
    lin = linearize(enc, 2.2, transfer, dtype)
    a = rng.uniform(-0.1, 0.1, (h, w)).astype(dtype)
    b = rng.uniform(-0.1, 0.1, (h, w)).astype(dtype)
    a[:3, :300] = b[:3, :300] = 0.0  # whole runs unchanged
    b[3:5, ::5] = -a[3:5, ::5]  # single pixels unchanged within changed runs
    a[5] = 0.25
    b[5] = -0.25  # a change that sums to 0 is no change
    zero = (a + b) == 0
    assert 0.2 < zero.mean() < 0.8
    plain = encode(lin, 2.2, transfer, a, b)
    kept = encode(lin, 2.2, transfer, a, b, unchanged=enc)
    assert kept.dtype == dtype
    assert np.array_equal(kept[zero], enc[zero])
    assert np.array_equal(kept[~zero], plain[~zero])
    # the round trip alone gives the pixels back only within about an ulp
    assert np.abs(plain[zero] - enc[zero]).max() < 1e-5
    one = encode(lin, 2.2, transfer, a, unchanged=enc)
    assert np.array_equal(one[a == 0], enc[a == 0])
    assert np.array_equal(one[a != 0], encode(lin, 2.2, transfer, a)[a != 0])
    grey = encode(lin[..., 0], 2.2, transfer, a, b, unchanged=enc[..., 0])
    assert np.array_equal(grey[zero], enc[..., 0][zero])
    # nothing added: the encoded image itself, as a new array
    same = encode(lin, 2.2, transfer, unchanged=enc)
    assert np.array_equal(same, enc) and same is not enc
    with pytest.raises(ValueError, match="unchanged has shape"):
        encode(lin, 2.2, transfer, a, unchanged=enc[:, :10])


def test_luminance_weights_are_bt601():
    from fovexp.colour import luminance

    rgb = np.array([[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.2, 0.4, 0.8]]])
    y = luminance(rgb)
    assert y.dtype == np.float64
    assert y[0] == pytest.approx([0.299, 0.587, 0.114, 0.299 * 0.2 + 0.587 * 0.4 + 0.114 * 0.8],
                                 abs=1e-15)
    y32 = luminance(rgb.astype(np.float32))
    assert y32.dtype == np.float32 and y32[0] == pytest.approx(y[0], abs=1e-7)
    grey = np.full((2, 2), 0.25, np.float32)
    assert luminance(grey) is not None and np.array_equal(luminance(grey), grey)
    assert luminance(grey.astype(np.float64)).dtype == np.float64
    with pytest.raises(ValueError, match=r"not \(2, 2, 4\)"):
        luminance(np.zeros((2, 2, 4), np.float32))


@pytest.mark.parametrize("gamma", [2.2, 1 / 2.2, 2.4, 1 / 2.4, 1.8, 1.0])
def test_the_polynomial_power_is_pow_within_one_unit_in_the_last_place(gamma):
    """Float32 transfers take their power from a polynomial (fovexp/colour.py): every value
    within one float32 ulp of the correctly rounded power, most the same, 0 and 1 exact,
    never decreasing, the same bits on 1 thread and on every thread.

    The reference is pow in float64 rounded to float32, not NumPy's float32 pow: on CPUs
    with AVX-512 NumPy takes that from SVML, which is itself one ulp off in about a fifth of
    the values (measured on a Xeon with AVX-512: 79.5 % the same as the float64 reference
    at gamma 2.2; the polynomial 99.996 %)."""
    import numba

    rng = np.random.default_rng(7)
    x = np.concatenate([
        rng.random(1 << 20, dtype=np.float32),
        np.linspace(0, 1, 1 << 16, dtype=np.float32),  # sorted: the monotony check below
        np.array([0.0, 1.0, 1e-45, 1e-38, 1e-20, np.nextafter(np.float32(1), 0)], np.float32),
    ])
    want = np.power(x.astype(np.float64), np.float64(np.float32(gamma))).astype(np.float32)
    got = linearize(x, gamma)
    ulps = np.abs(got.view(np.int32).astype(np.int64) - want.view(np.int32))
    assert ulps.max() <= 1
    assert (ulps == 0).mean() > 0.999
    assert got[x == 0].max() == 0 and (got[x == 1] == 1).all()
    ramp = got[1 << 20: (1 << 20) + (1 << 16)]
    assert (np.diff(ramp) >= 0).all()
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        assert linearize(x, gamma).tobytes() == got.tobytes()
    finally:
        numba.set_num_threads(before)
    # encode (the inverse, in one pass with its additions) through the same power
    img = x[: 3 * 1000].reshape(10, 100, 3)
    enc = encode(img, 1 / gamma)
    ref = np.power(img.astype(np.float64), np.float64(np.float32(gamma))).astype(np.float32)
    assert np.abs(enc.view(np.int32).astype(np.int64) - ref.view(np.int32)).max() <= 1


@pytest.mark.parametrize("transfer", ["power", "release"])
def test_flat_runs_copy_the_results_the_power_gives(transfer):
    """The transfers copy a run's results where it repeats the pixel before it (a flat grey
    or colour region, fovexp/colour.py): the same bits as every value through the power
    (the same values shuffled, where no run repeats), with a run broken by one value."""
    rng = np.random.default_rng(3)
    img = rng.random((40, 700, 3), dtype=np.float32)
    img[5:20] = (0.2, 0.5, 0.7)  # flat colour rows
    img[25:30, 100:600] = 0.25  # a flat grey stretch ...
    img[26, 300, 1] = np.float32(0.25) + np.float32(1e-7)  # ... one value off in a run
    perm = rng.permutation(img.size)

    def unshuffled(shuffled: np.ndarray) -> np.ndarray:
        out = np.empty_like(shuffled)
        out[perm] = shuffled
        return out

    got = linearize(img, 2.2, transfer)
    want = unshuffled(linearize(img.reshape(-1)[perm], 2.2, transfer))
    assert got.reshape(-1).tobytes() == want.tobytes()
    assert got[26, 300, 1] != got[26, 299, 1]
    enc = encode(got, 2.2, transfer)
    want = unshuffled(encode(got.reshape(-1)[perm], 2.2, transfer))
    assert enc.reshape(-1).tobytes() == want.tobytes()


@pytest.mark.parametrize("shape,dtype", [((37, 53, 3), np.float32), ((64, 40, 3), np.float32),
                                         ((21, 30, 3), np.float64), ((21, 30), np.float32)])
def test_the_luminance_and_its_block_extremes_in_one_pass_are_the_two_apart(shape, dtype):
    """colour.luminance_and_block_extremes: bit for bit colour.luminance and
    pyramids.channel_block_extremes of it (partial edge blocks included; float64 and grey
    through the two apart)."""
    from fovexp import pyramids
    from fovexp.colour import luminance, luminance_and_block_extremes

    img = np.random.default_rng(4).random(shape).astype(dtype)
    img[:16, :16] = 0.25  # flat blocks: extremes equal
    luma, lo, hi = luminance_and_block_extremes(img, 3)
    ref = luminance(img)
    rlo, rhi = (e[..., 0] for e in pyramids.channel_block_extremes(ref[..., None], 3))
    assert luma.dtype == ref.dtype and lo.shape == (-(-shape[0] // 8), -(-shape[1] // 8))
    for got, want in ((luma, ref), (lo, rlo), (hi, rhi)):
        assert np.array_equal(got, want) and got.dtype == want.dtype
    assert lo[0, 0] == hi[0, 0] and (lo <= hi).all()


def _power_path(src: np.ndarray, gamma: float, transfer: str) -> np.ndarray:
    """Every value of ``src`` through the transfer's power (no code table)."""
    from fovexp import colour

    flat = np.ascontiguousarray(src, dtype=np.float32).reshape(-1)
    out = np.empty_like(flat)
    colour._linearize_into(flat, np.float64(np.float32(gamma)), colour._offset(transfer), out,
                           colour._NO_BITS, np.zeros(8, np.uint32), colour._NO_TABLE,
                           colour._NO_TABLE)
    return out.reshape(src.shape)


@pytest.mark.parametrize("transfer,gamma", [("power", 2.2), ("power", 2.4), ("release", 2.2)])
def test_a_frame_of_file_codes_is_looked_up_as_the_numbers_the_power_gives(transfer, gamma):
    """An 8- or 16-bit file's samples, read as fovexp.io divides them (k / 255, k / 65535 in
    float32), are linearised from colour.code_table: bit for bit what the power gives them,
    with a non-code value (NaN included), flat runs and a run of other numbers among them;
    the check still refuses what it refused."""
    from fovexp.io import _to_unit_float

    rng = np.random.default_rng(31)
    for raw in (rng.integers(0, 256, (45, 333, 3), dtype=np.uint8),
                rng.integers(0, 65536, (45, 333, 3), dtype=np.uint16)):
        img = _to_unit_float(raw)
        img[10:14] = img[10, 0]  # flat rows of one code
        img[20, 30:330] = rng.random((300, 3), dtype=np.float32)  # a run of other numbers
        img[30, 7, 1] = np.float32(0.5)  # not a code: 32767.5 / 65535
        for a in (img, np.ascontiguousarray(img[..., 0])):
            want = _power_path(a, gamma, transfer)
            assert np.array_equal(linearize(a, gamma, transfer).view(np.uint32),
                                  want.view(np.uint32))
            checked = linearize_checked(a, gamma, transfer)
            assert checked is not None
            assert np.array_equal(checked.view(np.uint32), want.view(np.uint32))
        lin = _power_path(img, gamma, transfer)
        taken = linearize_luminance_checked(img, gamma, transfer, 3)
        assert taken is not None
        for got, want in zip(taken, (lin, *luminance_and_block_extremes(lin, 3)), strict=True):
            assert np.array_equal(got.view(np.uint32), want.view(np.uint32))
        nan = img.copy()
        nan[40, 50, 2] = np.nan
        assert np.array_equal(linearize(nan, gamma, transfer).view(np.uint32),
                              _power_path(nan, gamma, transfer).view(np.uint32))
        for bad in (np.nan, np.inf, -np.inf, -1.0, 2.0, -0.0):
            a = img.copy()
            a[44, 332, 2] = bad
            assert linearize_checked(a, gamma, transfer) is None, bad
            assert linearize_luminance_checked(a, gamma, transfer, 3) is None, bad


def test_the_code_table_is_what_a_frame_of_codes_reads(monkeypatch):
    """Each 8-bit code k / 255 is the table's entry 257 k (fovexp.io's division); a frame of
    codes takes its linear values from the table, and only a frame of codes: a sentinel
    table shows which runs read it (a run with one value that is not a code goes through
    the power, whole)."""
    from fovexp import colour
    from fovexp.io import _to_unit_float

    p = np.float64(np.float32(2.2))
    codes, linear = colour.code_table(p, 0.0)
    eight = _to_unit_float(np.arange(256, dtype=np.uint8))
    assert np.array_equal(codes[::257], eight)
    assert np.array_equal(_to_unit_float(np.arange(65536, dtype=np.uint16)), codes)
    assert np.array_equal(linear.view(np.uint32), _power_path(codes, 2.2, "power").view(np.uint32))
    sentinel = np.full_like(linear, -7.0)
    monkeypatch.setitem(colour._CODE_TABLES, (float(p), 0.0), (codes, sentinel))
    img = _to_unit_float(np.random.default_rng(5).integers(0, 256, (8, 1024, 3), np.uint8))
    img[5, 100, 0] = np.float32(0.3)  # 76.5 / 255: the run holding it is not codes only
    got = linearize(img, 2.2)
    looked_up = got == -7.0
    assert looked_up.sum() >= img.size - colour._RUN
    assert not looked_up[5, 100, 0] and not looked_up[5, 99, 2]
    assert np.array_equal(got[~looked_up], _power_path(img, 2.2, "power")[~looked_up])
    assert not (linearize(img + np.float32(1e-6), 2.2) == -7.0).any()


@pytest.mark.parametrize("kept", [False, True])
def test_grey_images_written_on_spans_are_read_there_only(kept):
    """A grey image given as WrittenRows (the enhancer's contrast change and noise: zeros
    outside each row's span never written) encodes as the whole image does, bit for bit,
    whatever lies outside the spans (NaN here): nothing there is read. Spans that overlap,
    that leave a gap between them, and one of two empty. With the kept image, the linear
    image is not read outside the spans either: those columns are the kept pixels."""
    from fovexp.memory import WrittenRows

    rng = np.random.default_rng(5)
    h, w = 40, 600
    img = rng.uniform(0.0, 1.0, (h, w, 3)).astype(np.float32)
    img[:, 300:] = img[:, 299:300]  # flat to the right: its runs are copies
    lin = linearize(img, 2.2)
    grey, written = [], []
    for seed, (lo, hi), gap in ((1, (0, 320), (0, 100)), (2, (250, 600), (400, 600))):
        full = np.zeros((h, w), np.float32)
        spans = np.zeros((h, 2), np.int64)
        spans[5:30] = (lo, hi)  # other rows: nothing written
        spans[17] = (hi, lo)  # an empty span: start past stop
        spans[32:36] = gap  # two spans with a gap between them
        if seed == 2:
            spans[36:39] = (lo, hi)  # the first empty, this one not
        values = np.full((h, w), np.nan, np.float32)
        g = np.random.default_rng(seed).normal(0, 0.05, (h, w)).astype(np.float32)
        for y in range(h):
            x0, x1 = spans[y]
            if x1 > x0:
                full[y, x0:x1] = values[y, x0:x1] = g[y, x0:x1]
        grey.append(full)
        written.append(WrittenRows(values, spans))
    unchanged = img if kept else None
    for n in (1, 2):
        want = encode(lin, 2.2, "power", *grey[:n], unchanged=unchanged)
        got = encode(lin, 2.2, "power", *written[:n], unchanged=unchanged)
        assert np.array_equal(want.view(np.uint32), got.view(np.uint32)), n
        if kept:
            untouched = lin.copy()
            for y in range(h):
                x0 = min([wr.spans[y, 0] for wr in written[:n] if wr.spans[y, 1] > wr.spans[y, 0]],
                         default=w)
                x1 = max([wr.spans[y, 1] for wr in written[:n] if wr.spans[y, 1] > wr.spans[y, 0]],
                         default=0)
                untouched[y, :x0] = untouched[y, max(x1, x0):] = np.nan
            got = encode(untouched, 2.2, "power", *written[:n], unchanged=unchanged)
            assert np.array_equal(want.view(np.uint32), got.view(np.uint32)), n
    assert np.isnan(written[0].values).any()  # the encode left them as they were
    assert np.array_equal(written[1].full(), grey[1])  # and full() writes the zeros
