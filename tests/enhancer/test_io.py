"""``fovexp.io``: every layout (grey, grey + alpha, RGB, RGBA) at 8 and 16 bits through PNG and
TIFF, read back exactly and read the same by other readers (imageio/Pillow, pypng, tifffile);
writes atomic, with the umask's permissions; the API passes alpha through the enhancer."""

from __future__ import annotations

import os
import stat

import imagecodecs
import imageio.v3 as iio
import numpy as np
import png
import pytest
import tifffile

from fovexp import FovexpError, load_display, make_enhancer, make_params, read_image, write_image
from fovexp.io import read_image_with_depth

from engine_helpers import textured_image

LAYOUTS = {"grey": 1, "grey+alpha": 2, "RGB": 3, "RGBA": 4}


def _ints(channels: int, dtype, seed: int = 0) -> np.ndarray:
    shape = (23, 37) if channels == 1 else (23, 37, channels)
    top = np.iinfo(dtype).max
    a = np.random.default_rng(seed).integers(0, top + 1, size=shape).astype(dtype)
    a.flat[:2] = (0, top)  # both ends
    return a


def _pypng_read(path) -> np.ndarray:
    w, h, rows, info = png.Reader(filename=str(path)).asDirect()
    data = np.vstack([np.asarray(r, dtype=np.uint32) for r in rows])
    data = data.reshape(h, w, info["planes"]) if info["planes"] > 1 else data.reshape(h, w)
    return data.astype(np.uint8 if info["bitdepth"] == 8 else np.uint16)


@pytest.mark.parametrize("suffix", [".png", ".tif"])
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
@pytest.mark.parametrize("layout", list(LAYOUTS))
def test_every_layout_and_depth_round_trips_exactly_and_reads_the_same_elsewhere(
        tmp_path, suffix, dtype, layout):
    ints = _ints(LAYOUTS[layout], dtype)
    top = np.iinfo(dtype).max
    path = tmp_path / f"x{suffix}"
    write_image(path, ints / top, bit_depth=8 * np.dtype(dtype).itemsize)
    # another reader sees the samples written, in RGB(A) order
    other = _pypng_read(path) if suffix == ".png" else tifffile.imread(path)
    assert other.dtype == dtype and np.array_equal(other, ints)
    img, depth = read_image_with_depth(path)
    assert depth == 8 * np.dtype(dtype).itemsize and img.dtype == np.float32
    assert img.shape == ints.shape
    assert np.array_equal(np.round(img * top).astype(dtype), ints)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_the_codes_written_are_one_numpy_conversion_of_the_whole_frame(tmp_path, dtype):
    """The conversion to integer codes, done in parts on threads (a 4K frame is dozens of
    parts), writes what one NumPy float32 conversion of the whole frame gives: values
    clipped (below 0, above 1), halves rounded to even, float64 input rounded to float32."""
    rng = np.random.default_rng(5)
    top = np.iinfo(dtype).max
    values = rng.uniform(-0.1, 1.1, (2160, 3840, 3))
    values[0, :4, 0] = (np.arange(4) + 0.5) / top  # halves: 0.5, 1.5, 2.5, 3.5 codes
    want = np.rint(np.clip(values, 0, 1, dtype=np.float32) * np.float32(top)).astype(dtype)
    assert list(want[0, :4, 0]) == [0, 2, 2, 4] and want.min() == 0 and want.max() == top
    for a in (values, values.astype(np.float32)):
        path = tmp_path / "x.png"
        write_image(path, a, bit_depth=8 * np.dtype(dtype).itemsize)
        got = imagecodecs.png_decode(path.read_bytes())  # libpng
        assert got.dtype == dtype and np.array_equal(got, want)
        if dtype == np.uint8:  # Pillow too (it reads 16-bit RGB as 8-bit)
            assert np.array_equal(iio.imread(path), want)


@pytest.mark.parametrize("layout", list(LAYOUTS))
def test_files_of_other_writers_read_in_rgba_order(tmp_path, layout):
    ints = _ints(LAYOUTS[layout], np.uint8, seed=1)
    iio.imwrite(tmp_path / "pil.png", ints)  # Pillow
    assert np.array_equal(np.round(read_image(tmp_path / "pil.png") * 255), ints)
    u16 = _ints(LAYOUTS[layout], np.uint16, seed=2)
    with open(tmp_path / "pp.png", "wb") as fh:
        n = LAYOUTS[layout]
        png.Writer(37, 23, greyscale=n <= 2, alpha=n in (2, 4), bitdepth=16).write(
            fh, u16.reshape(23, -1).tolist())
    assert np.array_equal(np.round(read_image(tmp_path / "pp.png") * 65535), u16)


def test_jpeg_and_float_tiff(tmp_path):
    rgb = textured_image(40, 64)
    write_image(tmp_path / "a.jpg", rgb)
    back, depth = read_image_with_depth(tmp_path / "a.jpg")
    assert depth == 8 and back.shape == rgb.shape and np.abs(back - rgb).mean() < 0.01
    assert np.array_equal(back, iio.imread(tmp_path / "a.jpg") / np.float32(255))
    tifffile.imwrite(tmp_path / "f.tif", rgb, photometric="rgb")  # float32 samples
    back, depth = read_image_with_depth(tmp_path / "f.tif")
    assert depth == 16 and np.array_equal(back, rgb)


@pytest.mark.parametrize("make,message", [
    (lambda p: tifffile.imwrite(p, np.zeros((2, 20, 20), np.uint8)), "several pages"),
    (lambda p: tifffile.imwrite(p, np.zeros((20, 20, 6), np.uint8), photometric="minisblack",
                                planarconfig="contig"), "6 channels"),
    (lambda p: tifffile.imwrite(p, np.zeros((20, 20), np.int32)), "sample type int32"),
    (lambda p: p.write_bytes(b"II*\x00garbage"), "cannot be read"),
])
def test_unreadable_files_are_one_line(tmp_path, make, message):
    path = tmp_path / "bad.tif"
    make(path)
    with pytest.raises(FovexpError, match=message) as exc:
        read_image(path)
    assert "\n" not in str(exc.value)


def test_jpeg_refuses_what_it_cannot_hold(tmp_path):
    with pytest.raises(FovexpError, match="8-bit only"):
        write_image(tmp_path / "x.jpg", textured_image(20, 20), 16)
    with pytest.raises(FovexpError, match="no alpha"):
        write_image(tmp_path / "x.jpg", np.zeros((20, 20, 4), np.float32))
    with pytest.raises(FovexpError, match="shape"):
        write_image(tmp_path / "x.png", np.zeros((20, 20, 5), np.float32))
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("umask", [0o022, 0o007])
def test_a_new_file_has_the_umask_permissions_and_a_failed_write_leaves_nothing(tmp_path,
                                                                                 umask):
    old = os.umask(umask)
    try:
        write_image(tmp_path / "sub" / "x.png", textured_image(20, 20))
        write_image(tmp_path / "x.tif", textured_image(20, 20), 16)
    finally:
        os.umask(old)
    for f in (tmp_path / "sub" / "x.png", tmp_path / "x.tif"):
        assert stat.S_IMODE(f.stat().st_mode) == 0o666 & ~umask
    assert stat.S_IMODE((tmp_path / "sub").stat().st_mode) == 0o777 & ~umask
    # a write that fails half-way leaves the previous file and no temporary
    before = (tmp_path / "x.tif").read_bytes()
    with pytest.raises(TypeError):
        write_image(tmp_path / "x.tif", np.zeros((20, 20, 3), object))
    assert (tmp_path / "x.tif").read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sub", "x.tif"]


@pytest.mark.parametrize("channels", [2, 4])
def test_the_api_passes_alpha_through_the_enhancer(channels):
    """Enhancer.set_image takes grey + alpha and RGBA; EnhanceResult.output has the same
    channels, the alpha channel identical, the colour what the frame without alpha gives."""
    colour = textured_image(90, 160, rgb=channels == 4)
    alpha = np.linspace(0, 1, 90 * 160, dtype=np.float32).reshape(90, 160)
    enh = make_enhancer(load_display("lg-oled55cx"), backend="cpu")
    params = make_params(impulses=12, blur_rate=0.57)
    with_alpha = enh.enhance((0.4, 0.5), params, image=np.dstack([colour, alpha]))
    out = with_alpha.output
    assert out.shape == (90, 160, channels) and out.dtype == np.float32
    assert np.array_equal(out[..., -1], alpha)
    assert with_alpha.map("output").shape == colour.shape  # the maps are colour only
    plain = enh.enhance((0.4, 0.5), params, image=colour).output
    assert np.array_equal(out[..., :-1].reshape(plain.shape), plain)
    with pytest.raises(FovexpError, match="alpha channel values must lie in"):
        enh.set_image(np.dstack([colour, alpha * 2]))


def _png_bytes_with_threads(frame: np.ndarray, threads: int) -> bytes:
    import numba

    from fovexp.io import _png_encode

    before = numba.get_num_threads()
    numba.set_num_threads(threads)
    try:
        return _png_encode(frame)
    finally:
        numba.set_num_threads(before)


def test_png_output_is_one_stream_of_parts_the_same_bytes_on_any_thread_count(monkeypatch):
    """A frame of several deflated parts (4K RGB 8-bit: 25 MB filtered, about 6 parts) gives
    the same file with one thread and with two, which libpng and pypng read back sample for
    sample; where python-isal is absent, Python's zlib writes a file that reads back the same."""
    from fovexp.io import _PNG_PART_BYTES

    rng = np.random.default_rng(11)
    frame = rng.integers(0, 256, (2160, 3840, 3), dtype=np.uint8)
    frame[:, 1000:2000] = 7  # a flat band: parts that compress differently
    assert frame.nbytes // _PNG_PART_BYTES >= 4
    one, two = (_png_bytes_with_threads(frame, t) for t in (1, 2))
    assert one == two
    assert np.array_equal(imagecodecs.png_decode(one), frame)
    rows = png.Reader(bytes=one).asDirect()[2]
    pypng = np.vstack([np.frombuffer(r, np.uint8) for r in rows]).reshape(frame.shape)
    assert np.array_equal(pypng, frame)
    monkeypatch.setitem(__import__("sys").modules, "isal", None)  # an install without isal
    fallback = _png_bytes_with_threads(frame, 2)
    assert fallback != one and np.array_equal(imagecodecs.png_decode(fallback), frame)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_every_integer_code_reads_as_its_float32_quotient(tmp_path, dtype):
    """read_image's conversion (one pass, in parts on threads) gives ``float32(k) / top`` for
    every code k of the depth, the value a single NumPy division gives."""
    top = np.iinfo(dtype).max
    codes = np.arange(top + 1, dtype=dtype)
    ints = np.resize(codes, (max(1, codes.size // 256 * 3), 256))  # many parts at 16 bits
    path = tmp_path / "codes.png"
    path.write_bytes(imagecodecs.png_encode(ints))
    img, depth = read_image_with_depth(path)
    assert depth == 8 * np.dtype(dtype).itemsize and img.dtype == np.float32
    assert img.tobytes() == (ints.astype(np.float32) / np.float32(top)).tobytes()
    assert img.min() == 0.0 and img.max() == 1.0


def test_a_planar_float_tiff_reads_as_one_contiguous_image(tmp_path):
    """Float samples are returned as read (checked for NaN and Inf), channels last and
    C-contiguous even when the file stores them plane by plane."""
    planes = np.random.default_rng(2).random((3, 20, 30)).astype(np.float32)
    path = tmp_path / "planar.tif"
    tifffile.imwrite(path, planes, photometric="rgb", planarconfig="separate")
    img, depth = read_image_with_depth(path)
    assert depth == 16 and img.flags.c_contiguous
    assert np.array_equal(img, np.moveaxis(planes, 0, -1))
