"""Sparse Gabor noise (paper section 4.4; Lagae et al. 2009): kernel radius, impulse density,
the K / 6 normalisation, and the synthesis against a direct sum."""

import math

import numpy as np
import pytest

from fovexp import gabor, make_options


def test_kernel_radius_and_density_as_computed_by_hand():
    """docs/METHOD.md, 4: r = sqrt(-ln 0.01 / pi) / a; N impulses per kernel of area pi r^2."""
    assert gabor.kernel_radius_px(0.06) == pytest.approx(20.2, abs=0.05)
    assert gabor.kernel_radius_px(0.08) == pytest.approx(15.1, abs=0.05)
    imp = gabor.generate_impulses(2000, 1000, 12, 0.06, 5)
    inside = (imp.x_px >= 0) & (imp.x_px < 2000) & (imp.y_px >= 0) & (imp.y_px < 1000)
    lam = gabor.impulse_density(12, 0.06)
    assert inside.sum() / (2000 * 1000) == pytest.approx(lam, rel=0.03)


@pytest.mark.parametrize("n", [12, 64])
def test_noise_std_over_k_is_one_sixth_whatever_the_impulse_count(n):
    """docs/METHOD.md, 5.9: the release's noise has std / K = 0.164 (measured) for 12 and 64."""
    h, w = 600, 800
    imp = gabor.generate_impulses(w, h, n, 0.06, 2)
    m = len(imp)
    rng = np.random.default_rng(0)
    noise = gabor.synthesize((h, w), imp, np.full(m, 0.3), rng.uniform(0.08, 0.4, m),
                             rng.uniform(0, np.pi, m), n, 0.06)
    ratio = noise[40:-40, 40:-40].std() / 0.3
    assert ratio == pytest.approx(1 / 6, rel=0.04)


def direct_sum(shape, imp, k, f, t, r_px, a, norm) -> np.ndarray:
    """The noise written out (paper section 4.4, as fovexp.gabor states it): each impulse's
    Gabor kernel exp(-pi a^2 d^2) cos(2 pi f (d . (cos t, sin t))), times w_i K_i and the
    normalisation, cut to the square of half-side ``r_px``; float64, every pixel, no skipping."""
    h, w = shape
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    ref = np.zeros((h, w))
    for i in range(len(imp)):
        dx, dy = xx - imp.x_px[i], yy - imp.y_px[i]
        g = np.exp(-math.pi * a * a * (dx * dx + dy * dy)) * np.cos(
            2 * math.pi * f[i] * (dx * math.cos(t[i]) + dy * math.sin(t[i])))
        g[(np.abs(dx) > r_px) | (np.abs(dy) > r_px)] = 0
        ref += imp.weight[i] * k[i] * norm * g
    return ref


@pytest.mark.parametrize("a,window_px", [(0.06, 48), (0.1, 32), (0.04, 64), (0.03, 96)])
def test_synthesis_matches_direct_sum_of_truncated_gabors(a, window_px):
    """Against the kernels summed directly, for each window width the synthesis has a path
    of its own for (48 px, both presets) and those it has not (32, 64, 96 px)."""
    assert gabor._window(gabor.kernel_radius_px(a))[0] == window_px
    h, w = 64, 80
    imp = gabor.generate_impulses(w, h, 3, a, 9)
    m = len(imp)
    rng = np.random.default_rng(1)
    k, f, t = rng.random(m), rng.uniform(0.05, 0.45, m), rng.uniform(-np.pi, np.pi, m)
    fast = gabor.synthesize((h, w), imp, k, f, t, 3, a)
    ref = direct_sum((h, w), imp, k, f, t, gabor.kernel_radius_px(a), a,
                     gabor.normalisation(3, a))
    assert np.abs(fast - ref).max() < 1e-4 * max(1.0, np.abs(ref).max())


def test_impulses_are_deterministic_from_the_seed():
    a = gabor.generate_impulses(300, 200, 12, 0.06, 1)
    b = gabor.generate_impulses(300, 200, 12, 0.06, 1)
    c = gabor.generate_impulses(300, 200, 12, 0.06, 2)
    assert np.array_equal(a.x_px, b.x_px) and np.array_equal(a.weight, b.weight)
    assert len(a) != len(c) or not np.array_equal(a.x_px, c.x_px)


def test_the_impulses_of_a_seed_are_pinned():
    """The first impulses of seed 1 on a 50 x 40 image, as this version generates them: a
    trial log's seed gives the same noise in a later version (its hash, cell keys and
    uniform draws unchanged; a change here must be deliberate and say so)."""
    imp = gabor.generate_impulses(50, 40, 12, 0.06, 1)
    assert len(imp) == 72 and imp.cell_px == gabor.kernel_radius_px(0.06)
    want = [(-4.421754127861437, -8.488593421059363, 0.20083293318748474, 0.551043470023197),
            (-18.025707016153785, -8.039788968838236, 0.3743612468242645, 0.5058563198010539),
            (-7.59169169080764, -6.5811868411684715, 0.8309105634689331, 0.358509420662877)]
    for i, (x, y, w, q) in enumerate(want):
        assert (imp.x_px[i], imp.y_px[i], float(imp.weight[i]), imp.quantile[i]) == pytest.approx(
            (x, y, w, q), rel=1e-15, abs=1e-15)


def test_impulses_lie_in_their_cells_with_the_counts_asked_for():
    """Cells of side r from -0.5 px, one cell past each edge; a Poisson count of mean
    N s^2 / (pi r^2) = N / pi per cell, or jittered (floor or ceil of it); weights uniform in
    (-1, 1), or their signs; quantiles in (0, 1)."""
    w, h, n = 400, 300, 12
    cell = gabor.cell_size_px(0.06)
    assert gabor.cell_counts(w, h, cell) == (math.ceil(w / cell) + 2, math.ceil(h / cell) + 2)
    assert gabor.cell_size_px(0.06, 0.5) == pytest.approx(0.5 * cell)
    assert gabor.cell_index(np.array([-0.5, -0.6, cell - 0.51, cell - 0.5]), cell).tolist() == [
        1, 0, 1, 2]
    poisson = gabor.generate_impulses(w, h, n, 0.06, 3)
    nx, ny = gabor.cell_counts(w, h, cell)
    assert poisson.x_px.min() >= -cell - 0.5 and poisson.x_px.max() < (nx - 1) * cell - 0.5
    assert poisson.y_px.min() >= -cell - 0.5 and poisson.y_px.max() < (ny - 1) * cell - 0.5
    assert np.all(np.diff(gabor.cell_index(poisson.y_px, cell)) >= 0)  # sorted by cell row
    key = gabor.cell_index(poisson.y_px, cell) * nx + gabor.cell_index(poisson.x_px, cell)
    counts = np.bincount(key, minlength=nx * ny)
    m = n / math.pi
    assert counts.mean() == pytest.approx(m, rel=0.1)
    assert counts.var() == pytest.approx(m, rel=0.35)  # Poisson: variance = mean
    jit = gabor.generate_impulses(w, h, n, 0.06, 3, count="jittered", weights="sign")
    jc = np.bincount(gabor.cell_index(jit.y_px, cell) * nx + gabor.cell_index(jit.x_px, cell),
                     minlength=nx * ny)
    # floor(m) or ceil(m), ceil with probability m - floor(m): the mean m within 3 of its
    # standard errors (0.4 % with these 374 cells)
    assert set(jc.tolist()) == {math.floor(m), math.ceil(m)}
    assert jc.mean() == pytest.approx(m, abs=3 * math.sqrt((m % 1) * (1 - m % 1) / jc.size))
    assert set(np.unique(jit.weight).tolist()) == {-1.0, 1.0}
    assert -1 < poisson.weight.min() < -0.9 and 0.9 < poisson.weight.max() < 1
    assert abs(poisson.weight.mean()) < 0.1
    assert 0 < poisson.quantile.min() < 0.05 and 0.95 < poisson.quantile.max() < 1
    with pytest.raises(ValueError, match="unknown impulse count"):
        gabor.generate_impulses(w, h, n, 0.06, 3, count="grid")


def test_the_normalisation_by_hand():
    """1 / (6 sqrt(V)), V = lambda E[w^2] / (4 a^2) (1 + exp(-2 pi F^2 / a^2)) with F = 1/16
    (docs/METHOD.md, 5.9), lambda = N / (pi r^2); a kernel cut elsewhere than at 0.01 keeps
    erf(sqrt(2 pi) a r)^2 of its energy, relative to the 0.01 cut's."""
    a, n = 0.06, 12
    r = math.sqrt(-math.log(0.01) / math.pi) / a
    lam = n / (math.pi * r * r)
    assert gabor.impulse_density(n, a) == pytest.approx(lam, rel=1e-12)
    for weights, msq in (("uniform", 1 / 3), ("sign", 1.0)):
        v = lam * msq / (4 * a * a) * (1 + math.exp(-2 * math.pi * 0.0625**2 / a**2))
        assert gabor.normalisation(n, a, weights) == pytest.approx(1 / (6 * math.sqrt(v)),
                                                                    rel=1e-12)
    r5 = math.sqrt(-math.log(0.05) / math.pi) / a
    kept = (math.erf(math.sqrt(2 * math.pi) * a * r5) / math.erf(math.sqrt(2 * math.pi) * a * r))
    assert gabor.normalisation(n, a, "uniform", 0.05) == pytest.approx(
        gabor.normalisation(n, a) / kept, rel=1e-12)
    # 2 ceil(r) + 2 = 44 columns, rounded up to 16s; the pad holds a window that starts up to
    # 2 ceil(r) + 1 columns left of the image (an impulse r left of it)
    assert gabor._window(r) == (48, 44)


def test_synthesis_without_skipping_and_with_a_closer_cut():
    """skip=False sums every impulse (zeros included): the same noise; a kernel cut at 0.5
    is the direct sum of kernels truncated to the square of half-side r(0.5)."""
    h, w = 40, 48
    imp = gabor.generate_impulses(w, h, 3, 0.06, 4)
    m = len(imp)
    rng = np.random.default_rng(2)
    k = np.where(rng.random(m) < 0.3, 0.0, rng.random(m))
    f, t = rng.uniform(0.05, 0.45, m), rng.uniform(-np.pi, np.pi, m)
    fast = gabor.synthesize((h, w), imp, k, f, t, 3, 0.06)
    assert np.array_equal(fast, gabor.synthesize((h, w), imp, k, f, t, 3, 0.06, skip=False))
    assert fast.dtype == np.float32
    assert gabor.synthesize((h, w), imp, k, f, t, 3, 0.06, dtype=np.float64).dtype == np.float64
    assert not gabor.synthesize((h, w), imp, np.zeros(m), f, t, 3, 0.06).any()
    one = np.zeros(m)
    one[np.argmin(np.hypot(imp.x_px - 24, imp.y_px - 20))] = 1.0  # one impulse, mid-image
    assert gabor.synthesize((h, w), imp, one, f, t, 3, 0.06).any()
    cut = gabor.synthesize((h, w), imp, k, f, t, 3, 0.06, 0.5, dtype=np.float64)
    ref = direct_sum((h, w), imp, k, f, t, gabor.kernel_radius_px(0.06, 0.5), 0.06,
                     gabor.normalisation(3, 0.06, "uniform", 0.5))
    assert np.abs(cut - ref).max() < 1e-9 * max(1.0, np.abs(ref).max())


@pytest.mark.parametrize("skip", [True, False])
def test_the_values_of_some_impulses_are_the_noise_of_every_impulse_with_the_others_zero(skip):
    """``index``: K, F and t given for some impulses only (the pipeline's band) sum to the
    same bits as every impulse's arrays with zeros elsewhere, skipping or not; an index that
    is not ascending or does not match the values is refused by name."""
    h, w = 64, 80
    imp = gabor.generate_impulses(w, h, 12, 0.06, 9)
    m = len(imp)
    rng = np.random.default_rng(3)
    index = np.flatnonzero(rng.random(m) < 0.4)
    k = rng.random(index.size)
    k[::5] = 0.0  # a given K of 0 is no kernel either
    f, t = rng.uniform(0.05, 0.45, index.size), rng.uniform(-np.pi, np.pi, index.size)
    full = [np.zeros(m) for _ in range(3)]
    for a, v in zip(full, (k, f, t), strict=True):
        a[index] = v
    want = gabor.synthesize((h, w), imp, *full, 12, 0.06, skip=skip)
    got = gabor.synthesize((h, w), imp, k, f, t, 12, 0.06, skip=skip, index=index)
    assert want.any() and np.array_equal(got, want)
    # the cell rows the set-up counts are cell_index's
    rows = gabor.cell_index(imp.y_px, imp.cell_px)
    assert np.array_equal(rows, np.floor((imp.y_px + 0.5) / imp.cell_px).astype(np.int64) + 1)
    with pytest.raises(ValueError, match="ascending"):
        gabor.synthesize((h, w), imp, k[::-1], f, t, 12, 0.06, index=index[::-1])
    with pytest.raises(ValueError, match=f"{index.size} values"):
        gabor.synthesize((h, w), imp, k[1:], f, t, 12, 0.06, index=index)


def test_each_band_holds_the_kernels_whose_first_row_it_holds_even_past_the_last_cells():
    """``_band_impulses``, run as Python (NumPy's bounds checked): each band of rows gets the
    impulses whose kernel's first image row lies in it and that reach the image, worked
    out directly, including the bottom band of a frame where cells a quarter of r and a
    kernel cut at 1e-6 (r = 35 px) put its rows past the last cell row's reach. There the
    cell-row range had started past its end, and the compiled kernel read past the end of
    ``row_start`` (the stress suite's std test failed once in a while with "negative
    dimensions")."""
    a, side = 0.06, 779
    imp = gabor.generate_impulses(side, side, 12, a, 0, cell_scale=0.25)
    r = gabor.kernel_radius_px(a, 1e-6)
    n_rows = gabor.cell_counts(side, side, imp.cell_px)[1]
    rows = gabor.cell_index(imp.y_px, imp.cell_px)
    row_start = np.searchsorted(rows, np.arange(n_rows + 1)).astype(np.int64)
    first = np.maximum(0, np.ceil(imp.y_px - r)).astype(np.int64)
    reaches = ((np.floor(imp.y_px + r) >= first) & (first < side) & (imp.x_px + r >= 0)
               & (imp.x_px - r <= side - 1))
    counts = []
    for y0 in range(0, side, 128):
        y1 = min(side, y0 + 128)
        got = gabor._band_impulses.py_func(imp.x_px, imp.y_px, row_start, imp.cell_px, r, y0,
                                           y1, side)
        want = np.flatnonzero(reaches & (first >= y0) & (first < y1))
        assert np.array_equal(got, want), y0
        counts.append(got.size)
    assert counts[-1] == 0 and min(counts[:-1]) > 800  # the bottom band: past every kernel


_MASK64 = 2**64 - 1


def _splitmix(state: int) -> tuple[int, int]:
    """SplitMix64 (Steele et al. 2014), written out on Python integers."""
    state = (state + 0x9E3779B97F4A7C15) & _MASK64
    z = state
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & _MASK64
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & _MASK64
    return state, z ^ (z >> 31)


def _uniform(state: int) -> tuple[int, float]:
    """53 random bits as (k + 1/2) / 2**53: strictly inside (0, 1)."""
    state, z = _splitmix(state)
    return state, ((z >> 11) + 0.5) / 2.0**53


def _cell_state(seed: int, cx: int, cy: int) -> int:
    """A cell's stream, keyed by its coordinates modulo the period and the seed."""
    p = gabor.CELL_PERIOD
    key = (seed * 0x100000001B3 + (cx % p) * p + (cy % p)) & _MASK64
    return _splitmix(key)[0]


def reference_impulses(w, h, n, a, seed, count="poisson", cell_scale=1.0):
    """The impulses as fovexp.gabor documents them, in plain Python: per cell (rows of cells
    from one cell past the top-left corner), a first uniform u gives the count (jittered:
    floor(m) + 1 if u < m - floor(m), else floor(m); Poisson, Knuth's: multiply uniforms
    while the product is above exp(-m)), then per impulse the uniforms x, y, weight, quantile."""
    cell = gabor.cell_size_px(a, cell_scale)
    m = gabor.impulse_density(n, a) * cell * cell
    nx, ny = math.ceil(w / cell) + 2, math.ceil(h / cell) + 2
    out = []
    for cy in range(-1, ny - 1):
        for cx in range(-1, nx - 1):
            state, u = _uniform(_cell_state(seed, cx, cy))
            if count == "jittered":
                k = int(m) + (1 if u < m - int(m) else 0)
            else:
                k, p = 0, u
                while p > math.exp(-m):
                    k += 1
                    state, u = _uniform(state)
                    p *= u
            for _ in range(k):
                state, ux = _uniform(state)
                state, uy = _uniform(state)
                state, uw = _uniform(state)
                state, uq = _uniform(state)
                out.append(((cx + ux) * cell - 0.5, (cy + uy) * cell - 0.5,
                            float(np.float32(2.0 * uw - 1.0)), uq))
    return out


def _as_tuples(imp):
    return list(zip(imp.x_px.tolist(), imp.y_px.tolist(), imp.weight.tolist(),
                    imp.quantile.tolist(), strict=True))


def test_the_impulses_are_the_documented_stream_bit_for_bit():
    """Every impulse (position, weight, quantile) is the SplitMix64 stream of its cell as the
    module states it, to the last bit: the uniforms are (k + 1/2) / 2**53, not shifted by a
    step, so a trial log's seed gives the same noise in any later version."""
    for count in ("poisson", "jittered"):
        imp = gabor.generate_impulses(50, 40, 12, 0.06, 1, count=count)
        assert _as_tuples(imp) == reference_impulses(50, 40, 12, 0.06, 1, count)


#: cell scales (EngineOptions.cell_scale) tuned so that a cell's count rule is a tie: the first
#: uniform u of cell (-1, -1) of the seed equals m - floor(m) (jittered) or exp(-m) (Poisson),
#: exactly; found by stepping the scale one float at a time (m = N cell_scale^2 / pi)
JITTERED_TIE = (8, 0.6493474777778507)  # seed, cell_scale: m = 1.61059..., u = 0.61059...
POISSON_TIE = (3, 0.35247422289677977)  # m = 0.47455..., exp(-m) = u = 0.62216...


@pytest.mark.parametrize(("count", "tie"), [("jittered", JITTERED_TIE), ("poisson", POISSON_TIE)])
def test_a_count_on_its_tie_follows_the_rule_as_written(count, tie):
    """A uniform exactly on the count's threshold, which a tuned cell_scale reaches: the
    jittered count adds its extra impulse only if u < m - floor(m) (so u = m - floor(m) gives
    floor(m)), Knuth's Poisson count goes on only while the product is > exp(-m) (so
    u = exp(-m) gives 0); the cell's count and every impulse of the frame are the reference's."""
    seed, scale = tie
    a = 0.06
    cell = gabor.cell_size_px(a, scale)
    m = gabor.impulse_density(12, a) * cell * cell
    u = _uniform(_cell_state(seed, -1, -1))[1]
    assert u == (m - math.floor(m) if count == "jittered" else math.exp(-m))  # the tie
    make_options(cell_scale=scale)  # a scale the engine accepts
    imp = gabor.generate_impulses(40, 30, 12, a, seed, count=count, cell_scale=scale)
    first = (gabor.cell_index(imp.x_px, cell) == 0) & (gabor.cell_index(imp.y_px, cell) == 0)
    assert first.sum() == (math.floor(m) if count == "jittered" else 0)
    assert _as_tuples(imp) == reference_impulses(40, 30, 12, a, seed, count, scale)


def test_the_kernel_square_is_closed_at_its_radius():
    """The kernel is cut to the closed square |d_x|, |d_y| <= r: a pixel exactly r from an
    impulse gets the kernel's value there (the envelope equals the cut, 0.305 here), the
    pixel past it nothing. One impulse at x = 16.25 with r = 10.25 exactly (a cut tuned one
    float at a time, an EngineOptions.kernel_truncation the engine accepts): column 6 lies at
    |d| = r, column 5 beyond; the synthesis is the direct sum, which keeps |d| = r."""
    a, trunc = 0.06, 0.3047605534365342
    r = gabor.kernel_radius_px(a, trunc)
    assert r == 10.25  # the tie asked for
    make_options(kernel_truncation=trunc)
    imp = gabor.Impulses(np.array([16.25]), np.array([12.0]), np.array([0.5], np.float32),
                         np.array([0.5]), gabor.cell_size_px(a), 0)
    one = (np.ones(1), np.zeros(1), np.zeros(1))  # K = 1, F = 0 (no carrier), t = 0
    out = gabor.synthesize((24, 32), imp, *one, 12, a, trunc, dtype=np.float64)
    ref = direct_sum((24, 32), imp, *one, r, a, gabor.normalisation(12, a, "uniform", trunc))
    assert ref[12, 6] == pytest.approx(0.5 * gabor.normalisation(12, a, "uniform", trunc)
                                       * trunc, rel=1e-12)
    assert np.abs(out - ref).max() < 1e-9 * np.abs(ref).max()
    assert out[12, 6] != 0.0 and not out[:, :6].any()


def test_amplitudes_of_negative_zero_add_no_noise():
    """K = -0.0 is K = 0: those impulses are skipped (and add exact zeros when summed), the
    noise of K = -0.0 everywhere is +0.0 everywhere, as K = 0's."""
    imp = gabor.generate_impulses(48, 40, 3, 0.06, 4)
    m = len(imp)
    rng = np.random.default_rng(3)
    f, t = rng.uniform(0.05, 0.45, m), rng.uniform(-np.pi, np.pi, m)
    zero = np.zeros((40, 48), np.float32).tobytes()
    for skip in (True, False):
        assert gabor.synthesize((40, 48), imp, np.full(m, -0.0), f, t, 3, 0.06,
                                skip=skip).tobytes() == zero


def test_the_set_ups_sine_and_cosine_are_libms_to_a_unit_in_the_last_place():
    """The synthesis's own (sin, cos) (gabor._sincos, which vectorises) against libm's over
    the phases it is given (|x| up to a few hundred rad) and past them, every quadrant edge
    included: within 2.3e-16 (one unit in the last place of 1)."""
    import numba

    @numba.njit
    def both(x, s, c):
        for i in range(x.shape[0]):
            s[i], c[i] = gabor._sincos(x[i])

    rng = np.random.default_rng(0)
    edges = np.arange(-400, 401) * (math.pi / 4)
    x = np.concatenate([rng.uniform(-300.0, 300.0, 100_000), edges, edges + 1e-9,
                        edges - 1e-9, [0.0, -0.0, 1e-300, 2.0**24]])
    s, c = np.empty_like(x), np.empty_like(x)
    both(x, s, c)
    assert np.abs(s - np.sin(x)).max() <= 2.3e-16
    assert np.abs(c - np.cos(x)).max() <= 2.3e-16
    assert s[x.size - 2] == 1e-300 and c[x.size - 2] == 1.0  # a tiny phase, exactly


def test_the_set_ups_exponential_is_libms_to_a_unit_in_the_last_place():
    """The synthesis's own e^x (gabor._exp, which vectorises) against libm's over the
    exponents the set-up gives it (-pi a^2 d^2 and the like, down to several hundred at a
    close cut) and at the reduction's edges: within one unit in the last place; exactly 1 at
    0, 0 below -708 where e^x is subnormal."""
    rng = np.random.default_rng(1)
    edges = -np.arange(0, 1000) * (math.log(2.0) / 2.0)
    x = np.concatenate([-rng.exponential(20.0, 100_000), -rng.uniform(0.0, 700.0, 10_000),
                        edges[edges > -700], edges[edges > -700] - 1e-12, [0.0, -0.0]])
    y = x.copy()
    gabor._exp_into(y, y.size)
    assert (np.abs(y - np.exp(x)) <= np.spacing(np.exp(x))).all()
    assert y[-1] == 1.0 and y[-2] == 1.0
    z = np.array([-708.5, -1000.0, -np.inf])
    gabor._exp_into(z, z.size)
    assert (z == 0.0).all()


def test_the_noise_is_written_on_the_columns_its_kernels_span_only():
    """written=True: each row holds values only on the span its kernels' windows cover (one
    kernel: its own window's columns, its rows; none elsewhere), the rest never written;
    full() is the noise synthesize gives, bit for bit."""
    h, w = 120, 400
    imp = gabor.generate_impulses(w, h, 3, 0.06, 4)
    m = len(imp)
    rng = np.random.default_rng(3)
    f, t = rng.uniform(0.05, 0.45, m), rng.uniform(-np.pi, np.pi, m)
    one = np.zeros(m)
    i = int(np.argmin(np.hypot(imp.x_px - 200, imp.y_px - 60)))
    one[i] = 1.0
    noise = gabor.synthesize((h, w), imp, one, f, t, 3, 0.06, written=True)
    r = gabor.kernel_radius_px(0.06)
    nwin, _ = gabor._window(r)
    x0 = math.floor(imp.x_px[i]) - math.ceil(r)
    rows = np.flatnonzero(noise.spans[:, 1] > noise.spans[:, 0])
    assert rows.size and (noise.spans[rows] == (x0, x0 + nwin)).all()
    assert rows[0] <= math.ceil(imp.y_px[i] - r) and math.floor(imp.y_px[i] + r) <= rows[-1]
    assert rows[-1] - rows[0] < 2 * gabor.BAND_ROWS + 2 * nwin  # its band and the next, at most
    full = noise.full()
    assert np.array_equal(full, gabor.synthesize((h, w), imp, one, f, t, 3, 0.06))
    assert np.abs(full).max() > 0
    k = np.where(rng.random(m) < 0.5, 0.0, rng.random(m))
    many = gabor.synthesize((h, w), imp, k, f, t, 3, 0.06, written=True)
    assert np.array_equal(many.full(), gabor.synthesize((h, w), imp, k, f, t, 3, 0.06))


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_the_vector_rows_are_the_loops_bits(dtype):
    """The 48-column window's rows in vectors held over the rows (gabor._vector_rows) add
    each value exactly as the loop does (gabor._kernel_rows: fma(cr, er, fma(-ci, ei, v))),
    rows of an array wider than the window, the window at an unaligned column, a kernel that
    is not its group's first."""
    import numba

    @numba.njit
    def both(flat_v, flat_l, stride, at, rows, er, ei, fr, fi, j):
        gabor._vector_rows(flat_v, np.uint64(stride), np.uint64(at), np.int64(rows), er, ei,
                           fr, fi, np.int64(j), 3)
        gabor._kernel_rows(flat_l, stride, np.uint64(at), rows, 48, er, ei, fr, fi, j)

    rng = np.random.default_rng(3)
    stride, rows = 101, 41
    flat = rng.standard_normal(stride * (rows + 2)).astype(dtype)
    er, ei = (rng.standard_normal(48).astype(dtype) for _ in range(2))
    fr, fi = (rng.standard_normal((rows, 64)).astype(dtype) for _ in range(2))
    flat_v, flat_l = flat.copy(), flat.copy()
    both(flat_v, flat_l, stride, stride + 7, rows, er, ei, fr, fi, 5)
    assert flat_v.tobytes() == flat_l.tobytes()
    changed = flat_v != flat
    assert changed.sum() == rows * 48  # the window's values, and nothing else
    end = stride + 7 + (rows - 1) * stride + 48  # one past the window's last value
    assert not changed[:stride + 7].any() and not changed[end:].any()


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_the_x_factors_four_chains_as_one_vector_are_the_scalar_steps(dtype):
    """gabor._four_chains steps the x factor's four chains as one vector: every value is
    the scalar recurrence's (written out here in Python's float64 arithmetic), converted
    to the output's dtype, and nothing past the steps asked for is written."""
    import numba

    @numba.njit
    def chains(er, ei, e, g, c, s, rc4, rs4, sq16, steps):
        gabor._four_chains(er, ei, (e[0], e[1], e[2], e[3]), (g[0], g[1], g[2], g[3]),
                           (c[0], c[1], c[2], c[3]), (s[0], s[1], s[2], s[3]), rc4, rs4,
                           sq16, np.int64(steps))

    rng = np.random.default_rng(4)
    e, g = rng.uniform(0.2, 1.0, 4), rng.uniform(0.8, 1.1, 4)
    angle = rng.uniform(0, 2 * np.pi, 4)
    c, s = np.cos(angle), np.sin(angle)
    rc4, rs4, sq16 = math.cos(0.7), math.sin(0.7), 0.93
    steps = 11
    er, ei = np.full(48, 7.0, dtype), np.full(48, 7.0, dtype)
    chains(er, ei, e, g, c, s, rc4, rs4, sq16, steps)
    want_r, want_i = np.full(48, 7.0, dtype), np.full(48, 7.0, dtype)
    e, g, c, s = ([float(v) for v in x] for x in (e, g, c, s))
    for t in range(steps):
        for p in range(4):
            want_r[4 * t + p], want_i[4 * t + p] = e[p] * c[p], e[p] * s[p]
            e[p], g[p] = e[p] * g[p], g[p] * sq16
            c[p], s[p] = c[p] * rc4 - s[p] * rs4, s[p] * rc4 + c[p] * rs4
    assert er.tobytes() == want_r.tobytes() and ei.tobytes() == want_i.tobytes()
    assert (er[4 * steps:] == 7.0).all()


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_the_y_factors_as_vector_lanes_are_each_kernels_scalar_steps(dtype):
    """gabor._y_factors steps a group's kernels as the lanes of one vector: every kernel's
    row factors are its own recurrence's (written out here in Python's float64
    arithmetic), converted to the factors' dtype, for a group that is not a whole number
    of vectors; rows past those asked for are not written."""
    import numba

    @numba.njit
    def y_factors(su, m, rows, step_q, yf):
        gabor._y_factors(su, np.int64(m), np.int64(rows), step_q, yf)

    rng = np.random.default_rng(5)
    group, m, rows, step_q = gabor.SETUP_GROUP, 21, 9, 0.955
    su = rng.uniform(-1.0, 1.0, (21, group))
    su[15], su[17] = rng.uniform(0.1, 1.0, group), rng.uniform(0.9, 1.2, group)
    yf = np.full((2, rows + 2, group), 7.0, dtype)
    y_factors(su, m, rows, step_q, yf)
    for j in range(m):
        s, c, rs, rc, env, q = (float(su[k, j]) for k in (10, 11, 12, 13, 15, 17))
        want = np.empty((2, rows), dtype)
        for row in range(rows):
            want[0, row], want[1, row] = env * c, env * s
            env, q = env * q, q * step_q
            c, s = c * rc - s * rs, s * rc + c * rs
        assert yf[:, :rows, j].tobytes() == want.tobytes()
    assert (yf[:, rows:] == 7.0).all()
