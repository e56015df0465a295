"""The paper's analyses of outputs run on the GPU backend too (Mesa llvmpipe in CI), through
the same public API: stereo (the noise map read back, warped, composed with
``EnhanceResult.with_noise``) and the spectra agree with the CPU backend's."""

from __future__ import annotations

import numpy as np

from fovexp.evaluation import spectra, stereo
from fovexp.evaluation.outputs import Setup

from evaluation_helpers import scene, small_display, write_scene


def test_stereo_and_spectra_on_the_gpu_backend(ctx, tmp_path):
    display = str(small_display(tmp_path))
    img = scene(3)
    disp = np.full(img.shape[:2], 5.0, np.float32)
    res = {b: stereo.enhance_pair(img, img, disp, Setup.make(display, backend=b, impulses=12,
                                                             gaze=(0.15, 0.5)), 0.57)
           for b in ("cpu", "gpu")}
    assert np.abs(res["gpu"].noise_left).max() > 0
    np.testing.assert_array_equal(res["gpu"].noise_right[:, :-6], res["gpu"].noise_left[:, 5:-1])
    for name in ("left", "right"):  # to float32 rounding, as the backends agree (docs/GPU.md)
        assert np.abs(getattr(res["gpu"], name) - getattr(res["cpu"], name)).max() <= 2 / 255
    path = write_scene(tmp_path / "s.png", 0)
    bands = {}
    for b in ("cpu", "gpu"):
        r = spectra.analyse([path], Setup.make(display, backend=b, impulses=12), [0.57],
                            spectra.default_rings((17.0,), 2.0))
        bands[b] = r.bands.set_index("method")["ratio_db"]
    np.testing.assert_allclose(bands["gpu"].to_numpy(), bands["cpu"].to_numpy(), atol=0.1)
