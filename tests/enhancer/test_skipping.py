"""Skipping what a scene does not need (EngineOptions.skip, issue 10 section 2) is exact: the
output with it is the output without it, bit for bit; the arithmetic it relies on (a constant
region comes out as its constant, |L| and the contrast change exactly 0 there) is tested
stage by stage; and it does leave work out."""

import numpy as np
import pytest

from fovexp import (
    EngineOptions,
    EnhanceParams,
    Enhancer,
    contrast,
    foveation,
    load_display,
    pyramids,
)
from fovexp.sequence import iter_frames

from engine_helpers import mixed_scene, textured_image

LG = load_display("lg-oled55cx")
MAPS = ("output", "noise", "contrast", "foveated", "amplitude")


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a).view(np.uint32 if a.dtype == np.float32 else np.uint64)


def _both(image, gaze=(0.5, 0.5), set_kw=None, preset="paper", **params):
    p = EnhanceParams(**{"blur_rate": 0.57, "impulses": 24, "preset": preset, **params})
    out = []
    for skip in (True, False):
        enh = Enhancer(LG, preset=preset, options=EngineOptions(skip=skip))
        enh.set_image(image, **(set_kw or {}))
        out.append((enh, enh.enhance(gaze, p)))
    return out


@pytest.mark.parametrize("foveated_input", [False, True])
@pytest.mark.parametrize("gaze", [(0.5, 0.5), (0.31, 0.62)])
def test_skipping_changes_nothing_bit_for_bit(foveated_input, gaze):
    image = mixed_scene()
    (_, on), (_, off) = _both(image, gaze, {"foveated": foveated_input})
    for name in MAPS:
        assert np.array_equal(_bits(on.map(name)), _bits(off.map(name))), name
    assert np.array_equal(_bits(on.linear("contrast")), _bits(off.linear("contrast")))
    # the scene has what the test is about: noise, flat regions without it, and a change
    noise = on.map("noise")
    assert np.abs(noise).max() > 0.01
    assert (noise[301:, 601:899] == 0).mean() > 0.25  # the flat grey region, away from edges
    assert np.abs(on.map("contrast") - on.map("foveated")).max() > 0.01


@pytest.mark.parametrize("kw", [
    {"method": "contrast"}, {"impulses": 64, "seed": 5}, {"blur_rate": 0.11},
])
def test_skipping_is_exact_for_other_methods_and_parameters(kw):
    (_, on), (_, off) = _both(mixed_scene(270, 480, seed=8), (0.4, 0.5), **kw)
    assert np.array_equal(_bits(on.output), _bits(off.output))


def test_skipping_is_exact_on_grey_images_the_release_preset_and_viewports():
    grey = mixed_scene(270, 480, rgb=False)
    (_, on), (_, off) = _both(grey)
    assert np.array_equal(_bits(on.output), _bits(off.output))
    (_, on), (_, off) = _both(mixed_scene(270, 480), preset="release", blur_rate=0.46875)
    assert np.array_equal(_bits(on.output), _bits(off.output))
    half = mixed_scene(270, 480)[:, 240:]
    (_, on), (_, off) = _both(half, set_kw={"viewport": (240, 0, 480, 270)})
    assert np.array_equal(_bits(on.output), _bits(off.output))


def test_skipping_a_given_sigma_map_and_a_parameter_step_stays_exact():
    image = mixed_scene(270, 480)
    (enh, full), _ = _both(image)
    sigma, fov = full.map("sigma_px"), full.map("foveated")
    (e_on, on), (e_off, off) = _both(fov, set_kw={"sigma_px": sigma})
    assert np.array_equal(_bits(on.output), _bits(off.output))
    step = on.params.model_copy(update={"s_k": 30.0, "f_e": 0.4})
    assert np.array_equal(_bits(e_on.enhance((0.5, 0.5), step).output),
                          _bits(e_off.enhance((0.5, 0.5), step).output))


@pytest.mark.slow
def test_skipping_changes_nothing_on_the_real_frame(sponza):
    (_, on), (_, off) = _both(sponza, blur_rate=0.34, impulses=12)
    assert np.array_equal(_bits(on.output), _bits(off.output))


def test_skipping_leaves_work_out():
    """What skipping leaves out, on the mixed scene: impulses with an empty band, impulses
    whose neighbourhood is flat (and so their |L| tiles), and the contrast change of flat
    blocks; each is exactly what the full computation gives there (the test above)."""
    (on_enh, _), (off_enh, _) = _both(mixed_scene())
    band_all = off_enh._c.get("imp_band")
    open_ = band_all.open_
    active = on_enh._c.get("imp_active")
    assert 0.05 < 1 - open_.mean() < 0.5  # the fovea and its surround: no band
    assert len(active.index) < 0.95 * open_.sum()  # flat neighbourhoods
    assert len(active.index) > 0.3 * open_.sum()
    # the impulses left out have K == 0 without skipping too
    k_all = np.zeros(len(band_all.index))
    k_all[band_all.index] = off_enh._c.get("imp_amplitude")
    left_out = np.setdiff1d(np.arange(len(band_all.index)), active.index)
    assert (k_all[left_out] == 0).all()
    # exactly the rule, in NumPy over every impulse: the band open, and the constant radius
    # of the impulse's block below the reach of |L| at its own bracketing level
    from fovexp import amplitude, pyramids

    shape = on_enh._c.get("shape")
    top = max(min(amplitude.MAX_LAPLACIAN_LEVEL, pyramids.pyramid_depth(shape, 99)), 1)
    reach = np.asarray(pyramids.blocks_reaching(
        amplitude.laplacian_reach_px(np.arange(top + 1), top),
        pyramids.level_scale(pyramids.FLAT_BLOCK_LEVEL)))
    bx, by = on_enh._c.get("imp_blocks")
    k0, _ = amplitude.bracketing_levels(band_all.level, top)
    rule = open_ & (on_enh._c.get("luma_flat")[by, bx] < reach[k0])
    assert np.array_equal(active.index, np.flatnonzero(rule))
    need = on_enh._laplacian_need(on_enh._c.get("pyramid"), active)
    assert 0.1 < np.mean([m.mean() for m in need.values()]) < 0.9
    # the impulses flat as far as the largest sigma reaches: their band is never evaluated
    evaluated = on_enh._c.get("imp_bands").done
    assert 0.5 < evaluated.mean() < 0.99 and evaluated[active.index].all()


# ---------------------------------------------------------------- the arithmetic it relies on


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_a_constant_region_stays_its_constant_through_the_pyramid(dtype):
    img = textured_image(300, 400, rgb=False).astype(dtype)
    c = dtype(0.3137)
    img[:150, :200] = c  # level m is exactly c where G_0 is c within 2 (2^m - 1) px
    pyr = pyramids.gaussian_pyramid(img, 5)
    for m in range(1, 6):
        s = 1 << m
        inner = pyr[m][: (150 - 2 * s) // s, : (200 - 2 * s) // s]
        assert inner.size and (inner == c).all(), m
    lap = pyramids.smoothed_abs_laplacian(pyr, 4)
    for k in range(1, 5):
        s = 1 << (k - 1)
        reach = pyramids.abs_laplacian_reach_px(k)
        inner = lap[k][: (150 - reach) // s - 1, : (200 - reach) // s - 1]
        assert inner.size and (inner == 0).all(), k
        assert lap[k].max() > 1e-3  # and not elsewhere


def test_tiles_of_the_laplacian_are_the_same_whichever_tiles_run():
    pyr = pyramids.gaussian_pyramid(textured_image(200, 300, rgb=False), 3)
    full = pyramids.smoothed_abs_laplacian(pyr, 2)
    rng = np.random.default_rng(0)
    need = {k: rng.random(pyramids.tile_grid(pyr[k - 1].shape)) < 0.5 for k in (1, 2)}
    part = pyramids.smoothed_abs_laplacian(pyr, 2, need)
    for k in (1, 2):
        t = pyramids.ABS_LAPLACIAN_TILE
        mask = np.kron(need[k], np.ones((t, t), bool))[: full[k].shape[0], : full[k].shape[1]]
        assert np.array_equal(part[k][mask], full[k][mask])
        assert (part[k][~mask] == 0).all()


def test_the_contrast_change_is_exactly_zero_on_flat_boxes_and_the_sums_are_exact():
    grey = textured_image(200, 300, rgb=False)
    grey[:, :120] = 1e-5  # dark: 1e-5 is not a multiple of the fixed-point step
    sigma = np.full(grey.shape, 3.6, np.float32)
    change = contrast.contrast_change(grey, sigma, 0.3)
    reach = contrast.sat_pad_px(3.6)
    assert (change[:, : 120 - reach] == 0).all()
    assert np.abs(change[:, 130:]).max() > 1e-3
    # the table's sums are integers: a box from it is the box's own sum of fixed-point values
    pad = contrast.sat_pad_px(3.6)
    sat, _ = contrast._sat(grey, pad, 0, grey.shape[0] + 2 * pad, 0, grey.shape[1] + 2 * pad)
    q = np.rint(np.pad(grey.astype(np.float64), pad, mode="symmetric") * 2.0**36).astype(
        np.int64)
    ya, xa, n = 17, 33, 16
    box = sat[ya + n, xa + n] - sat[ya, xa + n] - sat[ya + n, xa] + sat[ya, xa]
    assert box == q[ya: ya + n, xa: xa + n].sum()


def test_the_summed_area_table_refuses_frames_it_cannot_sum_exactly():
    contrast.check_sat_fits((4320, 7680), 64, 1.0)  # 8K fits
    with pytest.raises(Exception, match="too large"):
        contrast.check_sat_fits((17280, 30720), 64, 1.0)  # 32K does not


def test_the_foveation_leaves_a_constant_region_exactly_as_it_is():
    img = textured_image(300, 400)
    img[:, :200] = (0.2, 0.5, 0.7)
    yy, xx = np.mgrid[0:300, 0:400]
    sigma = (np.hypot(xx - 200, yy - 150) / 20).astype(np.float32)
    plan = foveation.blur_stack_plan(float(sigma.max()))
    for skip in (False, True):
        out = foveation.foveate(img, sigma, skip=skip)
        inner = out[:, : 200 - plan.reach_px()]
        assert (inner == img[:, : 200 - plan.reach_px()]).all()
    assert np.array_equal(foveation.foveate(img, sigma, skip=True),
                          foveation.foveate(img, sigma, skip=False))


# ------------------------------------------------------------------------------ sequences


def test_a_sequence_recomputes_only_what_depends_on_the_image(tmp_path):
    """`fovexp enhance frames/ out/` sets each frame on one enhancer with the same gaze and
    parameters: the sigma map's blocks, the impulses and their band (none depends on the
    image) are computed for the first frame only (the geometry, by set_image, too)."""
    from fovexp import write_image

    for i in range(3):
        write_image(tmp_path / f"f{i}.png", textured_image(135, 240, seed=i))
    _, _, frames = iter_frames(tmp_path)
    enh = Enhancer(LG)
    p = EnhanceParams(blur_rate=0.34, impulses=12)
    ran, done = [], []
    for _, img, _ in frames:
        ran.append(set(enh.enhance((0.5, 0.5), p, image=img).timings_s))
        done.append(enh._c.get("sigma_blocks").done.copy())
    independent = {"sigma_blocks", "impulses", "imp_bands", "ppd_map"}
    assert independent <= ran[0]
    assert not {"grids", "sigma"} & ran[0]  # the whole map: only when asked for
    for stages, blocks in zip(ran[1:], done[1:], strict=True):
        assert not independent & stages
        assert np.array_equal(blocks, done[0])  # a textured frame: every block, once
        assert {"linear", "foveated", "luma", "imp_active", "noise", "output"} <= stages


def test_a_foveated_frame_evaluates_sigma_only_where_the_contrast_reads_it():
    """A foveated frame described by its blur-rate: with skipping, nothing but the contrast
    needs the sigma map, and it is evaluated on the blocks whose change is not 0 only, once
    per gaze across a sequence; the output is the one without skipping (the tests above)."""
    image = mixed_scene()
    enh = Enhancer(LG)
    p = EnhanceParams(blur_rate=0.57, impulses=12)
    enh.set_image(image, foveated=True)
    first = enh.enhance((0.5, 0.5), p)
    assert not {"grids", "sigma"} & set(first.timings_s)
    done = enh._c.get("sigma_blocks").done
    assert 0.2 < done.mean() < 0.9  # the flat grey region was left out
    enh.set_image(image.copy(), foveated=True)  # the next frame, the same gaze
    enh.enhance((0.5, 0.5), p)
    assert enh._c.get("sigma_blocks").done is done and "sigma_blocks" not in enh._c.timings_s
    # the full map, asked for, is the same on the blocks evaluated
    sigma_full = enh.enhance((0.5, 0.5), p).map("sigma_px")
    px = np.kron(done, np.ones((8, 8), bool))[: image.shape[0], : image.shape[1]]
    partial = enh._c.get("sigma_blocks").on(done, 3)
    assert np.array_equal(_bits(partial[px]), _bits(sigma_full[px]))


@pytest.mark.parametrize("set_kw", [{}, {"foveated": True}])
def test_skipping_reads_no_memory_a_stage_did_not_write(monkeypatch, set_kw):
    """The stages' arrays are not initialised (fovexp.memory.frame_empty): the blocks a
    skipping stage leaves out are written 0 by the stage itself, or never read (the sigma
    map evaluated block by block). With every such array handed out full of NaN, the output
    and the maps are still the ones without skipping, bit for bit: a read of memory no stage
    wrote would carry a NaN into them."""
    from fovexp import memory

    def poisoned(self, shape, dtype):
        out = np.empty(shape, dtype)
        out.fill(np.nan if np.dtype(dtype).kind == "f" else 0x5A)
        return out

    image = mixed_scene()
    image[:, 760:] = image[380:, :] = 0.5  # flat to the right edge, and whole strips of rows
    _, off = _both(image, (0.45, 0.55), set_kw)[1]
    expected = {name: off.map(name) for name in MAPS}
    monkeypatch.setattr(memory.FramePool, "empty", poisoned)
    monkeypatch.setattr(memory, "POOL_MIN_BYTES", 0)  # every array the stages take
    enh = Enhancer(LG, options=EngineOptions(skip=True))
    enh.set_image(image, **set_kw)
    on = enh.enhance((0.45, 0.55), EnhanceParams(blur_rate=0.57, impulses=24))
    assert np.isnan(enh._c.get("sigma_blocks").on(
        np.zeros_like(enh._c.get("sigma_blocks").done), 3)).any()  # the poison is there
    for name in MAPS:
        assert np.array_equal(_bits(on.map(name)), _bits(expected[name])), name
