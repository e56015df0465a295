"""Stereoscopic content (paper section 6.4): the noise is synthesised once, for the left eye,
and warped to the right eye by the disparity, so that it appears to lie on the surfaces.

* Each eye is foveated and contrast-enhanced on its own image (its own content, the same
  gaze in normalised screen coordinates).
* The left eye is enhanced with ``ours``; its noise layer (``map("noise")``: linear luminance)
  is forward-warped to the right eye (:func:`forward_warp`), an image-based warp in the manner
  of Didyk et al. 2010 reduced to the horizontal disparity of a rectified pair: each row of
  left pixels is a 1-D mesh whose vertices move to x - d(x); a right pixel takes the value of
  the nearest left sample that lands on it (nearest, not interpolated: interpolation would
  low-pass the noise, which lives at up to 0.5 cycles/px), the nearer surface (larger d)
  winning where several land; a stretched cell between two neighbours whose disparities
  differ by at most :data:`SURFACE_STEP_PX` is filled, a larger step is a depth edge and left
  open.
* Right pixels no left pixel lands on are disocclusions: they get noise of the right eye's own
  parameters, synthesised by the enhancer on the right image cropped around them (with
  :data:`CONTEXT_PX` of context, as a viewport of the full frame, so eccentricity and blur are
  the full frame's). Only those crops are enhanced with noise: the right eye's noise is never
  synthesised where the warp provides it.
* The right eye's displayed frame is its contrast-enhanced image plus that noise
  (``EnhanceResult.with_noise``).

Disparity: d = x_left - x_right in pixels, given on the left image's grid (a left pixel at x
is seen at x - d by the right eye); for parallel cameras d >= 0 and nearer points have larger
d. A float32 ``.npy`` (H, W) in px, or a 16-bit grey PNG holding d x ``disparity_scale``
(default 256, 1/256 px steps up to 256 px: the KITTI benchmark's convention).

The seam: the warped noise and the right eye's own noise come from different impulses, so
the noise field is not continuous across a disocclusion's edge; both have the right eye's
local statistics (std K/6 with K estimated from the content on each side) and nothing is
blended. A disocclusion is where the right eye sees a surface the left eye does not, so there
is no left noise to continue. (Measured in ``tests/evaluation/test_stereo.py``: the noise's
std inside the disoccluded strip is within a factor of two of the std beside it.)

Anaglyph: red from the left eye's output, green and blue from the right's (grey inputs count
as R = G = B).

References
----------
.. [tariq] Tariq, T., Tursun, C., Didyk, P. (2022). Noise-based Enhancement for Foveated
   Rendering. ACM Transactions on Graphics 41(4) (SIGGRAPH 2022). doi:10.1145/3528223.3530101
.. [didyk] Didyk, P., Ritschel, T., Eisemann, E., Myszkowski, K., Seidel, H.-P. (2010).
   Adaptive Image-space Stereo View Synthesis. Vision, Modeling and Visualization (VMV 2010)
   (the paper's "Didyk2010"; no DOI given: not checked against the paper's bibliography)
.. [kitti] Geiger, A., Lenz, P., Urtasun, R. (2012). Are we ready for Autonomous Driving? The
   KITTI Vision Benchmark Suite. CVPR 2012. doi:10.1109/CVPR.2012.6248074
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numba
import numpy as np

from fovexp import FovexpError, read_image, read_samples, write_image

from .outputs import OutFolder, Setup, colour_of

#: The largest disparity step (px) between neighbouring left pixels still taken as one
#: surface (its stretched cell is filled); a larger step is a depth edge.
SURFACE_STEP_PX = 1.0
#: Context around a disocclusion, in px at 3840 px of width (scaled, at least 16): about three
#: Gabor kernel radii, so the crop's pyramids, contrast boxes and kernels see what the full
#: frame's would.
CONTEXT_PX = 64
#: A 16-bit PNG's value per pixel of disparity (KITTI's convention).
DISPARITY_PNG_SCALE = 256.0


# fastmath off, as every kernel of the package (fovexp/jit.py says why), named here since the
# evaluation uses only the enhancer's public API
@numba.njit(parallel=True, cache=True, nogil=True, fastmath=False)
def _warp_rows(src: np.ndarray, disp: np.ndarray, step: float, out: np.ndarray,
               depth: np.ndarray, covered: np.ndarray) -> None:
    h, w = src.shape
    for y in numba.prange(h):
        for x in range(w):
            d0 = disp[y, x]
            p0 = x - d0
            t = int(np.floor(p0 + 0.5))
            if 0 <= t < w and d0 > depth[y, t]:
                out[y, t] = src[y, x]
                depth[y, t] = d0
                covered[y, t] = True
            if x + 1 < w:
                d1 = disp[y, x + 1]
                if abs(d1 - d0) <= step:
                    p1 = x + 1 - d1
                    # the right pixels strictly inside the stretched cell (p0, p1)
                    ta = int(np.floor(p0 + 0.5)) + 1
                    tb = int(np.ceil(p1 - 0.5)) - 1
                    for t in range(max(ta, 0), min(tb, w - 1) + 1):
                        a = (t - p0) / (p1 - p0)
                        dt = d0 + a * (d1 - d0)
                        if dt > depth[y, t]:
                            out[y, t] = src[y, x] if a <= 0.5 else src[y, x + 1]
                            depth[y, t] = dt
                            covered[y, t] = True


def forward_warp(values: np.ndarray, disparity: np.ndarray,
                 surface_step_px: float = SURFACE_STEP_PX) -> tuple[np.ndarray, np.ndarray]:
    """Warp ``values`` (H, W) of the left eye to the right eye by ``disparity`` (left grid,
    d = x_left - x_right px): ``(warped, covered)``, ``covered`` False where no left pixel
    lands (disocclusions and the border the shift uncovers), ``warped`` 0 there. A constant
    integer disparity d gives ``warped[:, x] == values[:, x + d]`` exactly."""
    v = np.ascontiguousarray(values, dtype=np.float32)
    d = np.ascontiguousarray(disparity, dtype=np.float64)
    if v.shape != d.shape or v.ndim != 2:
        raise FovexpError(f"disparity has shape {d.shape}, the image {v.shape}")
    out = np.zeros(v.shape, np.float32)
    depth = np.full(v.shape, -np.inf)
    covered = np.zeros(v.shape, np.bool_)
    _warp_rows(v, d, float(surface_step_px), out, depth, covered)
    return out, covered


def read_disparity(path: Path, shape: tuple[int, int],
                   scale: float = DISPARITY_PNG_SCALE) -> np.ndarray:
    """The disparity map (px, float32, the left image's ``shape``): a ``.npy`` array or a
    16-bit grey PNG divided by ``scale``."""
    if not path.is_file():
        raise FovexpError(f"--disparity {path}: no such file")
    if path.suffix.lower() == ".npy":
        try:
            d = np.load(path, allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise FovexpError(f"--disparity {path}: cannot read it as .npy ({exc})") from None
        if d.dtype.kind not in "fiu":
            raise FovexpError(f"--disparity {path}: holds {d.dtype}, not numbers")
        d = d.astype(np.float32)
    else:
        raw = read_samples(path)
        if raw.dtype != np.uint16 or raw.ndim != 2:
            raise FovexpError(f"--disparity {path}: a PNG disparity must be 16-bit grey "
                              f"(d x {scale:g}); this one is {raw.dtype} {raw.shape}")
        if not scale > 0:
            raise FovexpError(f"--disparity-scale {scale}: must be above 0")
        d = (raw.astype(np.float64) / scale).astype(np.float32)
    if d.shape != shape:
        raise FovexpError(f"--disparity {path}: {d.shape[::-1] if d.ndim == 2 else d.shape} "
                          f"does not match the left image's {shape[1]}x{shape[0]} px")
    if not np.isfinite(d).all():
        raise FovexpError(f"--disparity {path}: holds NaN or Inf")
    if float(np.abs(d).max()) >= shape[1]:
        raise FovexpError(f"--disparity {path}: |d| reaches {float(np.abs(d).max()):g} px, the "
                          f"image is {shape[1]} px wide")
    return d


def anaglyph(left: np.ndarray, right: np.ndarray) -> np.ndarray:
    """Red-cyan anaglyph: red from ``left``, green and blue from ``right`` (H, W, 3)."""
    def rgb(img: np.ndarray) -> np.ndarray:
        c = colour_of(img)
        return np.repeat(c[..., None], 3, axis=2) if c.ndim == 2 else c

    lc, rc = rgb(left), rgb(right)
    return np.concatenate([lc[..., :1], rc[..., 1:3]], axis=2)


def context_px(width_px: int) -> int:
    return max(16, round(CONTEXT_PX * width_px / 3840))


def disocclusion_boxes(mask: np.ndarray, margin: int) -> list[tuple[int, int, int, int]]:
    """Boxes ``(y0, y1, x0, x1)`` around the disoccluded pixels with ``margin`` px of
    context, clipped to the frame; disocclusions closer than twice the margin share a box."""
    from scipy import ndimage

    if not mask.any():
        return []
    grown = ndimage.binary_dilation(mask, iterations=1, structure=np.ones((3, 3), bool))
    grown = ndimage.maximum_filter(grown, size=2 * margin + 1)
    labels, _ = ndimage.label(grown)
    h, w = mask.shape
    boxes = []
    for sl in ndimage.find_objects(labels):
        if sl is None:
            continue
        boxes.append((max(0, sl[0].start), min(h, sl[0].stop), max(0, sl[1].start),
                      min(w, sl[1].stop)))
    return boxes


@dataclass
class StereoResult:
    left: np.ndarray  # displayed left frame
    right: np.ndarray  # displayed right frame
    anaglyph: np.ndarray
    noise_left: np.ndarray  # float32, linear luminance
    noise_right: np.ndarray
    disoccluded: np.ndarray  # bool, right eye
    boxes: list[tuple[int, int, int, int]]

    @property
    def disoccluded_fraction(self) -> float:
        return float(self.disoccluded.mean())


def enhance_pair(left: np.ndarray, right: np.ndarray, disparity: np.ndarray, setup: Setup,
                 blur_rate: float) -> StereoResult:
    """Both eyes' displayed frames with the left eye's noise warped to the right (module
    docstring). ``left`` and ``right`` are display-encoded images of one size."""
    if left.shape != right.shape:
        raise FovexpError(f"the left image is {left.shape[1]}x{left.shape[0]} px, the right "
                          f"{right.shape[1]}x{right.shape[0]}: a stereo pair has one size")
    h, w = left.shape[:2]
    if disparity.shape != (h, w):
        raise FovexpError(f"disparity has shape {disparity.shape}, the images {(h, w)}")
    enh = setup.enhancer()
    enh.set_image(left)
    res_l = enh.enhance(setup.gaze, setup.params("ours", blur_rate))
    out_l = res_l.output
    noise_l = np.asarray(res_l.map("noise"), np.float32)
    warped, covered = forward_warp(noise_l, disparity)
    hole = ~covered
    noise_r = warped
    boxes = disocclusion_boxes(hole, context_px(w))
    if boxes:
        crop_enh = setup.enhancer()
        for y0, y1, x0, x1 in boxes:
            crop_enh.set_image(right[y0:y1, x0:x1], viewport=(x0, y0, w, h))
            own = crop_enh.enhance(setup.gaze, setup.params("ours", blur_rate)).map("noise")
            sel = hole[y0:y1, x0:x1]
            noise_r[y0:y1, x0:x1][sel] = np.asarray(own, np.float32)[sel]
    enh.set_image(right)
    res_r = enh.enhance(setup.gaze, setup.params("contrast", blur_rate))
    out_r = res_r.with_noise(noise_r)
    return StereoResult(out_l, out_r, anaglyph(out_l, out_r), noise_l, noise_r, hole, boxes)


def run(left_path: Path, right_path: Path, disparity_path: Path, setup: Setup,
        blur_rate: float, out: Path, disparity_scale: float = DISPARITY_PNG_SCALE,
        dump_maps: bool = False) -> StereoResult:
    """Read the pair and the disparity, :func:`enhance_pair`, write ``left.png``,
    ``right.png``, ``anaglyph.png`` (and with ``dump_maps`` ``noise-left.npy``,
    ``noise-right.npy`` and ``disocclusion.png``) into ``out``."""
    left, right = read_image(left_path), read_image(right_path)
    disparity = read_disparity(disparity_path, left.shape[:2], disparity_scale)
    res = enhance_pair(left, right, disparity, setup, blur_rate)
    folder = OutFolder(out)
    for name, img in (("left.png", res.left), ("right.png", res.right),
                      ("anaglyph.png", res.anaglyph)):
        write_image(out / name, img)
        folder.written.files.append(out / name)
    if dump_maps:
        folder.npy("noise-left.npy", res.noise_left)
        folder.npy("noise-right.npy", res.noise_right)
        write_image(out / "disocclusion.png", res.disoccluded.astype(np.float32))
    return res
