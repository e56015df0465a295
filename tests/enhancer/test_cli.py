"""``fovexp enhance``: a real run with every map dumped, sequences, and every error path
(one line, exit status 2, no output file left behind)."""

import imageio.v3 as iio
import numpy as np
import png
import pytest

from fovexp import MAP_NAMES, read_image
from fovexp.cli import main

from engine_helpers import textured_image


@pytest.fixture(scope="module")
def frame_png(tmp_path_factory):
    p = tmp_path_factory.mktemp("in") / "frame.png"
    iio.imwrite(p, (textured_image(270, 480) * 255).round().astype(np.uint8))
    return p


def run(capsys, *argv):
    try:
        rc = main([str(a) for a in argv])
    except SystemExit as exc:  # argparse
        rc = exc.code
    out, err = capsys.readouterr()
    return rc, out, err


def test_enhance_writes_output_and_every_map(frame_png, tmp_path, capsys):
    out = tmp_path / "out.png"
    rc, stdout, err = run(capsys, "enhance", frame_png, out, "--blur-rate", "0.57",
                          "--impulses", "12", "--dump-maps", tmp_path / "maps",
                          "--bit-depth", "16")
    assert rc == 0, err
    assert png.Reader(filename=str(out)).read()[3]["bitdepth"] == 16
    assert "f_e 0.28" in stdout  # Table 2 at 0.57
    for name in MAP_NAMES:
        m = np.load(tmp_path / "maps" / f"{name}.npy")
        assert m.dtype == np.float32 and m.shape[:2] == (270, 480), name
        assert (tmp_path / "maps" / f"{name}.png").is_file()
    out_map = np.load(tmp_path / "maps" / "output.npy")
    assert np.abs(read_image(out) - out_map).max() < 1 / 65535 + 1e-6


def test_sequence_folder_keeps_impulses_and_reports_ssim(tmp_path, capsys):
    frames = tmp_path / "frames"
    frames.mkdir()
    base = textured_image(270, 480, seed=2)
    for i in range(3):
        shifted = np.roll(base, i, axis=1)
        iio.imwrite(frames / f"f{i:02d}.png", (shifted * 255).round().astype(np.uint8))
    rc, stdout, err = run(capsys, "enhance", frames, tmp_path / "out", "--impulses", "12",
                          "--blur-rate", "0.57")
    assert rc == 0, err
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [
        "f00.png", "f01.png", "f02.png"]
    assert "mean inter-frame SSIM: input" in stdout


def _bad_inputs(tmp_path):
    corrupt = tmp_path / "corrupt.png"
    corrupt.write_bytes(b"\x89PNG not really")
    rgba = tmp_path / "rgba.png"
    iio.imwrite(rgba, np.zeros((40, 40, 4), np.uint8))
    nan = tmp_path / "nan.tif"
    a = textured_image(40, 40)
    a[3, 4, 1] = np.nan
    iio.imwrite(nan, a)
    bmp = tmp_path / "x.bmp"
    bmp.write_bytes(b"BM")
    display = tmp_path / "nodist.yaml"
    display.write_text("name: x\nwidth_px: 100\nheight_px: 100\nwidth_cm: 10\nheight_cm: 10\n"
                       "refresh_hz: 60\npeak_luminance_cd_m2: 100\ngamma: 2.2\n")
    table = tmp_path / "table.yaml"
    table.write_text("rows: [{blur_rate: 0.1, f_e: 0.2, s_k: -3, s_f: 2}]\n")
    sigma = tmp_path / "sigma.npy"
    np.save(sigma, np.zeros((10, 10), np.float32))
    return {"corrupt": corrupt, "rgba": rgba, "nan": nan, "bmp": bmp, "display": display,
            "table": table, "sigma": sigma}


CASES = [
    (["{missing}", "{out}"], "no such file"),
    (["{bmp}", "{out}"], "unsupported image type"),
    (["{corrupt}", "{out}"], "cannot be read"),
    (["{rgba}", "{out}"], "4 channels"),
    (["{nan}", "{out}"], "NaN"),
    (["{png}", "{outbmp}"], "unsupported output type"),
    (["{png}", "{out}", "--gaze", "1.5,0.5"], "outside the screen"),
    (["{png}", "{out}", "--gaze", "middle"], "gaze must be"),
    (["{png}", "{out}", "--blur-rate", "-1"], "blur_rate"),
    (["{png}", "{out}", "--impulses", "100000"], "impulses"),
    (["{png}", "{out}", "--sk", "nan"], "s_k"),
    (["{png}", "{out}", "--display", "{display}"], "distance_cm"),
    (["{png}", "{out}", "--display", "no-such-display"], "not found"),
    (["{png}", "{out}", "--table", "{table}"], "s_k"),
    (["{png}", "{out}", "--sigma-map", "{sigma}"], "sigma map has shape"),
    (["{png}", "{out}", "--method", "magic"], "invalid choice"),
]


@pytest.mark.parametrize("args,message", CASES, ids=[c[1] for c in CASES])
def test_every_error_is_one_line_exit_2_and_leaves_no_output(frame_png, tmp_path, capsys, args,
                                                             message):
    files = _bad_inputs(tmp_path)
    out = tmp_path / "result.png"
    fmt = dict(files, png=frame_png, out=out, outbmp=tmp_path / "result.bmp",
               missing=tmp_path / "missing.png")
    rc, _, err = run(capsys, "enhance", *[a.format(**fmt) for a in args])
    assert rc == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("fovexp: error:"), err
    assert message in lines[0]
    assert not out.exists() and not (tmp_path / "result.bmp").exists()
    assert not list(tmp_path.glob(".result*"))  # no temporary left either
