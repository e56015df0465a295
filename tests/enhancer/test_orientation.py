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
