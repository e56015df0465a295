"""Image files in and out: PNG, TIFF and JPEG, 8- and 16-bit, as float arrays in [0, 1].

Writes are atomic (a temporary file in the destination folder, then a rename), so a failed or
interrupted run never leaves a partial output file behind.
"""

from __future__ import annotations

import os
import tempfile
import warnings
from pathlib import Path

import imageio.v3 as iio
import numpy as np

from .errors import FovexpError

IMAGE_SUFFIXES = {".png": "PNG", ".tif": "TIFF", ".tiff": "TIFF", ".jpg": "JPEG", ".jpeg": "JPEG"}


def read_image(path: str | Path) -> np.ndarray:
    """Read an image as float32 display-encoded values in [0, 1]: (H, W) or (H, W, 3).

    8-bit files are divided by 255, 16-bit by 65535; float TIFFs are taken as they are and
    checked. An alpha channel or any other channel count is an error.
    """
    path = Path(path)
    if path.suffix.lower() not in IMAGE_SUFFIXES:
        raise FovexpError(
            f"{path}: unsupported image type {path.suffix!r} (use {', '.join(IMAGE_SUFFIXES)})"
        )
    if not path.is_file():
        raise FovexpError(f"{path}: no such file")
    try:
        with warnings.catch_warnings():
            # a broken file makes imageio probe every plugin; the legacy ones warn of their own
            # deprecation, noise beside the one error below
            warnings.simplefilter("ignore", DeprecationWarning)
            raw = _read_png16(path) if _is_png16(path) else iio.imread(path)
    except Exception as exc:  # imageio raises many types for bad files
        raise FovexpError(f"{path}: cannot be read as an image ({type(exc).__name__})") from None
    if raw.ndim == 3 and raw.shape[2] == 1:
        raw = raw[..., 0]
    if raw.ndim not in (2, 3) or (raw.ndim == 3 and raw.shape[2] != 3):
        n = raw.shape[2] if raw.ndim == 3 else raw.ndim
        raise FovexpError(
            f"{path}: {n} channels; expected grey or RGB (remove any alpha channel first)"
        )
    if raw.dtype == np.uint8:
        img = raw.astype(np.float32) / 255.0
    elif raw.dtype == np.uint16:
        img = raw.astype(np.float32) / 65535.0
    elif np.issubdtype(raw.dtype, np.floating):
        img = raw.astype(np.float32)
    else:
        raise FovexpError(f"{path}: unsupported sample type {raw.dtype}")
    if not np.isfinite(img).all():
        raise FovexpError(f"{path}: contains NaN or Inf pixels")
    return img


def _is_png16(path: Path) -> bool:
    """PNG with 16-bit samples (IHDR bit depth, byte 24): Pillow would read it as 8-bit."""
    with open(path, "rb") as fh:
        head = fh.read(25)
    return head[:8] == b"\x89PNG\r\n\x1a\n" and len(head) == 25 and head[24] == 16


def _read_png16(path: Path) -> np.ndarray:
    import png

    width, height, rows, info = png.Reader(filename=str(path)).asDirect()
    data = np.vstack([np.asarray(r, dtype=np.uint16) for r in rows])
    return data.reshape(height, width, info["planes"]) if info["planes"] > 1 else data


def atomic_write_bytes(path: Path, write) -> None:
    """Call ``write(tmp_path)`` for a temporary file beside ``path`` and rename it into place."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    try:
        write(Path(tmp))
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_image(path: str | Path, image: np.ndarray, bit_depth: int = 8) -> None:
    """Write float values in [0, 1] as an 8- or 16-bit PNG/TIFF, or an 8-bit JPEG (quality 95)."""
    path = Path(path)
    kind = IMAGE_SUFFIXES.get(path.suffix.lower())
    if kind is None:
        raise FovexpError(
            f"{path}: unsupported output type {path.suffix!r} (use {', '.join(IMAGE_SUFFIXES)})"
        )
    if bit_depth not in (8, 16):
        raise FovexpError(f"bit depth must be 8 or 16, not {bit_depth}")
    if kind == "JPEG" and bit_depth != 8:
        raise FovexpError(f"{path}: JPEG is 8-bit only")
    v = np.clip(np.asarray(image, dtype=np.float64), 0.0, 1.0)
    top = 255 if bit_depth == 8 else 65535
    data = np.round(v * top).astype(np.uint8 if bit_depth == 8 else np.uint16)
    if kind == "PNG" and bit_depth == 16:
        # Pillow cannot write 16-bit colour PNGs; pypng can.
        import png

        planes = 1 if data.ndim == 2 else data.shape[2]
        rows = data.reshape(data.shape[0], -1)

        def write_png16(tmp: Path) -> None:
            with open(tmp, "wb") as fh:
                png.Writer(data.shape[1], data.shape[0], greyscale=planes == 1, bitdepth=16
                           ).write(fh, rows)

        atomic_write_bytes(path, write_png16)
        return
    extra = {"quality": 95} if kind == "JPEG" else {}
    atomic_write_bytes(path, lambda tmp: iio.imwrite(tmp, data, extension=path.suffix, **extra))


def save_npy(path: str | Path, array: np.ndarray) -> None:
    """Atomic ``np.save`` (float32)."""
    path = Path(path)
    atomic_write_bytes(path, lambda tmp: np.save(tmp, np.asarray(array, dtype=np.float32)))
