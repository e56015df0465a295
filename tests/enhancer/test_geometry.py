"""Viewing geometry against the hand checks of docs/METHOD.md, section 4."""

import math

import numpy as np
import pytest

from fovexp import Display, FovexpError, load_display
from fovexp.acuity import t_high_cpd, t_low_cpd
from fovexp.foveation import sigma_px
from fovexp.geometry import ViewingGeometry, cpd_to_cpp, cpp_to_cpd

LG = load_display("lg-oled55cx")


def test_horizontal_field_is_80_8_deg():
    assert LG.horizontal_field_deg == pytest.approx(80.8, abs=0.05)


def test_on_axis_ppd_and_nyquist():
    g = ViewingGeometry.for_image(LG, 3840, 2160)
    ppd = float(g.ppd(np.array(1919.5), np.array(1079.5)))
    assert ppd == pytest.approx(39.3, abs=0.05)
    assert float(cpp_to_cpd(0.5, ppd)) == pytest.approx(19.7, abs=0.05)


def test_linear_approximation_is_width_over_field():
    g = ViewingGeometry.for_image(LG, 3840, 2160, "linear")
    assert g.ppd_constant == pytest.approx(3840 / 80.845, rel=1e-3)
    # eccentricity is on-screen distance over that constant
    e = g.eccentricity_deg(np.array([1919.5 + 475.0]), np.array([1079.5]), (1919.5, 1079.5))
    assert float(e[0]) == pytest.approx(475.0 / g.ppd_constant)


def test_ppd_grows_off_axis_on_a_flat_screen():
    g = ViewingGeometry.for_image(LG, 3840, 2160)
    x = np.array([1919.5, 2900.0, 3839.0])
    p = g.ppd(x, np.full(3, 1079.5))
    assert np.all(np.diff(p) > 0)


def test_blur_at_40_deg_is_10_9_arcmin_about_9_px():
    g = ViewingGeometry.for_image(LG, 3840, 2160)
    # find the horizontal pixel at 40 deg from a central gaze
    x = np.linspace(1920, 3839, 20000)
    e = g.eccentricity_deg(x, np.full_like(x, 1079.5), g.gaze_px((0.5, 0.5)))
    i = int(np.argmin(np.abs(e - 40.0)))
    assert 0.34 * (e[i] - 8.0) == pytest.approx(10.9, abs=0.05)
    s = float(sigma_px(e[i], g.ppd(x[i], 1079.5), 0.34, 8.0))
    assert s == pytest.approx(9.0, rel=0.1)


def test_exact_eccentricity_is_the_angle_between_rays():
    g = ViewingGeometry.for_image(LG, 3840, 2160)
    # corner pixel for a central gaze: atan(half diagonal / distance)
    e = float(g.eccentricity_deg(np.array(0.0), np.array(0.0), g.gaze_px((0.5, 0.5))))
    half_diag = math.hypot(60.9 - 121.8 / 3840 / 2, 34.25 - 68.5 / 2160 / 2)
    assert e == pytest.approx(math.degrees(math.atan(half_diag / 71.5)), abs=1e-6)
    # gaze off-centre: angle between the two rays, symmetric in its arguments
    gz = g.gaze_px((0.2, 0.7))
    e1 = g.eccentricity_deg(np.array(3000.0), np.array(400.0), gz)
    e2 = g.eccentricity_deg(np.array(gz[0]), np.array(gz[1]), (3000.0, 400.0))
    assert float(e1) == pytest.approx(float(e2))


def test_smaller_image_is_a_coarser_rendering_of_the_same_view():
    g4k = ViewingGeometry.for_image(LG, 3840, 2160)
    g = ViewingGeometry.for_image(LG, 960, 540)
    assert float(g.ppd(np.array(479.5), np.array(269.5))) == pytest.approx(
        float(g4k.ppd(np.array(1919.5), np.array(1079.5))) / 4, rel=1e-9)
    e = g.eccentricity_deg(np.array(0.0), np.array(0.0), g.gaze_px((0.5, 0.5)))
    e4 = g4k.eccentricity_deg(np.array(1.5), np.array(1.5), g4k.gaze_px((0.5, 0.5)))
    assert float(e) == pytest.approx(float(e4), abs=1e-6)


def test_release_geometry_gives_6_px_at_30_deg_for_blur_rate_0_46875():
    g = ViewingGeometry.for_image(LG, 3840, 2160, "release")
    assert g.ppd_constant == pytest.approx(42.6667, abs=1e-3)
    assert float(sigma_px(30.0, g.ppd_constant, 0.46875, 12.0)) == pytest.approx(6.0)


def test_unit_conversions_round_trip():
    assert float(cpd_to_cpp(cpp_to_cpd(0.2, 40.0), 40.0)) == pytest.approx(0.2)
    # 60 arcmin of blur (blur-rate 1, 60 deg past the fovea) at 40 px/deg is 40 px
    assert float(sigma_px(68.0, 40.0, 1.0, 8.0)) == pytest.approx(40.0)


def test_thibos_table_and_extension():
    assert float(t_low_cpd(30.0)) == 4.0 and float(t_high_cpd(30.0)) == 20.5
    assert float(t_low_cpd(12.5)) == pytest.approx((10.5 + 8.0) / 2)
    assert float(t_low_cpd(52.5)) == pytest.approx(2.5)  # release extension past 30 deg
    assert float(t_high_cpd(80.0)) == 20.5


@pytest.mark.parametrize("gaze", [(-0.1, 0.5), (0.5, 1.2), (float("nan"), 0.5)])
def test_gaze_outside_the_screen_is_refused(gaze):
    g = ViewingGeometry.for_image(LG, 3840, 2160)
    with pytest.raises(FovexpError, match="outside the screen"):
        g.gaze_px(gaze)


def test_display_profile_with_a_missing_field_names_it(tmp_path):
    p = tmp_path / "bad.yaml"
    p.write_text("name: bad\nwidth_px: 100\nheight_px: 100\nwidth_cm: 10\nheight_cm: 10\n"
                 "refresh_hz: 60\npeak_luminance_cd_m2: 100\ngamma: 2.2\n")
    with pytest.raises(FovexpError, match="distance_cm"):
        load_display(p)
    with pytest.raises(FovexpError, match="not found"):
        load_display("no-such-display")


def test_a_profile_with_pixels_far_from_square_is_refused(tmp_path):
    """A profile's size and resolution must give pixels square to within a factor 2 (the
    geometry takes one pitch per axis); the stress suite's 1 px, 0.001 x 1000 cm profile made
    a blur of 36 864 px and ran out of memory instead of saying so."""
    path = tmp_path / "typo.yaml"
    good = load_display("lg-oled55cx").model_dump()
    path.write_text("\n".join(f"{k}: {v}" for k, v in {**good, "height_cm": 0.68}.items()))
    with pytest.raises(FovexpError,
                       match=r"its pixels would be 101 times as wide as tall \(121.8 x 0.68"):
        load_display(path)
    path.write_text("\n".join(f"{k}: {v}" for k, v in {**good, "height_cm": 68.5}.items()))
    assert load_display(path).height_cm == 68.5


def _float32_steps(e32: np.ndarray, e64: np.ndarray) -> float:
    """The largest difference of a float32 map from the float64 one, in float32 steps of
    the float64 values (the smallest normal's step below it)."""
    step = np.spacing(np.maximum(np.abs(e64), np.finfo(np.float32).tiny).astype(np.float32))
    return float((np.abs(e32.astype(np.float64) - e64) / step).max())


def test_the_float32_eccentricity_is_within_5_steps_of_the_float64_angle():
    """The float32 map's angle (float32 square root, arctangent and degrees, for their
    divider's four values at a time) against the float64 one: within 5 float32 steps on
    the 4K profile for gazes over the whole screen and on profiles of other shapes and
    distances (the largest angles 18 to 128 deg); the largest difference measured is 4.5 steps,
    1.2e-5 deg. Near the gaze, where the angle tends to 0, the float32 step tends to 0 too:
    the bound holds there in steps as well."""
    rng = np.random.default_rng(29)
    cases = [(LG, 3840, 2160)] + [
        (Display(name=f"d{i}", width_px=1920, height_px=1080, width_cm=float(wcm),
                 height_cm=float(wcm * rng.uniform(0.3, 1.0)), distance_cm=float(dist),
                 refresh_hz=60, peak_luminance_cd_m2=100, gamma=2.2), 480, 270)
        for i, (wcm, dist) in enumerate([(20, 20), (300, 40), (120, 300), (60, 25), (150, 60)])]
    worst = 0.0
    for disp, w, h in cases:
        g = ViewingGeometry.for_image(disp, w, h)
        for gaze in [(0.5, 0.5), (0.0, 0.0), (1.0, 1.0), *map(tuple, rng.random((3, 2)))]:
            gp = g.gaze_px(gaze)
            e32, _ = g.eccentricity_and_ppd_maps(gp)
            e64, _ = g.eccentricity_and_ppd_maps(gp, np.float64)
            worst = max(worst, _float32_steps(e32, e64))
    assert 1.0 < worst <= 5.0  # float32 arithmetic, not float64 rounded once


@pytest.mark.parametrize("viewport", [None, (1000, 300, 3840, 2160)])
def test_the_maps_are_the_point_formulas_on_the_grid(viewport):
    """The eccentricity and ppd maps (one parallel pass over the grid) are eccentricity_deg
    and ppd of every pixel: bit for bit in float64, the ppd rounded once in float32, the
    float32 eccentricity (its last steps float32 arithmetic) within 5 float32 steps; and the
    point formulas broadcast their arguments as NumPy does."""
    w, h = (600, 400) if viewport else (960, 540)
    g = ViewingGeometry.for_image(LG, w, h, viewport=viewport)
    gaze = g.gaze_px((0.37, 0.61))
    x, y = g.grid()
    e64, p64 = g.eccentricity_deg(x, y, gaze), g.ppd(x, y)
    assert e64.shape == p64.shape == (h, w)
    ecc, ppd = g.eccentricity_and_ppd_maps(gaze, np.float64)
    assert ecc.dtype == ppd.dtype == np.float64
    assert np.array_equal(ecc, e64) and np.array_equal(ppd, p64)
    ecc, ppd = g.eccentricity_and_ppd_maps(gaze)
    assert ecc.dtype == ppd.dtype == np.float32 and np.array_equal(ppd, p64.astype(np.float32))
    assert _float32_steps(ecc, e64) <= 5.0
    row = g.eccentricity_deg(np.array([3.0, 70.0, 5.5]), np.array(2.0), gaze)
    assert row.shape == (3,) and np.array_equal(row, e64[2, [3, 70]].tolist() + [
        float(g.eccentricity_deg(np.array(5.5), np.array(2.0), gaze))])
    assert g.eccentricity_deg(np.array(3.0), np.array(2.0), gaze).shape == ()


@pytest.mark.parametrize("model", ["exact", "linear", "release"])
def test_the_largest_eccentricity_and_ppd_are_at_a_corner(model):
    """What bounds the sigma map without evaluating it (the skipping's contrast stage): the
    largest eccentricity and ppd of an image, for gazes inside and outside it."""
    rng = np.random.default_rng(11)
    for _ in range(12):
        w, h = int(rng.integers(40, 400)), int(rng.integers(40, 300))
        x0, y0 = int(rng.integers(0, 3840 - w)), int(rng.integers(0, 2160 - h))
        g = ViewingGeometry.for_image(LG, w, h, model, (x0, y0, 3840, 2160))
        gaze = g.gaze_px(tuple(rng.random(2)))
        x, y = g.grid()
        ecc = g.eccentricity_deg(x, y, gaze)
        ppd = np.broadcast_to(g.ppd(x, y), ecc.shape)
        e_max, p_max = g.max_eccentricity_and_ppd(gaze)
        assert e_max == ecc.max() and p_max == ppd.max()


def _rays(display, viewport, width, height, x, y, gaze_norm):
    """The exact model written out with vectors: the eye at the origin, the screen the plane
    z = D, a frame pixel's centre at ((X + 0.5 - SW / 2) pitch_x, (Y + 0.5 - SH / 2) pitch_y, D)
    with X, Y its frame coordinates; the angle between the rays to the pixel and to the gaze
    point, and (pi / 180) |ray| / pitch (pitch: the geometric mean of the two axes')."""
    x0, y0, sw, sh = viewport
    px, py = display.width_cm / sw, display.height_cm / sh
    d = display.distance_cm
    u = np.stack([(x + x0 + 0.5 - sw / 2) * px, (y + y0 + 0.5 - sh / 2) * py,
                  np.full(np.shape(x), d)], axis=-1)
    gx, gy = gaze_norm[0] * sw, gaze_norm[1] * sh  # frame position of the gaze (px edges)
    v = np.array([(gx - sw / 2) * px, (gy - sh / 2) * py, d])
    cos = (u @ v) / (np.linalg.norm(u, axis=-1) * np.linalg.norm(v))
    ecc = np.degrees(np.arccos(np.clip(cos, -1, 1)))
    ppd = np.pi / 180 * np.linalg.norm(u, axis=-1) / math.sqrt(px * py)
    return ecc, ppd


@pytest.mark.parametrize("viewport,size", [(None, (96, 54)), ((700, 250, 1920, 1080), (300, 200))])
def test_the_exact_model_is_the_angle_between_rays_written_out(viewport, size):
    """Eccentricity and ppd of every pixel, for gazes anywhere (the maps and the points),
    against the geometry written out with vectors; a display whose pixels are not square."""
    from fovexp import Display

    disp = Display(name="wide-pixels", width_px=1920, height_px=1080, width_cm=110.0,
                   height_cm=50.0, distance_cm=65.0, refresh_hz=60, peak_luminance_cd_m2=100,
                   gamma=2.2)
    w, h = size
    vp = viewport or (0, 0, w, h)
    g = ViewingGeometry.for_image(disp, w, h, viewport=viewport)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    for gaze in ((0.5, 0.5), (0.1, 0.9), (1.0, 0.0)):
        ecc, ppd = _rays(disp, vp, w, h, xx, yy, gaze)
        gp = g.gaze_px(gaze)
        assert gp == pytest.approx((gaze[0] * vp[2] - 0.5 - vp[0], gaze[1] * vp[3] - 0.5 - vp[1]))
        assert np.allclose(g.eccentricity_deg(xx, yy, gp), ecc, atol=1e-7)
        assert np.allclose(g.ppd(xx, yy), ppd, rtol=1e-12)
        e32, p32 = g.eccentricity_and_ppd_maps(gp)
        assert e32.dtype == np.float32 and np.allclose(e32, ecc, atol=2e-5)
        assert np.allclose(p32, ppd, rtol=1e-6)
        e64, _ = g.eccentricity_and_ppd_maps(gp, np.float64)
        assert np.allclose(e64, ecc, atol=1e-7)
        emax, pmax = g.max_eccentricity_and_ppd(gp)
        assert emax == pytest.approx(ecc.max(), abs=1e-7) and pmax == pytest.approx(ppd.max())
    assert g.shape == (h, w)


def test_the_linear_and_release_models_written_out():
    """linear: on-screen distance (px) over the constant width / field; release: atan(R / D)
    with R the on-screen distance (cm) on the release's 120 x 67 cm screen at 60 cm, and its
    constant 3840 / 90 px/deg scaled to the frame width."""
    lin = ViewingGeometry.for_image(LG, 400, 300, "linear", viewport=(100, 50, 1920, 1080))
    assert lin.ppd_constant == pytest.approx(1920 / LG.horizontal_field_deg)
    x, y = np.array([0.0, 399.0, 17.0]), np.array([0.0, 299.0, 200.0])
    gaze = lin.gaze_px((0.3, 0.6))
    assert np.allclose(lin.eccentricity_deg(x, y, gaze),
                       np.hypot(x - gaze[0], y - gaze[1]) / lin.ppd_constant)
    assert np.array_equal(lin.ppd(x, y), np.full(3, lin.ppd_constant))
    e, p = lin.eccentricity_and_ppd_maps(gaze)
    assert e.shape == (300, 400) and e[200, 17] == pytest.approx(
        np.hypot(17 - gaze[0], 200 - gaze[1]) / lin.ppd_constant, rel=1e-6)
    assert (p == np.float32(lin.ppd_constant)).all()
    rel = ViewingGeometry.for_image(LG, 1920, 1080, "release")
    assert rel.ppd_constant == pytest.approx(3840 / 90 * 1920 / 3840)
    gaze = rel.gaze_px((0.5, 0.5))
    r_cm = np.hypot((x - gaze[0]) * 120 / 1920, (y - gaze[1]) * 67 / 1080)
    assert np.allclose(rel.eccentricity_deg(x, y, gaze), np.degrees(np.arctan(r_cm / 60.0)))
    with pytest.raises(FovexpError, match="does not fit at"):
        ViewingGeometry.for_image(LG, 400, 300, viewport=(1600, 0, 1920, 1080))
    with pytest.raises(FovexpError, match="does not fit at"):
        ViewingGeometry.for_image(LG, 400, 300, viewport=(-1, 0, 1920, 1080))
    ViewingGeometry.for_image(LG, 400, 300, viewport=(1520, 780, 1920, 1080))  # just fits


def test_the_display_schema_bounds_and_the_release_display():
    """The profile's ranges at their edges (docs/DISPLAYS: 1 px to 32768 px, up to 10 m,
    luminance above 0 up to 100000 cd/m2) and the release's display (docs/METHOD.md, 5);
    geometries are values (frozen)."""
    import dataclasses

    from fovexp import Display
    from fovexp.geometry import RELEASE_DISPLAY

    ok = dict(name="x", width_px=32768, height_px=18432, width_cm=1000.0, height_cm=562.5,
              distance_cm=0.5, refresh_hz=60, peak_luminance_cd_m2=0.5, gamma=2.2)
    Display(**ok)
    Display(**dict(ok, distance_cm=1000.0, peak_luminance_cd_m2=100000.0))
    for field, bad in (("width_px", 32769), ("width_cm", 1000.5), ("distance_cm", 1000.5),
                       ("distance_cm", 0.0), ("peak_luminance_cd_m2", 0.0),
                       ("peak_luminance_cd_m2", 100001.0)):
        with pytest.raises(ValueError):
            Display(**dict(ok, **{field: bad}))
    assert (RELEASE_DISPLAY.width_px, RELEASE_DISPLAY.height_px) == (3840, 2160)
    assert (RELEASE_DISPLAY.width_cm, RELEASE_DISPLAY.height_cm,
            RELEASE_DISPLAY.distance_cm) == (120.0, 67.0, 60.0)
    assert (RELEASE_DISPLAY.refresh_hz, RELEASE_DISPLAY.peak_luminance_cd_m2,
            RELEASE_DISPLAY.gamma) == (60.0, 100.0, 2.2)
    g = ViewingGeometry.for_image(LG, 64, 48)
    with pytest.raises(dataclasses.FrozenInstanceError):
        g.distance_cm = 10.0  # type: ignore[misc]


def test_a_viewport_fits_at_the_frames_edges_and_not_past_them():
    for vp in ((0, 0, 1920, 1080), (1520, 0, 1920, 1080), (0, 780, 1920, 1080)):
        assert ViewingGeometry.for_image(LG, 400, 300, viewport=vp).x0_px == vp[0]
    for vp in ((1521, 0, 1920, 1080), (0, 781, 1920, 1080), (0, -1, 1920, 1080)):
        with pytest.raises(FovexpError, match="does not fit"):
            ViewingGeometry.for_image(LG, 400, 300, viewport=vp)


def test_a_geometry_made_directly_is_the_image_full_screen_by_default():
    """ViewingGeometry's defaults (no screen size, no origin) are the image full screen, the
    frame for_image makes without a viewport: the same geometry, the same gaze and
    eccentricities; a screen size and origin given are kept."""
    w, h = 640, 360
    full = ViewingGeometry.for_image(LG, w, h)
    direct = ViewingGeometry(w, h, LG.width_cm / w, LG.height_cm / h, LG.distance_cm, "exact",
                             w / LG.horizontal_field_deg)
    assert direct == full
    assert (direct.screen_width_px, direct.screen_height_px, direct.x0_px, direct.y0_px) == (
        w, h, 0, 0)
    assert direct.gaze_px((0.5, 0.5)) == ((w - 1) / 2, (h - 1) / 2)
    x, y = np.array([0.0, 319.5, 639.0]), np.array([0.0, 179.5, 359.0])
    gaze = direct.gaze_px((0.25, 0.75))
    assert np.array_equal(direct.eccentricity_deg(x, y, gaze), full.eccentricity_deg(x, y, gaze))
    part = ViewingGeometry(w, h, 0.03, 0.03, 80.0, screen_width_px=1920, screen_height_px=1080,
                           x0_px=100, y0_px=50)
    assert (part.screen_width_px, part.screen_height_px, part.x0_px, part.y0_px) == (
        1920, 1080, 100, 50)
