"""Noise orientation (paper section 4.3; docs/METHOD.md, 5.5): on a straight edge the Gabor
noise's stripes run along the edge, measured on the noise itself."""

import math

import numpy as np
import pytest

from fovexp import EnhanceParams, Enhancer, load_display
from fovexp import orientation as orient

LG = load_display("lg-oled55cx")
H, W = 540, 960
#: A point of the edge, right of the gaze (about 25 deg eccentricity: the band is open there).
X0, Y0 = int(0.78 * W), H // 2
HALF = 32  # the measured window is 64 x 64 px around (X0, Y0)


def edge_image(angle_deg: float) -> np.ndarray:
    """Grey step (0.3 | 0.7) along a line through (X0, Y0) at ``angle_deg`` from the x axis
    (x right, y down)."""
    a = math.radians(angle_deg)
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float64)
    side = -(xx - X0) * math.sin(a) + (yy - Y0) * math.cos(a)
    return np.repeat((0.3 + 0.4 * (side > 0))[..., None], 3, axis=2).astype(np.float32)


def stripe_angle_deg(noise: np.ndarray) -> tuple[float, float]:
    """Direction of the stripes of ``noise`` around (X0, Y0), in [0, 180) deg, and the
    coherence of that direction (0..1): from the second moments of the windowed 2-D power
    spectrum (the spectrum's main axis is across the stripes). Measured on the spectrum
    rather than with finite differences, whose response is not isotropic near Nyquist."""
    patch = noise[Y0 - HALF: Y0 + HALF, X0 - HALF: X0 + HALF].astype(np.float64)
    win = np.outer(np.hanning(2 * HALF), np.hanning(2 * HALF))
    power = np.abs(np.fft.fft2((patch - patch.mean()) * win)) ** 2
    f = np.fft.fftfreq(2 * HALF)
    fx, fy = f[None, :], f[:, None]
    sxx, syy, sxy = (power * fx * fx).sum(), (power * fy * fy).sum(), (power * fx * fy).sum()
    across = 0.5 * math.atan2(2 * sxy, sxx - syy)
    coherence = math.hypot(sxx - syy, 2 * sxy) / (sxx + syy)
    return math.degrees(across + math.pi / 2) % 180.0, coherence


def angle_error_deg(a: float, b: float) -> float:
    """Difference of two undirected angles (deg), in [0, 90]."""
    d = abs(a - b) % 180.0
    return min(d, 180.0 - d)


def _noise(angle_deg: float) -> np.ndarray:
    enh = Enhancer(LG)
    enh.set_image(edge_image(angle_deg))
    res = enh.enhance((0.5, 0.5), EnhanceParams(blur_rate=0.57, impulses=64))
    noise = res.map("noise")
    assert noise[Y0 - HALF: Y0 + HALF, X0 - HALF: X0 + HALF].std() > 1e-3  # noise is there
    return noise


@pytest.mark.parametrize("angle_deg", [30.0, 120.0])
def test_noise_stripes_run_along_a_straight_edge(angle_deg):
    stripes, coherence = stripe_angle_deg(_noise(angle_deg))
    assert coherence > 0.9  # one clear direction
    assert angle_error_deg(stripes, angle_deg) < 3.0, stripes


def test_the_measurement_sees_a_rotated_orientation(monkeypatch):
    """The same measurement with omega rotated by 90 deg: stripes across the edge. (So the
    test above is decided by the orientation, not by the strip of noise along the edge.)"""
    rotated = orient.orientation_at

    def across(*args, **kwargs):
        return rotated(*args, **kwargs) + np.float32(0.5 * np.pi)

    monkeypatch.setattr(orient, "orientation_at", across)
    stripes, _ = stripe_angle_deg(_noise(30.0))
    assert angle_error_deg(stripes, 30.0 + 90.0) < 3.0, stripes


def test_orientation_is_the_edge_direction():
    """omega = atan2(G_y, G_x) - pi/2: perpendicular to the gradient, along the edge."""
    img = edge_image(30.0)[..., 0]
    from fovexp.pyramids import gaussian_pyramid

    level = gaussian_pyramid(img, orient.ORIENTATION_LEVEL)[orient.ORIENTATION_LEVEL]
    gx, gy = orient.sobel_gradients(level)
    omega = orient.orientation_at(gx, gy, np.array([float(X0)]), np.array([float(Y0)]))
    assert angle_error_deg(math.degrees(float(omega[0])) % 180.0, 30.0) < 2.0


def test_sobel_gradients_by_hand_with_replicated_borders():
    """G_x = [1 0 -1]-differences along x smoothed [1 2 1] along y, scaled as SciPy's Sobel
    (x right, y down, positive where the image grows), the border replicated; float32 kept
    as float32 and float64 as float64."""
    rng = np.random.default_rng(3)
    g = rng.random((6, 7))
    p = np.pad(g, 1, mode="edge")
    dx = p[:, 2:] - p[:, :-2]  # rows padded, columns interior
    gx = dx[:-2] + 2 * dx[1:-1] + dx[2:]
    dy = p[2:, :] - p[:-2, :]
    gy = dy[:, :-2] + 2 * dy[:, 1:-1] + dy[:, 2:]
    got_x, got_y = orient.sobel_gradients(g)
    assert got_x.dtype == np.float64 and np.allclose(got_x, gx) and np.allclose(got_y, gy)
    got_x32, _ = orient.sobel_gradients(g.astype(np.float32))
    assert got_x32.dtype == np.float32 and np.allclose(got_x32, gx, atol=1e-5)
    assert orient.sobel_gradients(g.astype(np.float16))[0].dtype == np.float32


def test_sobel_gradients_are_scipys_bit_for_bit():
    """The compiled Sobel pass gives ``scipy.ndimage.sobel(mode="nearest")``'s bytes along
    both axes (its rounding: the difference stored in the output's type, then the
    smoothing): float32 and float64, a 4K frame's level-3 grid, one row, one column, one
    pixel, values spanning many octaves, -0.0, NaN and infinities."""
    from scipy import ndimage

    rng = np.random.default_rng(1)
    nonfinite = rng.random((40, 40)).astype(np.float32)
    nonfinite[3, 4], nonfinite[10, 10], nonfinite[20, 0] = np.nan, np.inf, -np.inf
    levels = [
        rng.random((270, 480)).astype(np.float32), rng.random((1, 5)).astype(np.float32),
        rng.random((7, 1)), rng.random((1, 1)).astype(np.float32), rng.random((2, 2)),
        (rng.random((50, 60)) ** 8).astype(np.float32),
        np.where(rng.random((40, 40)) < 0.5, -0.0, 1e-30).astype(np.float32),
        (rng.standard_normal((33, 17)) * 1e20).astype(np.float32), rng.random((64, 63)),
        nonfinite,
    ]
    for g in levels:
        with np.errstate(invalid="ignore"):
            gx, gy = orient.sobel_gradients(g)
            want_x = ndimage.sobel(g, axis=1, mode="nearest")
            want_y = ndimage.sobel(g, axis=0, mode="nearest")
        assert gx.dtype == g.dtype and gx.tobytes() == want_x.tobytes(), g.shape
        assert gy.dtype == g.dtype and gy.tobytes() == want_y.tobytes(), g.shape
    with pytest.raises(ValueError, match="2-D level"):
        orient.sobel_gradients(np.zeros((2, 2, 2)))


def test_orientation_at_is_atan2_less_a_quarter_turn_and_defined_where_flat():
    """omega = atan2(G_y, G_x) - pi/2 where |G| >= GRADIENT_EPS, and -pi/2 where it is below
    (a flat area), on constant gradient grids (their bicubic samples are the constant)."""
    shape = (12, 12)
    x = np.array([40.0, 41.5])
    y = np.array([37.0, 44.25])
    for gx, gy in ((1.0, 0.0), (0.0, 1.0), (-1.0, 1.0), (0.3, -0.4)):
        om = orient.orientation_at(np.full(shape, gx), np.full(shape, gy), x, y)
        assert om.dtype == np.float32
        assert om == pytest.approx(math.atan2(gy, gx) - math.pi / 2, abs=1e-6)
    eps = orient.GRADIENT_EPS
    assert eps == 1e-5
    just = orient.orientation_at(np.full(shape, eps), np.zeros(shape), x, y, dtype=np.float64)
    below = orient.orientation_at(np.zeros(shape), np.full(shape, 0.9 * eps), x, y)
    assert just.dtype == np.float64 and just == pytest.approx(-math.pi / 2)  # atan2(0, eps)
    assert below == pytest.approx(-math.pi / 2)  # flat: not atan2(0.9 eps, 0) = 0
    # the level: the same grid read at level 2 samples other points of a ramp
    ramp = np.tile(np.arange(12.0), (12, 1))
    at3 = orient.orientation_at(ramp, ramp.T, np.array([20.0]), np.array([60.0]))
    at2 = orient.orientation_at(ramp, ramp.T, np.array([20.0]), np.array([60.0]), level=2)
    assert abs(float(at3[0]) - float(at2[0])) > 0.1


def test_the_orientation_threshold_and_level():
    """|G| exactly GRADIENT_EPS is a direction (only below it is flat), read at a node of the
    level grid (where the bicubic sample is the node's value exactly); the gradients are
    taken on level 3, 1/8 of the resolution (docs/METHOD.md, 5.5)."""
    assert orient.ORIENTATION_LEVEL == 3
    eps = orient.GRADIENT_EPS
    shape = (12, 12)
    node = np.array([40.0]), np.array([48.0])  # level-3 node (5, 6)
    at = orient.orientation_at(np.zeros(shape), np.full(shape, eps), *node, dtype=np.float64)
    assert at[0] == pytest.approx(0.0, abs=1e-12)  # atan2(eps, 0) - pi/2
    below = orient.orientation_at(np.zeros(shape), np.full(shape, np.nextafter(eps, 0)), *node,
                                  dtype=np.float64)
    assert below[0] == pytest.approx(-math.pi / 2)
