"""Frame sequences: a folder of frames or a video, enhanced with the same impulses throughout.

The paper keeps the impulse positions fixed over a sequence (section 4.4) and measures temporal
coherence as the mean SSIM between consecutive frames (section 7.2); both are done here.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
from skimage.metrics import structural_similarity

from .errors import FovexpError
from .io import IMAGE_SUFFIXES, atomic_write_bytes, read_image

VIDEO_SUFFIXES = (".mp4", ".mov", ".avi", ".mkv", ".webm", ".gif")


def is_sequence(path: Path) -> bool:
    return path.is_dir() or path.suffix.lower() in VIDEO_SUFFIXES


def frame_paths(folder: Path) -> list[Path]:
    """The image files of a folder, sorted by name."""
    frames = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not frames:
        raise FovexpError(f"{folder}: no image frames ({', '.join(IMAGE_SUFFIXES)}) in folder")
    return frames


def iter_frames(source: Path) -> tuple[int, float | None, Iterator[tuple[str, np.ndarray]]]:
    """``(count, fps, frames)`` of a folder or a video; frames are (name, float image)."""
    if source.is_dir():
        paths = frame_paths(source)
        return len(paths), None, ((p.stem, read_image(p)) for p in paths)
    if not source.is_file():
        raise FovexpError(f"{source}: no such file or folder")
    import imageio.v3 as iio

    try:
        meta = iio.immeta(source, plugin="pyav") if _has_pyav() else iio.immeta(source)
        frames = iio.imread(source, index=None)
    except Exception as exc:
        raise FovexpError(f"{source}: cannot be read as a video ({type(exc).__name__})") from None
    fps = meta.get("fps")
    if frames.ndim == 3:  # a single grey frame or a grey sequence is ambiguous: take it as RGB-less
        frames = frames[..., None].repeat(3, axis=-1) if frames.shape[-1] != 3 else frames[None]
    scale = 255.0 if frames.dtype == np.uint8 else 65535.0

    def gen() -> Iterator[tuple[str, np.ndarray]]:
        for i, f in enumerate(frames):
            yield f"frame{i:05d}", np.asarray(f[..., :3], dtype=np.float32) / scale

    return int(frames.shape[0]), fps, gen()


def _has_pyav() -> bool:
    try:
        import av  # noqa: F401
    except ImportError:
        return False
    return True


def write_video(path: Path, frames: list[np.ndarray], fps: float | None) -> None:
    """Write 8-bit frames as a video, atomically."""
    import imageio.v3 as iio

    data = np.stack([np.round(np.clip(f, 0, 1) * 255).astype(np.uint8) for f in frames])
    atomic_write_bytes(path, lambda tmp: iio.imwrite(tmp, data, extension=path.suffix,
                                                     fps=fps or 30))


def mean_interframe_ssim(frames: list[np.ndarray]) -> float:
    """Mean SSIM between consecutive frames (paper section 7.2), on luma-like grey."""
    if len(frames) < 2:
        return float("nan")
    grey = [f.mean(axis=2) if f.ndim == 3 else f for f in frames]
    pairs = zip(grey[:-1], grey[1:], strict=True)
    return float(np.mean([structural_similarity(a, b, data_range=1.0) for a, b in pairs]))
