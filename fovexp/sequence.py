"""Frame sequences: a folder of frames or a video, enhanced with the same impulses throughout.

The paper keeps the impulse positions fixed over a sequence (section 4.4) and measures temporal
coherence as the mean SSIM between consecutive frames (section 6.2); both are done here. Frames
are streamed: one input and one output frame are held at a time, whatever the length. Frames of
a folder keep their alpha channel and bit depth; videos are 8-bit colour.

References
----------
.. [tariq] Tariq, T., Tursun, C., Didyk, P. (2022). Noise-based Enhancement for Foveated
   Rendering. ACM Transactions on Graphics 41(4) (SIGGRAPH 2022). doi:10.1145/3528223.3530101
.. [ssim] Wang, Z., Bovik, A. C., Sheikh, H. R., Simoncelli, E. P. (2004). Image Quality
   Assessment: From Error Visibility to Structural Similarity. IEEE Transactions on Image
   Processing 13(4), 600-612. doi:10.1109/TIP.2003.819861
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from .errors import FovexpError
from .io import IMAGE_SUFFIXES, read_image_with_depth

VIDEO_SUFFIXES = (".mp4", ".mov", ".avi", ".mkv", ".webm", ".gif")


def is_sequence(path: Path) -> bool:
    return path.is_dir() or path.suffix.lower() in VIDEO_SUFFIXES


def frame_paths(folder: Path) -> list[Path]:
    """The image files of a folder, sorted by name."""
    frames = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not frames:
        raise FovexpError(f"{folder}: no image frames ({', '.join(IMAGE_SUFFIXES)}) in folder")
    return frames


def iter_frames(
    source: Path,
) -> tuple[int | None, float | None, Iterator[tuple[str, np.ndarray, int]]]:
    """``(count or None, fps or None, frames)`` of a folder or a video; frames are
    ``(name, float image in [0, 1], bit depth of the file)``."""
    if source.is_dir():
        paths = frame_paths(source)
        return len(paths), None, ((p.stem, *read_image_with_depth(p)) for p in paths)
    if not source.is_file():
        raise FovexpError(f"{source}: no such file or folder")
    import imageio.v3 as iio

    try:
        meta = iio.immeta(source)
    except Exception as exc:
        raise FovexpError(f"{source}: cannot be read as a video ({type(exc).__name__})") from None
    fps = meta.get("fps")
    n = meta.get("nframes")
    count = int(n) if isinstance(n, (int, float)) and np.isfinite(n) else None

    def gen() -> Iterator[tuple[str, np.ndarray, int]]:
        try:
            for i, f in enumerate(iio.imiter(source)):
                f = np.asarray(f)
                depth = 8 if f.dtype == np.uint8 else 16
                rgb = f[..., :3] if f.ndim == 3 else np.repeat(f[..., None], 3, axis=2)
                yield f"frame{i:05d}", rgb.astype(np.float32) / (2.0**depth - 1.0), depth
        except FovexpError:
            raise
        except Exception as exc:
            raise FovexpError(f"{source}: video frame cannot be decoded ({exc})") from None

    return count, fps, gen()


class VideoWriter:
    """Write 8-bit frames to a temporary file beside ``path``; :meth:`close` renames it into
    place, :meth:`abort` removes it, so a failed run leaves no partial video."""

    def __init__(self, path: Path, fps: float | None) -> None:
        self.path = path
        self.tmp = path.with_name(f".{path.stem}.partial{path.suffix}")
        path.parent.mkdir(parents=True, exist_ok=True)
        kw = {"fps": fps or 30.0}
        if path.suffix.lower() != ".gif":
            kw["macro_block_size"] = 1  # keep the frame size exactly
        self._writer = None
        self._kw = kw

    def append(self, frame: np.ndarray) -> None:
        """Add a frame (grey or colour; an alpha channel is dropped: videos have none)."""
        import imageio.v2 as iio2

        colour = _colour(frame)
        data = np.round(np.clip(colour, 0, 1) * 255).astype(np.uint8)
        if self._writer is None:
            self._writer = iio2.get_writer(self.tmp, **self._kw)
        self._writer.append_data(data)

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()
            self.tmp.replace(self.path)

    def abort(self) -> None:
        if self._writer is not None:
            self._writer.close()
        self.tmp.unlink(missing_ok=True)


def _colour(frame: np.ndarray) -> np.ndarray:
    """A frame without its alpha channel, if it has one."""
    from .pipeline import split_alpha

    return split_alpha(frame)[0]


#: SSIM's constants and window (Wang et al. 2004; scikit-image's defaults, which
#: ``fovexp enhance`` has always reported): K1, K2 and a 7 x 7 uniform window with the sample
#: covariance (N / (N - 1)).
SSIM_K1, SSIM_K2, SSIM_WINDOW_PX = 0.01, 0.03, 7


def ssim(a: np.ndarray, b: np.ndarray, data_range: float = 1.0) -> float:
    """Mean structural similarity of two grey images of the same shape (paper section 6.2,
    the measure of Kaplanyan et al. 2019's temporal procedure; Wang et al. 2004's SSIM index
    with a 7 x 7 uniform window).

    The same number as scikit-image's ``structural_similarity(a, b, data_range=...)`` with
    its defaults (within 1e-6 on float images, tested), computed in float64 and over the
    interior only: skimage averages the map without the 3 px border its window reflects into,
    so that border is never filtered here (measured on a 4K pair, 2-core VM, same load: 1.3x to
    1.5x faster than scikit-image; benchmarks/EVALUATION.md).

    >>> import numpy as np
    >>> x = np.random.default_rng(0).random((64, 64))
    >>> round(ssim(x, x), 6)
    1.0
    >>> bool(ssim(x, 1 - x) < 0)  # the structure inverted
    True
    """
    from scipy.ndimage import uniform_filter1d

    x = np.asarray(a, dtype=np.float64)
    y = np.asarray(b, dtype=np.float64)
    if x.shape != y.shape or x.ndim != 2:
        raise FovexpError(f"ssim needs two grey images of one shape, got {x.shape} and {y.shape}")
    win = SSIM_WINDOW_PX
    if min(x.shape) < win:
        raise FovexpError(f"ssim needs images of at least {win} x {win} px, got {x.shape}")

    def box(img: np.ndarray) -> np.ndarray:
        # the window's mean at every interior pixel ('valid' part of the uniform filter)
        h = win // 2
        rows = uniform_filter1d(img, win, axis=0)[h:-h]
        return uniform_filter1d(rows, win, axis=1)[:, h:-h]

    ux, uy = box(x), box(y)
    n = win * win
    cov = n / (n - 1.0)
    vx = cov * (box(x * x) - ux * ux)
    vy = cov * (box(y * y) - uy * uy)
    vxy = cov * (box(x * y) - ux * uy)
    c1 = (SSIM_K1 * data_range) ** 2
    c2 = (SSIM_K2 * data_range) ** 2
    num = (2.0 * ux * uy + c1) * (2.0 * vxy + c2)
    den = (ux * ux + uy * uy + c1) * (vx + vy + c2)
    return float(np.mean(num / den))


class InterframeSSIM:
    """Running mean SSIM (:func:`ssim`) between consecutive frames (paper section 6.2), on
    grey (the mean of the colour channels)."""

    def __init__(self) -> None:
        self._prev: np.ndarray | None = None
        self._sum = 0.0
        self._n = 0

    def add(self, frame: np.ndarray) -> None:
        colour = _colour(frame)
        grey = colour.mean(axis=2) if colour.ndim == 3 else colour
        if self._prev is not None:
            self._sum += ssim(self._prev, grey)
            self._n += 1
        self._prev = grey

    @property
    def mean(self) -> float:
        return self._sum / self._n if self._n else float("nan")

    @property
    def count(self) -> int:
        """How many consecutive pairs the mean is over."""
        return self._n
