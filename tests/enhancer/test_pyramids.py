"""Image pyramids (paper sections 4.2, 4.3): the min/max pyramid of the clipping control
against brute force and against the paper's 2 x 2 construction."""

import numpy as np
import pytest

from fovexp import pyramids


def test_block_extremes_match_brute_force():
    rng = np.random.default_rng(3)
    img = rng.random((37, 45, 3))
    lo, hi = pyramids.block_extremes(img, 3)
    assert lo.shape == (5, 6)
    assert lo[1, 2] == img[8:16, 16:24].min() and hi[4, 5] == img[32:37, 40:45].max()
    # the paper's construction, 2 x 2 neighbourhoods level by level, gives the same numbers
    a = img.min(axis=2)[:32, :40]
    for _ in range(3):
        a = np.minimum(np.minimum(a[0::2, 0::2], a[1::2, 0::2]),
                       np.minimum(a[0::2, 1::2], a[1::2, 1::2]))
    assert np.array_equal(a, lo[:4, :5])


def _constant_by_filters(lo: np.ndarray, hi: np.ndarray, radius: int) -> np.ndarray:
    """The definition of pyramids.constant_blocks: min of lo == max of hi over the clamped
    (2 r + 1)^2 window, in every channel (SciPy's filters)."""
    from scipy import ndimage

    size = 2 * radius + 1
    out = np.ones(lo.shape[:2], dtype=bool)
    for ch in range(lo.shape[2]):
        out &= ndimage.minimum_filter(lo[..., ch], size, mode="nearest") == (
            ndimage.maximum_filter(hi[..., ch], size, mode="nearest"))
    return out


def test_constant_radius_answers_every_radius_as_the_window_filters_do():
    """One pass (a chessboard distance to the nearest block whose 3 x 3 window is not
    constant) gives, at every radius, the blocks whose whole window is one constant: random
    grids of one, two or three channels, mostly one value with specks, regions of another
    value and non-constant blocks; the whole grid constant answers every radius."""
    rng = np.random.default_rng(7)
    for _ in range(300):
        bh, bw, c = (int(v) for v in (rng.integers(1, 25), rng.integers(1, 25),
                                     rng.integers(1, 4)))
        other = rng.integers(0, 2, (bh, bw, c)).astype(np.float32)
        lo = np.where(rng.random((bh, bw, c)) < 0.3 * rng.random(), other, np.float32(0.5))
        hi = lo + np.float32(0.1) * (rng.random((bh, bw, c)) < 0.05)
        radius = pyramids.constant_radius_blocks(lo, hi)
        for r in [*range(0, 27), 60]:
            np.testing.assert_array_equal(radius >= r, _constant_by_filters(lo, hi, r))
    flat = np.full((5, 7, 1), 0.25, np.float32)
    assert pyramids.constant_blocks(flat, flat, 10**6).all()
    speck = flat.copy()
    speck[2, 3] = np.nan  # NaN is never one constant (SciPy's filters would skip it)
    assert (pyramids.constant_radius_blocks(speck, speck)[2, 3]) == -1
    for shape in ((0, 4), (3, 0), (0, 0)):  # no block: an empty answer
        empty = np.zeros(shape, np.float32)
        got = pyramids.constant_radius_blocks(empty, empty)
        assert got.shape == shape and got.dtype == np.int32


# --- against independent implementations (issue 19: every formula of the stage checked) -----

def _reduce_ref(img):
    """Binomial [1 4 6 4 1] / 16 along both axes, borders replicated, every second sample."""
    from scipy import ndimage

    k = np.array([1, 4, 6, 4, 1]) / 16.0
    a = ndimage.correlate1d(img.astype(np.float64), k, axis=0, mode="nearest")
    a = ndimage.correlate1d(a, k, axis=1, mode="nearest")
    return a[::2, ::2]


def _expand_ref(a, shape):
    """Zero insertion and the binomial kernel x 2, written as its two phases: even outputs
    (a[i-1] + 6 a[i] + a[i+1]) / 8, odd outputs (a[i] + a[i+1]) / 2, borders replicated."""
    def one_axis(v, n):
        p = np.pad(v, [(1, 1)] + [(0, 0)] * (v.ndim - 1), mode="edge")
        out = np.empty((n,) + v.shape[1:])
        for y in range(n):
            i = y // 2 + 1
            out[y] = (p[i - 1] + 6 * p[i] + p[i + 1]) / 8 if y % 2 == 0 else (p[i] + p[i + 1]) / 2
        return out

    return one_axis(one_axis(a.astype(np.float64), shape[0]).T, shape[1]).T


def test_reduce_and_expand_are_the_binomial_filters():
    rng = np.random.default_rng(11)
    for h, w in ((9, 14), (16, 7), (2, 3)):
        img = rng.random((h, w))
        red = pyramids.reduce(img)
        assert red.dtype == np.float64 and red.shape == ((h + 1) // 2, (w + 1) // 2)
        assert np.allclose(red, _reduce_ref(img), atol=1e-14)
        assert np.allclose(pyramids.expand(red, (h, w)), _expand_ref(red, (h, w)), atol=1e-14)
    rgb = rng.random((10, 12, 3)).astype(np.float32)
    red = pyramids.reduce(rgb)
    assert red.dtype == np.float32 and red.shape == (5, 6, 3)
    assert np.allclose(red[..., 2], _reduce_ref(rgb[..., 2]), atol=1e-6)
    assert pyramids.reduce(np.ones((4, 4), np.uint8)).dtype == np.float32
    # a constant gives exactly its constant (the flat regions the enhancer skips)
    c = np.full((13, 11), 0.3, np.float32)
    assert (pyramids.reduce(c) == np.float32(0.3)).all()
    assert (pyramids.expand(pyramids.reduce(c), (13, 11)) == np.float32(0.3)).all()


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_an_interleaved_reduce_and_its_border_read_in_place_are_exact(dtype):
    """The (H, W, C) reduce keeps the channels interleaved: each channel comes out bit for bit
    as the one-channel reduce gives it. ``pad_px`` reads the replicated border through clamped
    indices: bit for bit the pyramid of the ``np.pad(mode="edge")`` copy, at every level,
    shapes odd and even, down to a single pixel and a border wider than the image."""
    rng = np.random.default_rng(3)
    rgb = rng.random((21, 34, 3)).astype(dtype)
    red = pyramids.reduce(rgb)
    for ch in range(3):
        one = pyramids.reduce(np.ascontiguousarray(rgb[..., ch]))
        assert red[..., ch].tobytes() == one.tobytes()
    for shape in ((1, 1, 3), (2, 1, 1), (5, 7, 3), (31, 17, 2), (9, 12)):
        img = rng.random(shape).astype(dtype)
        for pad in (0, 1, 2, 3, 8, 40):
            widths = ((pad, pad), (pad, pad)) + (((0, 0),) if img.ndim == 3 else ())
            want = pyramids.gaussian_pyramid(np.pad(img, widths, mode="edge"), 5)
            got = pyramids.gaussian_pyramid(img, 5, pad_px=pad)
            assert got[0] is img and len(got) == len(want), (shape, pad)
            for a, b in zip(want[1:], got[1:], strict=True):
                assert a.shape == b.shape and a.dtype == b.dtype, (shape, pad)
                assert a.tobytes() == b.tobytes(), (shape, pad)
    with pytest.raises(ValueError, match="pad_px must be >= 0"):
        pyramids.reduce(rgb, pad_px=-1)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_a_reduce_given_its_flat_blocks_is_the_same_and_does_not_read_them(dtype):
    """``reduce(constant=...)`` (the enhancer's first pyramid level when skipping) gives the
    plain reduce's bytes on images flat in parts (a textured quadrant, specks, stripes of
    other constants, -0.0 and infinite flat regions, all of it constant), shapes odd and
    even down to one pixel; and where it is told a block is flat it writes the constant
    without reading the pixels (a lie about them shows)."""
    rng = np.random.default_rng(5)
    shapes = ((1, 1), (1, 9), (9, 1), (3, 5), (8, 8), (17, 23), (65, 129), (100, 37))
    for h, w in shapes:
        for kind in range(6):
            img = np.full((h, w), 0.5, dtype)
            if kind == 0:
                img[:h // 2, :w // 2] = rng.random((h // 2, w // 2))
            elif kind == 1:
                img[rng.random((h, w)) < 0.01] = 0.7
            elif kind == 2:
                img[:, :w // 3] = 0.25
                img[h // 2:, 2 * w // 3:] = rng.random((h - h // 2, w - 2 * w // 3))
            elif kind == 3:
                img[:, w // 2:] = -0.0
            elif kind == 4:
                img[: h // 2] = np.inf
            lo, hi = pyramids.channel_block_extremes(img[..., None], 3)
            constant = (pyramids.constant_radius_blocks(lo, hi), lo[..., 0], 8)
            with np.errstate(invalid="ignore"):
                want = pyramids.reduce(img)
                got = pyramids.reduce(img, constant=constant)
            assert got.dtype == want.dtype and got.tobytes() == want.tobytes(), (h, w, kind)
    img = rng.random((40, 48)).astype(dtype)
    told = np.zeros((5, 6), np.int32)
    told[2, 3] = 1  # block (2, 3) and its neighbours said to be the constant 7
    got = pyramids.reduce(img, constant=(told, np.full((5, 6), 7.0, dtype), 8))
    assert (got[8:12, 12:16] == 7.0).all() and not (np.delete(got, slice(12, 16), 1) == 7).any()
    with pytest.raises(ValueError, match="constant blocks of shape"):
        pyramids.reduce(img, constant=(told[:4], np.zeros((4, 6), dtype), 8))
    with pytest.raises(ValueError, match="without padding"):
        pyramids.reduce(img, pad_px=2, constant=(told, np.zeros((5, 6), dtype), 8))
    # blocks of 2 px: the taps' reach; the same bytes there too, and 1 px blocks refused
    img = np.full((33, 47), 0.5, dtype)
    img[:9, :20] = rng.random((9, 20))
    lo, hi = pyramids.channel_block_extremes(img[..., None], 1)
    got = pyramids.reduce(img, constant=(pyramids.constant_radius_blocks(lo, hi), lo[..., 0], 2))
    assert got.tobytes() == pyramids.reduce(img).tobytes()
    with pytest.raises(ValueError, match="at least 2 px"):
        pyramids.reduce(img, constant=(np.zeros((33, 47), np.int32), img, 1))


def test_the_pyramids_levels_and_laplacian_bands():
    img = np.random.default_rng(5).random((40, 24))
    pyr = pyramids.gaussian_pyramid(img, 10)
    assert pyr[0] is img and [p.shape for p in pyr] == [(40, 24), (20, 12), (10, 6), (5, 3),
                                                        (3, 2), (2, 1)]
    assert pyramids.pyramid_depth((40, 24), 10) == 5 and pyramids.pyramid_depth((40, 24), 2) == 2
    assert len(pyramids.gaussian_pyramid(img, 2)) == 3
    bands = pyramids.laplacian_levels(pyr, 3)
    assert sorted(bands) == [1, 2, 3]
    assert np.allclose(bands[2], pyr[1] - _expand_ref(pyr[2], pyr[1].shape), atol=1e-14)
    assert [pyramids.level_scale(k) for k in (0, 1, 3)] == [1, 2, 8]
    # each reduce adds a variance of 1 in its input's pixels: 4**j full-resolution px^2
    assert pyramids.gaussian_sigma_px(3) == pytest.approx(np.sqrt(1 + 4 + 16))
    assert pyramids.gaussian_sigma_px(0) == 0


def test_the_smoothed_abs_laplacian_is_a_3x3_mean_of_abs_l():
    """|G_{k-1} - expand(G_k)| averaged over 3 x 3 (borders replicated), on its own grid;
    limited to the tiles asked for, the others 0, the computed ones unchanged."""
    from scipy import ndimage

    img = np.random.default_rng(6).random((70, 90))
    pyr = pyramids.gaussian_pyramid(img, 3)
    got = pyramids.smoothed_abs_laplacian(pyr, 3)
    for k in (1, 2, 3):
        band = np.abs(pyr[k - 1] - _expand_ref(pyr[k], pyr[k - 1].shape))
        assert np.allclose(got[k], ndimage.uniform_filter(band, 3, mode="nearest"), atol=1e-13)
    assert pyramids.tile_grid((70, 90)) == (3, 3) and pyramids.tile_grid((64, 65), 32) == (2, 3)
    need = np.zeros((3, 3), bool)
    need[1, 2] = True
    part = pyramids.smoothed_abs_laplacian(pyr, 1, {1: need})[1]
    assert np.array_equal(part[32:64, 64:90], got[1][32:64, 64:90])
    part[32:64, 64:90] = 0
    assert not part.any()
    assert [pyramids.abs_laplacian_reach_px(k) for k in (1, 2, 3)] == [7, 16, 34]
    assert pyramids.blocks_reaching(16, 8) == 3 and pyramids.blocks_reaching(17, 8) == 4


def test_block_and_window_extremes_by_brute_force():
    rng = np.random.default_rng(8)
    img = rng.random((19, 21, 3))
    add = rng.uniform(-0.2, 0.2, (19, 21))
    lo, hi = pyramids.block_extremes(img, 2, add)
    s = img + add[..., None]
    assert lo[4, 5] == s[16:19, 20:21].min() and hi[1, 2] == s[4:8, 8:12].max()
    assert lo.shape == (5, 6) and (lo <= hi).all()
    clo, chi = pyramids.channel_block_extremes(img, 2)
    assert clo.shape == (5, 6, 3)
    assert clo[2, 3, 1] == img[8:12, 12:16, 1].min() and chi[4, 0, 2] == img[16:, 0:4, 2].max()
    grey_lo, grey_hi = s.min(axis=2), s.max(axis=2)
    x, y = np.array([0.0, 10.4, 20.0, 5.5]), np.array([0.0, 9.6, 18.0, 3.0])
    wlo, whi = pyramids.window_extremes(grey_lo, grey_hi, 2.5, x, y)
    for i in range(4):
        xs = slice(max(int(np.ceil(x[i] - 2.5)), 0), min(int(np.floor(x[i] + 2.5)), 20) + 1)
        ys = slice(max(int(np.ceil(y[i] - 2.5)), 0), min(int(np.floor(y[i] + 2.5)), 18) + 1)
        assert wlo[i] == grey_lo[ys, xs].min() and whi[i] == grey_hi[ys, xs].max()
    full_lo, full_hi = pyramids.window_extremes(grey_lo, grey_hi, 2.5)
    for yy in range(19):  # every pixel: the 5 x 5 window around it, clipped
        for xx in range(21):
            win = np.s_[max(yy - 2, 0): yy + 3, max(xx - 2, 0): xx + 3]
            assert full_lo[yy, xx] == grey_lo[win].min() and full_hi[yy, xx] == grey_hi[win].max()
    # the partial blocks of the right and bottom edges (23 = 5 x 4 + 3 columns)
    lo23, _ = pyramids.block_extremes(rng.random((9, 23)), 2)
    assert lo23.shape == (3, 6)
    clo23, _ = pyramids.channel_block_extremes(rng.random((9, 23, 2)), 2)
    assert clo23.shape == (3, 6, 2)


def _keys(t, a=-0.5):
    t = abs(t)
    if t <= 1:
        return (a + 2) * t**3 - (a + 3) * t**2 + 1
    if t < 2:
        return a * t**3 - 5 * a * t**2 + 8 * a * t - 4 * a
    return 0.0


def test_sampling_a_level_at_full_resolution_coordinates():
    """A level-k grid read at full-resolution (x, y): grid coordinates (x / 2**k, y / 2**k),
    borders held; bilinear as scipy's map_coordinates (order 1, nearest), bicubic with Keys'
    kernel a = -0.5 (MATLAB's imresize 'bicubic'), nearest as the block that holds the
    pixel."""
    from scipy import ndimage

    rng = np.random.default_rng(9)
    grid = rng.random((7, 9))
    x = np.array([0.0, 3.3, 17.9, 40.0, -5.0, 12.0, 1.0, 16.9])
    y = np.array([0.0, 5.2, 11.0, 30.0, 2.0, 27.5, 1.0, 12.9])  # and near the borders
    s = 2.0
    want = ndimage.map_coordinates(grid, [np.clip(y / s, 0, 6), np.clip(x / s, 0, 8)], order=1,
                                   mode="nearest")
    assert np.allclose(pyramids.sample_bilinear(grid, x, y, 1), want, atol=1e-12)
    assert pyramids.sample_bilinear(grid.astype(np.float32), x, y, 1).dtype == np.float32
    cubic = pyramids.sample_cubic(grid, x, y, 1)
    for i in range(len(x)):
        u, v = x[i] / s, y[i] / s
        iu, iv = int(np.floor(u)), int(np.floor(v))
        ref = sum(_keys(v - (iv - 1 + j)) * _keys(u - (iu - 1 + k))
                  * grid[min(max(iv - 1 + j, 0), 6), min(max(iu - 1 + k, 0), 8)]
                  for j in range(4) for k in range(4))
        assert cubic[i] == pytest.approx(ref, abs=1e-12)
    assert pyramids.sample_cubic(grid, np.array([6.0]), np.array([4.0]), 1)[0] == pytest.approx(
        grid[2, 3])  # interpolating: a node gives its value
    # a pair of grids in one pass: each grid's own samples, bit for bit, in float32 too
    other = rng.random((7, 9))
    for a, b in ((grid, other), (grid.astype(np.float32), other.astype(np.float32))):
        pair = pyramids.sample_cubic(np.stack((a, b)), x.reshape(2, 4), y.reshape(2, 4), 1)
        assert pair.shape == (2, 2, 4)
        assert pair[0].tobytes() == pyramids.sample_cubic(a, x, y, 1).reshape(2, 4).tobytes()
        assert pair[1].tobytes() == pyramids.sample_cubic(b, x, y, 1).reshape(2, 4).tobytes()
    with pytest.raises(ValueError, match="pair of grids"):
        pyramids.sample_cubic(np.stack((grid, grid, grid)), x, y, 1)
    near = pyramids.sample_nearest(grid, np.array([0.0, 7.4, 7.6, 100.0]),
                                   np.array([0.0, 3.0, 3.0, -3.0]), 4)
    assert near.tolist() == [grid[0, 0], grid[0, 1], grid[0, 2], grid[0, 8]]
    # the compiled pass against NumPy's truncation, floor division and clip, for blocks of a
    # power of two (a shift) and not, points past every edge, and a 2-D set of points
    rng = np.random.default_rng(3)
    px, py = rng.uniform(-30.0, 60.0, (2, 40, 50))
    for block in (1, 3, 4, 8):
        iy = np.clip((py + 0.5).astype(np.int64) // block, 0, grid.shape[0] - 1)
        ix = np.clip((px + 0.5).astype(np.int64) // block, 0, grid.shape[1] - 1)
        got = pyramids.sample_nearest(grid, px, py, block)
        assert got.shape == px.shape and np.array_equal(got, grid[iy, ix]), block


def test_the_tiles_of_taps_are_those_each_tap_reads():
    """Every tile a point's bilinear taps (and one node more each side) fall in, on levels
    k0 and k0 + 1, is marked, and no other: against the taps enumerated one by one, with
    points past the edges (clamped) and levels out of range (skipped)."""
    rng = np.random.default_rng(5)
    shape = (300, 517)
    gaussian = pyramids.gaussian_pyramid(rng.random(shape, dtype=np.float32), 5)
    top, tile = 4, 8
    n = 60
    x = rng.uniform(-40.0, shape[1] + 40.0, n)
    y = rng.uniform(-40.0, shape[0] + 40.0, n)
    k0 = rng.integers(-1, top + 1, n)
    got = pyramids.tiles_of_taps(x, y, k0, gaussian, top, tile)
    assert sorted(got) == list(range(1, top + 1))
    for k in range(1, top + 1):
        h, w = gaussian[k - 1].shape
        want = np.zeros(pyramids.tile_grid((h, w), tile), bool)
        scale = 2.0 ** (k - 1)
        for i in np.flatnonzero((k0 == k) | (k0 + 1 == k)):
            ny, nx = int(np.floor(y[i] / scale)), int(np.floor(x[i] / scale))
            for dy in range(-1, 3):
                for dx in range(-1, 3):
                    want[min(max(ny + dy, 0), h - 1) // tile,
                         min(max(nx + dx, 0), w - 1) // tile] = True
        assert np.array_equal(got[k], want), k
        assert want.any() and (k > 2 or not want.all())  # a test that can tell
    with pytest.raises(ValueError, match="power of two"):
        pyramids.tiles_of_taps(x, y, k0, gaussian, top, 12)


def test_block_extremes_take_the_known_blocks_without_reading_them():
    """block_extremes(known=(mask, lo, hi)): the marked blocks' extremes are the given ones
    plus 0.0 (-0.0 becomes +0.0, as a read of x + 0.0 gives) and their pixels are never read
    (NaN there changes nothing); every other block as without them; the rows of known
    blocks all in one part of the frame (the threads' share of the rest); grids of the
    wrong shape refused."""
    rng = np.random.default_rng(11)
    img = rng.random((70, 90)).astype(np.float32)
    add = rng.normal(0, 0.1, (70, 90)).astype(np.float32)
    lo, hi = pyramids.block_extremes(img, 3, add)
    mask = np.zeros(lo.shape, bool)
    mask[4:, :] = True
    mask[0, 2] = True
    poisoned = img.copy()
    poisoned[np.kron(mask, np.ones((8, 8), bool))[:70, :90]] = np.nan
    known_lo = np.where(mask, np.float32(-0.0), lo)
    known_hi = np.where(mask, np.float32(0.25), hi)
    glo, ghi = pyramids.block_extremes(poisoned, 3, add, known=(mask, known_lo, known_hi))
    assert np.array_equal(glo[~mask], lo[~mask]) and np.array_equal(ghi[~mask], hi[~mask])
    assert (glo[mask] == 0).all() and not np.signbit(glo[mask]).any() and (ghi[mask] == 0.25).all()
    with pytest.raises(ValueError, match="known block grids must have shape"):
        pyramids.block_extremes(img, 3, add, known=(mask[:-1], known_lo, known_hi))
