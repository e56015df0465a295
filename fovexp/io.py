"""Image files in and out: PNG, TIFF and JPEG, 8- and 16-bit, grey or colour, with or without
an alpha channel, as float32 arrays in [0, 1].

Channels (last axis): grey (H, W), grey + alpha (H, W, 2), RGB (H, W, 3), RGBA (H, W, 4).
The enhancer processes the colour; alpha passes through unchanged (docs/API.md).

Codecs: imagecodecs for reading PNG and JPEG and writing JPEG (libpng and libjpeg-turbo; 8-
and 16-bit, 1 to 4 channels); tifffile for TIFF (float samples too). Both are imported when
first used. PNG is written here (:func:`_png_encode`): the "up" filter on every row, deflated
in fixed parts on threads by ISA-L (python-isal, level :data:`PNG_ISAL_LEVEL`; Python's zlib
at :data:`PNG_ZLIB_LEVEL` where isal is not installed). A 4K frame takes about 0.1 s on two
cores with ISA-L, 0.35 s with zlib, where libpng at zlib's level takes 0.9 s on one
(docs/STATUS.md, "Decisions").
(Not OpenCV: PsychoPy depends on ``opencv-python``, and a second OpenCV wheel in the same
environment would share its ``cv2`` folder.)

Writes are atomic (a temporary file in the destination folder, then a rename), so a failed or
interrupted run never leaves a partial output file behind, and the file gets the permissions
the user's umask gives a new file (the temporary file is created as any new file is).
"""

from __future__ import annotations

import os
import secrets
import struct
import zlib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from .errors import FovexpError

IMAGE_SUFFIXES = {".png": "PNG", ".tif": "TIFF", ".tiff": "TIFF", ".jpg": "JPEG", ".jpeg": "JPEG"}
#: Integer sample depths files are written with.
BIT_DEPTHS = (8, 16)
#: ISA-L level of PNG output (1: ISA-L's fast matcher; the 4K Sponza output's file is 3 % larger
#: than zlib's level 1, and the whole PNG encode 3.4-3.9x faster).
PNG_ISAL_LEVEL = 1
#: zlib level of PNG output where isal is not installed (1: the fastest compression; a 4K frame's
#: file is about 10 % larger than at the default 6, which takes several times longer:
#: benchmarks/CLI.md).
PNG_ZLIB_LEVEL = 1
#: PNG colour type by channel count (PNG specification, 11.2.2: grey, grey + alpha, RGB, RGBA).
_PNG_COLOUR_TYPE = {1: 0, 2: 4, 3: 2, 4: 6}
#: Filtered bytes per deflated part of a PNG: fixed, so that the file's bytes do not depend on
#: the thread count.
_PNG_PART_BYTES = 1 << 22
#: JPEG quality of JPEG output.
JPEG_QUALITY = 95

_CHANNELS = {2: "grey + alpha", 3: "RGB", 4: "RGBA"}


def read_image(path: str | Path) -> np.ndarray:
    """Read an image as float32 values in [0, 1]: grey (H, W), grey + alpha (H, W, 2),
    RGB (H, W, 3) or RGBA (H, W, 4); colour display-encoded as stored, alpha as stored.

    8-bit files are divided by 255, 16-bit by 65535; float TIFFs are taken as they are.
    """
    return read_image_with_depth(path)[0]


def read_image_with_depth(path: str | Path) -> tuple[np.ndarray, int]:
    """:func:`read_image` and the file's sample depth: 8 or 16 (float TIFFs count as 16, the
    deepest integer depth they can be written back with)."""
    raw = read_samples(path)
    if raw.dtype == np.float32:  # a float TIFF: the only samples that can be NaN or Inf
        if not np.isfinite(raw).all():
            raise FovexpError(f"{path}: contains NaN or Inf pixels")
        return np.ascontiguousarray(raw), 16  # a planar TIFF's samples come as a view
    return _to_unit_float(raw), 8 if raw.dtype == np.uint8 else 16


def _to_unit_float(raw: np.ndarray) -> np.ndarray:
    """Integer samples as float32 in [0, 1]: each divided by the type's largest value in
    float32 (correctly rounded: exact codes ``k / top``), in one pass on threads
    (:func:`fovexp._parallel.in_parts`)."""
    from ._parallel import in_parts

    top = np.float32(np.iinfo(raw.dtype).max)

    def part(src: np.ndarray, dst: np.ndarray) -> None:
        np.divide(src, top, out=dst, dtype=np.float32)

    return in_parts(part, raw, np.empty(raw.shape, np.float32))


def read_samples(path: str | Path) -> np.ndarray:
    """An image file's samples as stored: uint8 or uint16 (float32 for a float TIFF), grey
    (H, W), grey + alpha (H, W, 2), RGB (H, W, 3) or RGBA (H, W, 4); PNGs of 1, 2 or 4 bits
    and palette PNGs come as 8-bit grey or RGB. Anything else is one clear error."""
    path = Path(path)
    kind = IMAGE_SUFFIXES.get(path.suffix.lower())
    if kind is None:
        raise FovexpError(
            f"{path}: unsupported image type {path.suffix!r} (use {', '.join(IMAGE_SUFFIXES)})"
        )
    if not path.is_file():
        raise FovexpError(f"{path}: no such file")
    try:
        raw = _read_tiff(path) if kind == "TIFF" else _decode(kind, path.read_bytes())
    except FovexpError:
        raise
    except Exception as exc:  # the decoders raise many types for bad files
        raise FovexpError(f"{path}: cannot be read as an image ({type(exc).__name__})") from None
    if raw.ndim == 3 and raw.shape[2] == 1:
        raw = raw[..., 0]
    if raw.ndim not in (2, 3):
        raise FovexpError(f"{path}: an array of shape {raw.shape} (several pages?); expected "
                          "one grey, grey + alpha, RGB or RGBA image")
    if raw.ndim == 3 and raw.shape[2] not in _CHANNELS:
        raise FovexpError(f"{path}: {raw.shape[2]} channels; expected grey, grey + alpha, RGB "
                          "or RGBA")
    if raw.dtype == np.float64:
        raw = raw.astype(np.float32)
    if raw.dtype not in (np.uint8, np.uint16, np.float32):
        raise FovexpError(f"{path}: unsupported sample type {raw.dtype}")
    return raw


def _decode(kind: str, data: bytes) -> np.ndarray:
    """A PNG or JPEG file's samples as stored (8/16-bit, 1-4 channels, RGB(A) order)."""
    import imagecodecs

    return imagecodecs.png_decode(data) if kind == "PNG" else imagecodecs.jpeg8_decode(data)


def _read_tiff(path: Path) -> np.ndarray:
    import tifffile

    with tifffile.TiffFile(path) as tif:
        series = tif.series[0]
        axes = series.axes
        if axes not in ("YX", "YXS", "SYX"):
            raise FovexpError(f"{path}: a TIFF of shape {series.shape} (axes {axes}: several "
                              "pages?); expected one grey, grey + alpha, RGB or RGBA image")
        raw = series.asarray()
    if axes == "SYX":  # planar samples: channels last
        raw = np.moveaxis(raw, 0, -1)
    return raw


def _temporary_beside(path: Path) -> Path:
    """A new empty file ``.STEM.RANDOM.SUFFIX`` beside ``path``, created as any new file is
    (mode 0o666, the umask applied by the system), unlike :func:`tempfile.mkstemp`'s 0o600."""
    for _ in range(100):
        tmp = path.with_name(f".{path.stem}.{secrets.token_hex(4)}{path.suffix}")
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
        except FileExistsError:
            continue
        os.close(fd)
        return tmp
    raise FovexpError(f"{path.parent}: cannot create a temporary file")  # pragma: no cover


def atomic_write_bytes(path: Path, write: Callable[[Path], object]) -> None:
    """Call ``write(tmp_path)`` for a temporary file beside ``path`` and rename it into place;
    the file keeps the permissions a new file gets (folders too: created as ``mkdir`` does)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = _temporary_beside(path)
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_bytes_atomic(path: str | Path, data: bytes, sync: bool = True) -> None:
    """Write ``data`` to ``path`` atomically (:func:`atomic_write_bytes`), fsync'ed before the
    rename when ``sync`` (files a session relies on: manifests, stimuli)."""

    def write(tmp: Path) -> None:
        with open(tmp, "wb") as fh:
            fh.write(data)
            if sync:
                fh.flush()
                os.fsync(fh.fileno())

    atomic_write_bytes(Path(path), write)


def write_image(path: str | Path, image: np.ndarray, bit_depth: int = 8) -> None:
    """Write float values in [0, 1] (grey, grey + alpha, RGB or RGBA; values outside are
    clipped) as an 8- or 16-bit PNG or TIFF, or an 8-bit JPEG (quality :data:`JPEG_QUALITY`,
    no alpha).

    >>> import os, tempfile
    >>> import numpy as np
    >>> from fovexp import read_image, write_image
    >>> path = os.path.join(tempfile.mkdtemp(), "ramp.png")
    >>> ramp = np.linspace(0, 1, 12, dtype=np.float32).reshape(3, 4)
    >>> write_image(path, ramp, 16)
    >>> back = read_image(path)
    >>> back.shape, back.dtype, float(np.abs(back - ramp).max()) <= 0.5 / 65535
    ((3, 4), dtype('float32'), True)
    """
    path = Path(path)
    kind = IMAGE_SUFFIXES.get(path.suffix.lower())
    if kind is None:
        raise FovexpError(
            f"{path}: unsupported output type {path.suffix!r} (use {', '.join(IMAGE_SUFFIXES)})"
        )
    if bit_depth not in BIT_DEPTHS:
        raise FovexpError(f"bit depth must be 8 or 16, not {bit_depth}")
    a = np.asarray(image)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[..., 0]
    if a.ndim not in (2, 3) or (a.ndim == 3 and a.shape[2] not in _CHANNELS):
        raise FovexpError(f"{path}: cannot write an image of shape {a.shape} "
                          "(grey, grey + alpha, RGB or RGBA)")
    channels = 1 if a.ndim == 2 else a.shape[2]
    if kind == "JPEG" and bit_depth != 8:
        raise FovexpError(f"{path}: JPEG is 8-bit only (write PNG or TIFF for 16 bits)")
    if kind == "JPEG" and channels in (2, 4):
        raise FovexpError(f"{path}: JPEG has no alpha channel (write PNG or TIFF)")
    dtype = np.uint8 if bit_depth == 8 else np.uint16
    data = _quantize(a, dtype)
    if kind == "TIFF":
        atomic_write_bytes(path, lambda tmp: _write_tiff(tmp, data))
    else:
        encoded = _encode(kind, data)
        atomic_write_bytes(path, lambda tmp: tmp.write_bytes(encoded))


def _quantize(a: np.ndarray, dtype: type) -> np.ndarray:
    """Values in [0, 1] (clipped) to the integer codes of ``dtype``: ``rint(v * top)`` in
    float32 steps as the enhancer computes (exact for ``k / top`` inputs), in parts on
    threads (:func:`fovexp._parallel.in_parts`)."""
    from ._parallel import in_parts

    top = np.float32(np.iinfo(dtype).max)

    def part(src: np.ndarray, dst: np.ndarray) -> None:
        scaled = np.clip(src, 0.0, 1.0, dtype=np.float32)
        scaled *= top
        np.rint(scaled, out=scaled)
        dst[...] = scaled

    return in_parts(part, a, np.empty(a.shape, dtype))


def _encode(kind: str, data: np.ndarray) -> bytes | bytearray:
    if kind == "PNG":
        return _png_encode(data)
    import imagecodecs

    return imagecodecs.jpeg8_encode(data, level=JPEG_QUALITY)


def _png_chunk(kind: bytes, body: bytes) -> bytes:
    """A PNG chunk: length, type, data, CRC-32 of type and data (PNG specification, 5.3)."""
    crc = zlib.crc32(body, zlib.crc32(kind))
    return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", crc)


def _deflater() -> tuple[Callable[[], Any], Callable[[Any], int]]:
    """A raw-deflate compressor factory and the Adler-32 function: ISA-L's where python-isal is
    installed (a dependency; it releases the GIL), Python's zlib otherwise."""
    try:
        from isal import isal_zlib
    except ImportError:  # a platform without its wheel
        return (lambda: zlib.compressobj(PNG_ZLIB_LEVEL, zlib.DEFLATED, -15)), zlib.adler32
    return (lambda: isal_zlib.compressobj(PNG_ISAL_LEVEL, isal_zlib.DEFLATED, -15),
            isal_zlib.adler32)


def _png_encode(data: np.ndarray) -> bytes:
    """A PNG file (ISO/IEC 15948) of 8- or 16-bit samples (H, W) or (H, W, 1-4 channels).

    Every row gets the "up" filter (the difference from the row above, byte by byte: PNG
    specification, 9.2), then the rows are deflated (:func:`_deflater`) in contiguous parts of
    about :data:`_PNG_PART_BYTES`, on threads. Every part but the last ends with a sync flush
    (an empty stored block: the stream continues byte-aligned), so the parts joined are one
    deflate stream; the zlib stream around it carries the Adler-32 of all the filtered bytes
    (RFC 1950, 1951). The parts depend on the image's size only: the same bytes with any
    number of threads."""
    from ._parallel import thread_map

    h, w = data.shape[:2]
    channels = 1 if data.ndim == 2 else data.shape[2]
    samples = data.astype(data.dtype.newbyteorder(">"), copy=False)  # PNG is big-endian
    rows = np.ascontiguousarray(samples).reshape(h, -1).view(np.uint8)
    filtered = np.empty((h, rows.shape[1] + 1), np.uint8)
    filtered[:, 0] = 2  # "up"; the row above the first is zero
    filtered[0, 1:] = rows[0]
    np.subtract(rows[1:], rows[:-1], out=filtered[1:, 1:])  # modulo 256
    parts = max(1, min(filtered.nbytes // _PNG_PART_BYTES, h))
    edges = [h * i // parts for i in range(parts + 1)]
    compressobj, adler32 = _deflater()

    def deflate(i: int) -> bytes:
        c = compressobj()  # raw deflate
        part = filtered[edges[i]:edges[i + 1]].data.cast("B")
        return c.compress(part) + c.flush(zlib.Z_FINISH if i == parts - 1 else zlib.Z_SYNC_FLUSH)

    deflated = thread_map(deflate, range(parts))
    adler = adler32(filtered.data.cast("B"))
    stream = b"".join([b"\x78\x01", *deflated, struct.pack(">I", adler)])  # zlib, fastest
    ihdr = struct.pack(">IIBBBBB", w, h, 8 * data.dtype.itemsize, _PNG_COLOUR_TYPE[channels],
                       0, 0, 0)  # deflate, adaptive filtering, no interlace
    idat = b"".join(_png_chunk(b"IDAT", stream[i:i + (1 << 30)])
                    for i in range(0, len(stream), 1 << 30))
    return (b"\x89PNG\r\n\x1a\n" + _png_chunk(b"IHDR", ihdr) + idat
            + _png_chunk(b"IEND", b""))


def _write_tiff(tmp: Path, data: np.ndarray) -> None:
    import tifffile

    channels = 1 if data.ndim == 2 else data.shape[2]
    tifffile.imwrite(
        tmp, data, photometric="minisblack" if channels <= 2 else "rgb",
        planarconfig="contig" if channels > 1 else None,
        extrasamples=["unassalpha"] if channels in (2, 4) else None,
    )


def save_npy(path: str | Path, array: np.ndarray) -> None:
    """Atomic ``np.save`` (float32)."""
    path = Path(path)
    atomic_write_bytes(path, lambda tmp: np.save(tmp, np.asarray(array, dtype=np.float32)))
