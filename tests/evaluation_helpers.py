"""Small inputs for the tests of ``fovexp.evaluation``: a display profile on which a 640 x 360
frame keeps the paper's display's pixels per degree in the periphery (36 deg wide at 71.5 cm:
about 18 px/deg, so the noise band T_L..Nyquist is open past about 14 deg), and generated
scenes at that size."""

from __future__ import annotations

from pathlib import Path

import numpy as np

SIZE = (640, 360)
SMALL_DISPLAY = """\
name: small-wide
width_px: 640
height_px: 360
width_cm: 46.46
height_cm: 26.13
distance_cm: 71.5
refresh_hz: 120
peak_luminance_cd_m2: 167.33
gamma: 2.2
"""


def small_display(folder: Path) -> Path:
    path = folder / "small-wide.yaml"
    path.write_text(SMALL_DISPLAY)
    return path


def scene(index: int, size: tuple[int, int] = SIZE) -> np.ndarray:
    from fovexp.stimuli.scenes import render_scene

    return render_scene(index, *size).astype(np.float32) / 255.0


def write_scene(path: Path, index: int, size: tuple[int, int] = SIZE) -> Path:
    from fovexp import write_image

    write_image(path, scene(index, size))
    return path
