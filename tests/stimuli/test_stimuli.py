"""Stimuli at the display's own resolution (issue 9, section 1): the generated scenes are
deterministic to the byte and carry pixel-level detail at 4K; the stimulus folder is found in a
stated order; a real session refuses another size before any window, a dry run scales and
records it; ``fovexp stimuli generate / add / check`` round trips, from any folder."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from fovexp import FovexpError
from fovexp.experiment.options import SessionOptions
from fovexp.experiment.protocol.spec import load_protocol
from fovexp.experiment.session import Session
from fovexp.stimuli import scenes
from fovexp.stimuli.folder import (
    DRY_RUN_SIZE,
    ENV_VAR,
    GENERATED,
    StimulusSet,
    find_folder,
    generate_scenes,
    load_scene_pins,
    load_stimulus,
    read_samples,
    size_text,
)

from experiment_helpers import (  # noqa: F401
    REPO,
    cli,
    make_workspace,
    pattern,
    run_cli,
    write_png,
    xvfb_display,
)

PINS = load_scene_pins()


def tiny_display(folder: Path, w: int = 64, h: int = 36) -> Path:
    """A display profile of ``w`` x ``h`` pixels (the paper's otherwise): small test frames."""
    data = yaml.safe_load((REPO / "protocols" / "displays" / "lg-oled55cx.yaml").read_text())
    data.update(name=f"tiny-{w}x{h}", width_px=w, height_px=h)
    path = folder / f"tiny-{w}x{h}.yaml"
    folder.mkdir(parents=True, exist_ok=True)
    path.write_text(yaml.safe_dump(data))
    return path


def protocol_with(folder: Path, images: list[str], **changes) -> Path:
    """A copy of calibration-fe naming ``images`` (and other ``changes``)."""
    data = yaml.safe_load((REPO / "protocols" / "calibration-fe.yaml").read_text())
    data.update(images=images, **changes)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "proto.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


# -- the generated scenes ------------------------------------------------------------------------
def test_dry_run_scenes_are_byte_deterministic_and_pinned(dry_run_scenes: Path) -> None:
    """Rendered twice, the same bytes; those bytes and pixels are the pinned ones; and the
    session's generated folder holds exactly them."""
    res = size_text(DRY_RUN_SIZE)
    for spec in scenes.SCENES:
        a = scenes.render_scene(spec.index, *DRY_RUN_SIZE)
        b = scenes.render_scene(spec.index, *DRY_RUN_SIZE)
        data = scenes.png_bytes(a)
        assert data == scenes.png_bytes(b)
        pin = PINS[spec.id].sha256[res]
        assert hashlib.sha256(data).hexdigest() == pin.file, spec.id
        assert scenes.pixels_sha256(a) == pin.pixels
        written = dry_run_scenes / GENERATED / res / f"{spec.id}.png"
        assert written.read_bytes() == data
        assert np.array_equal(read_samples(written), a)  # the PNG is lossless


@pytest.fixture(scope="module")
def scenes_4k() -> dict[int, np.ndarray]:
    # a day scene (bricks) and a night one (cobblestones: the slowest to draw)
    return {i: scenes.render_scene(i, 3840, 2160) for i in (0, 1)}


@pytest.mark.slow
def test_every_4k_scene_matches_its_pin() -> None:
    for spec in scenes.SCENES:
        img = scenes.render_scene(spec.index, 3840, 2160)
        pin = PINS[spec.id].sha256["3840x2160"]
        assert scenes.pixels_sha256(img) == pin.pixels, spec.id
        assert hashlib.sha256(scenes.png_bytes(img)).hexdigest() == pin.file, spec.id


def _luma(img: np.ndarray) -> np.ndarray:
    a = img.astype(np.int64)
    return (2 * a[..., 0] + 5 * a[..., 1] + a[..., 2]) / 8.0


def detail(img: np.ndarray) -> dict[str, float]:
    """Measures of fine structure: the fraction of 4x4 blocks that are not one colour (a
    960x540 frame stretched 4x has none), of pixels that are 1 px lines or dots (an extremum
    48 levels above or below both neighbours across it), of the (non-DC) power in the top
    octave (0.25 ... 0.5 cycles/px), and of perfectly flat 8x8 blocks."""
    y = _luma(img)
    h, w = (s // 8 * 8 for s in y.shape)
    y = y[:h, :w]
    b4 = y.reshape(h // 4, 4, w // 4, 4)
    b8 = y.reshape(h // 8, 8, w // 8, 8)
    c, left, right = y[1:-1, 1:-1], y[1:-1, :-2], y[1:-1, 2:]
    up, down = y[:-2, 1:-1], y[2:, 1:-1]

    def peak(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return ((c - a >= 48) & (c - b >= 48)) | ((a - c >= 48) & (b - c >= 48))

    p = np.abs(np.fft.rfft2(y - y.mean())) ** 2
    fy = np.abs(np.fft.fftfreq(h))[:, None]
    fx = np.fft.rfftfreq(w)[None, :]
    return {
        "varied_4x4": float((b4.max(axis=(1, 3)) != b4.min(axis=(1, 3))).mean()),
        "thin": float((peak(left, right) | peak(up, down)).mean()),
        "top_octave": float(p[np.maximum(fy, fx) > 0.25].sum() / p.sum()),
        "flat_8x8": float((b8.max(axis=(1, 3)) == b8.min(axis=(1, 3))).mean()),
    }


@pytest.mark.slow
def test_4k_scenes_have_pixel_level_detail(scenes_4k: dict[int, np.ndarray]) -> None:
    """At 4K the scenes hold structure down to one pixel (1 px wires, text strokes, stars,
    pickets, grain), and flat regions too; the same scene drawn at 960x540 and upscaled 4x
    (nearest: the old stretched stimuli; bicubic: smooth) has none of that fine structure."""
    from PIL import Image

    for i, img in scenes_4k.items():
        small = scenes.render_scene(i, 960, 540)
        near = np.asarray(Image.fromarray(small).resize((3840, 2160), Image.Resampling.NEAREST))
        smooth = np.asarray(Image.fromarray(small).resize((3840, 2160),
                                                          Image.Resampling.BICUBIC))
        m, mn, ms = detail(img), detail(near), detail(smooth)
        assert m["varied_4x4"] > 0.4 and mn["varied_4x4"] == 0.0
        assert m["thin"] > 3e-4 and mn["thin"] == 0.0 and ms["thin"] == 0.0
        assert m["top_octave"] > 3 * ms["top_octave"] and m["top_octave"] > 0.01
        assert m["flat_8x8"] > 0.15  # sky, walls, sign panels


def test_dark_and_bright_scenes() -> None:
    """Paper section 5.1: dark and bright scenes; in both sets (calibration, validation)."""
    means = {s.index: _luma(scenes.render_scene(s.index, 480, 270)).mean() for s in scenes.SCENES}
    dark = {i for i, s in enumerate(scenes.SCENES) if s.dark}
    assert dark & set(range(5)) and dark & set(range(5, 15))
    assert all(means[i] < 60 for i in dark)
    assert all(means[i] > 90 for i in means if i not in dark)


# -- the stimulus folder --------------------------------------------------------------------------
def test_folder_lookup_order(tmp_path: Path, monkeypatch) -> None:
    """--stimuli, then the protocol's key, then $FOVEXP_STIMULI, then ./stimuli, then the
    per-user data folder."""
    monkeypatch.delenv(ENV_VAR, raising=False)
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "xdg"))
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    assert find_folder()[::2] == (tmp_path / "xdg" / "fovexp" / "stimuli", "the user data folder")
    (work / "stimuli").mkdir()
    assert find_folder()[::2] == (work / "stimuli", "./stimuli")
    monkeypatch.setenv(ENV_VAR, str(tmp_path / "env"))
    assert find_folder()[::2] == (tmp_path / "env", f"${ENV_VAR}")
    folder, manifest, how = find_folder(protocol_key="../lab/manifest.yaml",
                                        protocol_dir=tmp_path / "protocols")
    assert (folder, manifest) == (tmp_path / "lab", tmp_path / "lab" / "manifest.yaml")
    assert find_folder(tmp_path / "cli", "../lab", tmp_path / "p")[0] == tmp_path / "cli"


def test_lab_ids_may_not_shadow_generated_scenes(tmp_path: Path) -> None:
    (tmp_path / "manifest.yaml").write_text(yaml.safe_dump({"images": [
        {"id": "scene-03", "path": "x.png", "source": "s", "licence": "l", "sha256": "0" * 64}]}))
    with pytest.raises(FovexpError, match="'scene-03' is a generated scene's"):
        StimulusSet(tmp_path)


# -- what a session may show ----------------------------------------------------------------------
def test_real_session_refuses_another_size(tmp_path: Path, dry_run_scenes: Path) -> None:
    """A 480x270 frame on the 3840x2160 display: refused with the image, its size and the
    display's, before any window (no display needed, no results folder left); the same
    protocol runs as a dry run, scaled."""
    lab = tmp_path / "lab"
    frame = write_png(lab / "frames" / "mine.png", pattern(270, 480, 1))
    (lab / "manifest.yaml").write_text(yaml.safe_dump({"images": [
        {"id": "mine", "path": "frames/mine.png", "source": "test", "licence": "CC0-1.0",
         "sha256": hashlib.sha256(frame.read_bytes()).hexdigest()}]}))
    proto = protocol_with(tmp_path / "p", ["mine"],
                          display=str(REPO / "protocols/displays/lg-oled55cx.yaml"),
                          stimuli=str(lab))
    lp = load_protocol(proto)
    with pytest.raises(FovexpError) as err:
        lp.prepare_images(lp.native_size, dry_run=False)
    msg = str(err.value)
    assert "image 'mine'" in msg and "is 480x270" in msg and "the display shows 3840x2160" in msg
    assert "\n" not in msg
    # a Session refuses it too (the library path), before it creates anything
    opts = SessionOptions(participant="R01", results_root=tmp_path / "results", tracker="mouse")
    with pytest.raises(FovexpError, match="is 480x270; the display shows 3840x2160"):
        Session(lp, opts)
    assert not (tmp_path / "results").exists()
    # and the operator sees one line from fovexp run, with no window and no display
    r = run_cli(["run", str(proto), "--participant", "R01", "--tracker", "mouse",
                 "--results", str(tmp_path / "results")], cwd=tmp_path,
                env_update={"DISPLAY": None})
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "is 480x270; the display shows 3840x2160" in lines[0]
    assert not (tmp_path / "results").exists()
    # a dry run may scale it: checked, and marked as scaled
    images = lp.prepare_images(DRY_RUN_SIZE, dry_run=True)
    assert not images["mine"].scaled
    images = lp.prepare_images((320, 180), dry_run=True)
    assert images["mine"].scaled and images["mine"].size == (480, 270)
    rec = lp.stimuli_record()
    assert rec["scaled"] == ["mine"] and rec["images"]["mine"]["scaled_to"] == [320, 180]
    # load_stimulus never rescales unless told to (dry runs)
    with pytest.raises(FovexpError, match="never rescales"):
        load_stimulus(frame, (320, 180))
    assert load_stimulus(frame, (320, 180), scale=True).shape == (180, 320, 3)


def test_missing_scenes_name_the_command(tmp_path: Path) -> None:
    """No 4K scenes: the error names the exact command that writes them where the runner
    looks; a dry run without any asks for the dry-run resolution."""
    empty = tmp_path / "empty"
    lp = load_protocol(REPO / "protocols" / "validation.yaml", stimuli=empty)
    with pytest.raises(FovexpError) as err:
        lp.prepare_images(lp.native_size, dry_run=False)
    assert f"fovexp stimuli generate --size 3840x2160 --stimuli {empty}" in str(err.value)
    assert "9 more image(s)" in str(err.value)
    with pytest.raises(FovexpError, match=rf"generate --size 480x270 --stimuli {empty}"):
        lp.prepare_images((800, 450), dry_run=True)


def test_dry_run_picks_the_nearest_generated_resolution(tmp_path: Path,
                                                        dry_run_scenes: Path) -> None:
    """A dry run takes the window's own resolution when there is one, else the smallest
    larger one, else the largest; sizes fovexp does not pin are recorded by the folder."""
    stim = StimulusSet(tmp_path / "s")
    done = generate_scenes(stim, (64, 36), ["scene-00"])
    assert done.recorded and done.written == ["scene-00"]
    assert "scene-00" in yaml.safe_load(stim.manifest_path.read_text())["generated"]["64x36"]
    generate_scenes(stim, DRY_RUN_SIZE, ["scene-00"])
    stim = StimulusSet(tmp_path / "s")  # read back from disk
    pick = {w: stim.check("scene-00", (w, w * 9 // 16), dry_run=True) for w in (32, 64, 320,
                                                                                960)}
    assert pick[64].status == "ok" and pick[64].size == (64, 36)
    assert pick[32].scaled and pick[32].size == (64, 36)
    assert pick[320].scaled and pick[320].size == (480, 270)
    assert pick[960].scaled and pick[960].size == (480, 270)
    # a real session at 64x36 uses the recorded file; after an edit it is refused
    assert stim.check("scene-00", (64, 36), dry_run=False).status == "ok"
    path = stim.scene_path("scene-00", (64, 36))
    px = read_samples(path).copy()
    px[0, 0] ^= 1
    write_png(path, px)
    bad = stim.check("scene-00", (64, 36), dry_run=False)
    assert bad.status == "changed" and "--force" in bad.fix
    assert generate_scenes(stim, (64, 36), ["scene-00"]).written == ["scene-00"]
    assert stim.check("scene-00", (64, 36), dry_run=False).status == "ok"


def test_pixels_decide_when_another_zlib_wrote_the_file(tmp_path: Path,
                                                        dry_run_scenes: Path) -> None:
    """Another deflate (here: another level) writes other bytes for the pinned pixels: the
    file is accepted by its pixel hash; a changed pixel is not."""
    stim = StimulusSet(tmp_path / "s")
    path = stim.scene_path("scene-04", DRY_RUN_SIZE)
    px = scenes.render_scene(4, *DRY_RUN_SIZE)
    path.parent.mkdir(parents=True)
    path.write_bytes(scenes.png_bytes(px, level=1))
    assert stim.verify_scene("scene-04", DRY_RUN_SIZE, path)[0] == "ok (pixels)"
    assert stim.check("scene-04", DRY_RUN_SIZE, dry_run=False).usable
    px[100, 200, 1] ^= 4
    path.write_bytes(scenes.png_bytes(px, level=1))
    assert stim.check("scene-04", DRY_RUN_SIZE, dry_run=False).status == "changed"


def test_generate_refuses_pixels_that_differ_from_the_pins(tmp_path: Path) -> None:
    """A machine that draws other pixels than the pinned ones writes nothing."""
    pins = {k: v.model_copy(deep=True) for k, v in PINS.items()}
    pins["scene-02"].sha256["480x270"].pixels = "f" * 64
    stim = StimulusSet(tmp_path / "s", scene_pins=pins)
    with pytest.raises(FovexpError, match="scene-02 at 480x270: the generator's pixels differ"):
        generate_scenes(stim, DRY_RUN_SIZE, ["scene-02"])
    assert not stim.scene_path("scene-02", DRY_RUN_SIZE).exists()


@pytest.mark.gui
def test_dry_run_scaling_is_logged(tmp_path: Path, xvfb_display) -> None:  # noqa: F811
    ws = make_workspace(tmp_path / "ws")
    r = run_cli(["run", "protocols/calibration-fe.yaml", "--participant", "S01", "--dry-run",
                 "--window", "320x180", "--limit-trials", "1", "--practice", "0",
                 "--sim-speed", "12"], cwd=ws, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "dry run: 5 of 5 images scaled from 480x270 to 320x180" in r.stderr
    (info_path,) = (ws / "results" / "calibration-fe" / "S01").glob("session-*.json")
    rec = json.loads(info_path.read_text())["stimuli"]
    assert rec["frame_size"] == [320, 180] and rec["dry_run"] is True
    assert rec["scaled"] == [f"scene-0{i}" for i in range(5)]
    assert rec["images"]["scene-00"]["size"] == [480, 270]


# -- fovexp stimuli add / check -------------------------------------------------------------------
def test_add_images_keeps_their_samples(tmp_path: Path, capsys) -> None:
    """8-bit RGB and 16-bit RGB and grey stills: written losslessly as PNG at the same depth,
    listed with source, licence and the file's sha256; ids are guarded."""
    disp = tiny_display(tmp_path)
    lab = tmp_path / "lab"
    cases = {"rgb8": pattern(36, 64, 1), "rgb16": pattern(36, 64, 2, np.uint16),
             "grey16": pattern(36, 64, 3, np.uint16, channels=1)}
    for name, px in cases.items():
        src = write_png(tmp_path / "in" / f"{name}.png", px)
        r = cli(capsys, ["stimuli", "add", str(src), "--id", name, "--display", str(disp),
                         "--licence", "CC-BY-3.0", "--source", f"test {name}",
                         "--stimuli", str(lab)])
        assert r.returncode == 0, r.stderr
    # a TIFF (another format) is converted to PNG, still 16-bit
    import imageio.v3 as iio

    iio.imwrite(tmp_path / "in" / "t16.tif", cases["rgb16"])
    r = cli(capsys, ["stimuli", "add", str(tmp_path / "in" / "t16.tif"), "--id", "tiff16",
                     "--display", str(disp), "--stimuli", str(lab)])
    assert r.returncode == 0 and "no --licence given" in r.stderr
    man = yaml.safe_load((lab / "manifest.yaml").read_text())
    by_id = {e["id"]: e for e in man["images"]}
    for name, px in {**cases, "tiff16": cases["rgb16"]}.items():
        e = by_id[name]
        path = lab / e["path"]
        assert e["path"] == f"frames/{name}.png" and path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert e["sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()
        back = read_samples(path)
        assert back.dtype == px.dtype and np.array_equal(back, px)
    assert by_id["rgb8"]["source"] == "test rgb8" and by_id["rgb8"]["licence"] == "CC-BY-3.0"
    assert by_id["tiff16"]["source"] == "t16.tif" and by_id["tiff16"]["licence"] == "unspecified"

    def add(*extra: str, src: Path = tmp_path / "in" / "rgb8.png"):
        return cli(capsys, ["stimuli", "add", str(src), "--display", str(disp), "--stimuli",
                            str(lab), *extra])

    r = add("--id", "rgb8")
    assert r.returncode == 2 and "already in" in r.stderr and "--replace" in r.stderr
    assert add("--id", "rgb8", "--replace").returncode == 0
    assert len(yaml.safe_load((lab / "manifest.yaml").read_text())["images"]) == 4
    r = add("--id", "scene-01")
    assert r.returncode == 2 and "generated scene's id" in r.stderr
    r = add("--id", "big", src=write_png(tmp_path / "in" / "big.png", pattern(40, 64, 4)))
    assert r.returncode == 2
    assert "big.png is 64x40; display tiny-64x36 shows 64x36" in r.stderr
    rgba = np.dstack([pattern(36, 64, 5), np.full((36, 64), 128, np.uint8)])
    from PIL import Image

    Image.fromarray(rgba).save(tmp_path / "in" / "rgba.png")
    r = add("--id", "rgba", src=tmp_path / "in" / "rgba.png")
    assert r.returncode == 2 and "transparent pixels" in r.stderr
    assert add("--id", "x", src=tmp_path / "nope.png").returncode == 2
    assert len(r.stderr.strip().splitlines()) == 1


def _video(path: Path, frames: list[np.ndarray], fps: float, pix_fmt_in: str,
           pix_fmt_out: str) -> Path:
    """A lossless (FFV1) video with the ffmpeg imageio-ffmpeg ships."""
    import imageio_ffmpeg

    h, w = frames[0].shape[:2]
    writer = imageio_ffmpeg.write_frames(str(path), (w, h), fps=fps, codec="ffv1",
                                         pix_fmt_in=pix_fmt_in, pix_fmt_out=pix_fmt_out,
                                         macro_block_size=1, output_params=["-g", "5"])
    writer.send(None)
    for f in frames:
        writer.send(np.ascontiguousarray(f).tobytes())
    writer.close()
    return path


def test_add_video_frame_at_a_time_stamp(tmp_path: Path, capsys) -> None:
    """The frame at --at (the first at or after it), 8-bit as 8-bit, 16-bit as 16-bit."""
    disp = tiny_display(tmp_path)
    lab = tmp_path / "lab"
    frames8 = [pattern(36, 64, 100 + k) for k in range(20)]
    v8 = _video(tmp_path / "v8.mkv", frames8, 10, "rgb24", "bgr0")
    frames16 = [pattern(36, 64, 200 + k, np.uint16) for k in range(20)]
    v16 = _video(tmp_path / "v16.mkv", [f.astype("<u2") for f in frames16], 10, "rgb48le",
                 "gbrp16le")
    for vid, at, k, name in ((v8, "0.5", 5, "a"), (v8, "00:00:01.2", 12, "b"),
                             (v16, "0:00.7", 7, "c")):
        r = cli(capsys, ["stimuli", "add", str(vid), "--at", at, "--id", name, "--display",
                         str(disp), "--licence", "CC0-1.0", "--stimuli", str(lab)])
        assert r.returncode == 0, r.stderr
        got = read_samples(lab / "frames" / f"{name}.png")
        want = (frames8 if vid == v8 else frames16)[k]
        assert got.dtype == want.dtype and np.array_equal(got, want), (name, k)
    e = {x["id"]: x for x in yaml.safe_load((lab / "manifest.yaml").read_text())["images"]}
    assert e["b"]["source"] == "v8.mkv at 00:00:01.2"
    r = cli(capsys, ["stimuli", "add", str(v8), "--at", "5", "--id", "late", "--display",
                     str(disp), "--stimuli", str(lab)])
    assert r.returncode == 2 and "no frame at 5 s" in r.stderr
    r = cli(capsys, ["stimuli", "add", str(v8), "--id", "d", "--display", str(disp),
                     "--stimuli", str(lab)])
    assert r.returncode == 2 and "--at TIME" in r.stderr


def test_check_lists_every_image_and_exits_2_on_a_refusal(tmp_path: Path, capsys) -> None:
    disp = tiny_display(tmp_path)
    lab = tmp_path / "lab"
    src = write_png(tmp_path / "in" / "f.png", pattern(36, 64, 9))
    assert cli(capsys, ["stimuli", "add", str(src), "--id", "lab-1", "--display", str(disp),
                        "--stimuli", str(lab)]).returncode == 0
    assert cli(capsys, ["stimuli", "generate", "--display", str(disp), "--only", "scene-00",
                        "--stimuli", str(lab)]).returncode == 0
    proto = protocol_with(tmp_path / "p", ["lab-1", "scene-00"], display=str(disp))
    r = cli(capsys, ["stimuli", "check", str(proto), "--stimuli", str(lab)])
    assert r.returncode == 0, r.stdout + r.stderr
    rows = {ln.split()[0]: ln.split() for ln in r.stdout.splitlines()
            if ln.startswith(("lab-1", "scene-00"))}
    assert rows["lab-1"][1:] == ["frames/lab-1.png", "64x36", "ok", "ok"]
    assert rows["scene-00"][1:] == ["generated/64x36/scene-00.png", "64x36", "ok", "ok"]
    # the paper's display: both would be refused (the frame's size, the scene missing)
    r = cli(capsys, ["stimuli", "check", str(proto), "--stimuli", str(lab), "--display",
                     "lg-oled55cx"])
    assert r.returncode == 2
    assert "refused: 64x36 is not 3840x2160" in r.stdout and "missing" in r.stdout
    assert f"fovexp stimuli generate --size 3840x2160 --stimuli {lab}" in r.stdout
    # ... while a dry run may scale both to its window
    r = cli(capsys, ["stimuli", "check", str(proto), "--stimuli", str(lab), "--display",
                     "lg-oled55cx", "--dry-run"])
    assert r.returncode == 0 and r.stdout.count("scaled from 64x36") == 2
    # a changed file
    f = lab / "frames" / "lab-1.png"
    f.write_bytes(f.read_bytes() + b"\0")
    r = cli(capsys, ["stimuli", "check", str(proto), "--stimuli", str(lab)])
    assert r.returncode == 2 and "changed" in r.stdout
    # bad input: one line, exit 2
    for args in (["check", "no-such-protocol"], ["generate", "--size", "12xq"],
                 ["generate", "--only", "scene-99", "--stimuli", str(lab)]):
        r = cli(capsys, ["stimuli", *args])
        assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr


def test_check_takes_several_protocols(tmp_path: Path, capsys) -> None:
    """``fovexp stimuli check protocols/*.yaml``: each protocol's table in turn; exit 0 only
    when every one passes; a protocol that cannot be read is one error line, the others are
    still checked."""
    disp = tiny_display(tmp_path)
    lab = tmp_path / "lab"
    assert cli(capsys, ["stimuli", "generate", "--display", str(disp), "--only",
                        "scene-00,scene-01", "--stimuli", str(lab)]).returncode == 0
    p0 = protocol_with(tmp_path / "p0", ["scene-00"], display=str(disp))
    p1 = protocol_with(tmp_path / "p1", ["scene-01"], display=str(disp))
    r = cli(capsys, ["stimuli", "check", str(p0), str(p1), "--stimuli", str(lab)])
    assert r.returncode == 0, r.stdout + r.stderr
    assert r.stdout.count("all 1 images can be shown by a real session") == 2
    assert r.stdout.count("protocol ") == 2
    p2 = protocol_with(tmp_path / "p2", ["scene-02"], display=str(disp))  # not generated
    r = cli(capsys, ["stimuli", "check", str(p0), str(p2), str(p1), "--stimuli", str(lab)])
    assert r.returncode == 2 and r.stdout.count("can be shown by a real session") == 2
    assert "1 of 1 images would be refused" in r.stdout
    r = cli(capsys, ["stimuli", "check", "no-such-protocol", str(p1), "--stimuli", str(lab)])
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    assert "can be shown by a real session" in r.stdout


def test_from_any_folder(tmp_path: Path) -> None:
    """From a folder with no ./stimuli and no $FOVEXP_STIMULI, the commands share the per-user
    data folder: generate, then check the shipped validation protocol by name."""
    work = tmp_path / "anywhere"
    work.mkdir()
    env = {ENV_VAR: None, "XDG_DATA_HOME": str(tmp_path / "xdg")}
    r = run_cli(["stimuli", "generate", "--size", "480x270", "--only",
                 ",".join(f"scene-{i:02d}" for i in range(5, 15))], cwd=work, env_update=env)
    assert r.returncode == 0, r.stderr
    folder = tmp_path / "xdg" / "fovexp" / "stimuli"
    assert len(list((folder / "generated" / "480x270").glob("scene-*.png"))) == 10
    r = run_cli(["stimuli", "check", "validation", "--dry-run"], cwd=work, env_update=env)
    assert r.returncode == 0 and f"stimulus folder {folder} (found by the user data folder)" \
        in r.stdout
    r = run_cli(["stimuli", "check", "validation"], cwd=work, env_update=env)
    assert r.returncode == 2
    assert f"fovexp stimuli generate --size 3840x2160 --stimuli {folder}" in r.stdout
    assert list(work.iterdir()) == []  # nothing written where it ran
