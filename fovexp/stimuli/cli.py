"""``fovexp stimuli``: generate the scenes, add a lab's frames, check a protocol's images.

``fovexp.cli`` registers it with :func:`add_stimuli_parser` (this module imports nothing heavy
at import time). Exit status: 0 done; 2 bad input, or (``check``) an image a session would
refuse. Where the stimulus folder is, and what is in it: :mod:`.stimuli`, docs/EXPERIMENT.md.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path
from typing import Any

from fovexp import FovexpError

#: file suffixes read as videos (one frame taken at --at); anything else is read as an image
VIDEO_SUFFIXES = (".mp4", ".mov", ".mkv", ".webm", ".avi", ".m4v", ".mxf", ".y4m", ".mpg",
                  ".mpeg", ".ts")
DEFAULT_DISPLAY = "lg-oled55cx"


def _folder_help() -> str:
    return ("stimulus folder (default: the stimuli/ of the study folder (fovexp init) you are "
            "in, $FOVEXP_STIMULI, ./stimuli if there is one, else the user data folder)")


def add_stimuli_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add the ``stimuli`` subcommand to ``subparsers`` (an argparse sub-parser action)."""
    p = subparsers.add_parser(
        "stimuli", help="generate scenes, add a lab's frames, check a protocol's images",
        description="The images protocols name by id: the generated scenes (scene-00 ... "
        "scene-14) and a lab's own frames, kept in a stimulus folder the lab owns. A real "
        "session shows each at the display's own resolution and refuses any other size.")
    sub = p.add_subparsers(dest="stimuli_command", required=True, parser_class=type(p))

    g = sub.add_parser("generate", help="write the generated scenes at a display's resolution",
                       description="Write scene-00 ... scene-14 as PNG into "
                       "generated/WxH/ of the stimulus folder, deterministic to the byte; "
                       "checked against the sha256 fovexp pins for 3840x2160 and 480x270 "
                       "(other sizes: recorded in the folder's manifest.yaml).")
    size = g.add_mutually_exclusive_group()
    size.add_argument("--display", default=None, metavar="PROFILE",
                      help=f"display profile whose resolution to use (default {DEFAULT_DISPLAY})")
    size.add_argument("--size", default=None, metavar="WxH",
                      help="this resolution instead (480x270: what a dry run shows)")
    g.add_argument("--only", default=None, metavar="IDS",
                   help="comma-separated scene ids (default: all fifteen)")
    g.add_argument("--force", action="store_true",
                   help="write every scene again (default: keep files that check out)")
    g.add_argument("--jobs", type=int, default=None, metavar="N",
                   help="scenes generated at once (default: the CPU count, at most 8)")
    g.add_argument("--stimuli", type=Path, default=None, metavar="DIR", help=_folder_help())
    g.set_defaults(func=generate_command)

    a = sub.add_parser("add", help="import a lab's frame: an image, or a video's frame",
                       description="Import a still image, or the first frame at or after "
                       "--at of a video, as a lossless PNG (16-bit input stays 16-bit) into "
                       "frames/ID.png of the stimulus folder, and list it in its "
                       "manifest.yaml with source, licence and sha256.")
    a.add_argument("source_file", type=Path, metavar="IMAGE|VIDEO")
    a.add_argument("--id", required=True, help="the id protocols will name it by")
    a.add_argument("--at", default=None, metavar="TIME",
                   help="a video's time stamp: seconds (310.5) or [HH:]MM:SS[.fff]")
    a.add_argument("--source", default=None,
                   help="where it comes from (default: the file's name and the time stamp)")
    a.add_argument("--licence", "--license", dest="licence", default="unspecified",
                   help="its licence, an SPDX id (e.g. CC-BY-3.0 for the Blender open movies)")
    a.add_argument("--display", default=DEFAULT_DISPLAY, metavar="PROFILE",
                   help=f"display profile its size must match (default {DEFAULT_DISPLAY})")
    a.add_argument("--replace", action="store_true", help="replace an existing id")
    a.add_argument("--stimuli", type=Path, default=None, metavar="DIR", help=_folder_help())
    a.set_defaults(func=add_command)

    c = sub.add_parser("check", help="list protocols' images with size and status",
                       description="Every image each protocol names: file, size, sha256 and "
                       "whether a session can show it. Exits 2 when a real session (or, with "
                       "--dry-run, a dry run) would refuse one, or a protocol cannot be read.")
    c.add_argument("protocol", nargs="+",
                   help="protocol YAML, or the name of one in ./protocols or shipped with "
                   "fovexp (calibration-fe, calibration-sk, calibration-sf, validation); "
                   "several at once (protocols/*.yaml)")
    c.add_argument("--display", default=None, metavar="PROFILE",
                   help="check for this display profile instead of the protocol's")
    c.add_argument("--dry-run", action="store_true",
                   help="check for a dry run instead of a real session (scaling allowed, "
                   "except at the display's own size: a rehearsal)")
    c.add_argument("--window", default=None, metavar="WxH",
                   help="the window size, as fovexp run --window")
    c.add_argument("--stimuli", type=Path, default=None, metavar="DIR",
                   help="stimulus folder (default: the protocol's, then as for generate)")
    c.set_defaults(func=check_command)

    pan = sub.add_parser("pan", help="write a camera pan over a generated scene (frames)",
                         description="A deterministic test sequence for 'fovexp evaluate "
                         "temporal' (paper section 6.2): the camera pans across a generated "
                         "scene, the content moving --step px to the left per frame; frames "
                         "written as frame-0000.png ... into --out.")
    pan.add_argument("--scene", default="scene-00", help="generated scene id (default scene-00)")
    pan.add_argument("--size", default="3840x2160", metavar="WxH", help="frame size")
    pan.add_argument("--frames", type=int, default=30, help="number of frames (default 30)")
    pan.add_argument("--step", type=int, default=8, metavar="PX",
                     help="pan per frame in px (default 8: 960 px/s at 120 Hz)")
    pan.add_argument("--out", type=Path, required=True, metavar="DIR")
    pan.set_defaults(func=pan_command)

    st = sub.add_parser("stereo", help="write a stereo pair with a known disparity map",
                        description="A stereo test pair for 'fovexp stereo' (paper section "
                        "6.4): a generated scene as a far plane and a rectangle of another as a "
                        "near plane. Writes left.png, right.png and the disparity of the left "
                        "image's pixels, d = x_left - x_right in px, as disparity.npy (float32) "
                        "and disparity.png (16-bit, d = value / 256).")
    st.add_argument("--scene", default="scene-00", help="generated scene id (default scene-00)")
    st.add_argument("--size", default="3840x2160", metavar="WxH", help="image size")
    st.add_argument("--far", type=int, default=4, metavar="PX",
                    help="disparity of the background plane (default 4 px)")
    st.add_argument("--near", type=int, default=16, metavar="PX",
                    help="disparity of the near rectangle (default 16 px)")
    st.add_argument("--out", type=Path, required=True, metavar="DIR")
    st.set_defaults(func=stereo_command)
    return p


def _run(name: str, body: Any, args: argparse.Namespace) -> int:
    try:
        return int(body(args) or 0)
    except FovexpError as exc:
        print(f"fovexp stimuli {name}: error: {exc}", file=sys.stderr)
        return 2


# -- generate ------------------------------------------------------------------------------------
def generate_command(args: argparse.Namespace) -> int:
    return _run("generate", _generate, args)


def _generate(args: argparse.Namespace) -> int:
    import os

    from .folder import StimulusSet, generate_scenes, parse_size, size_text

    if args.size is not None:
        size = parse_size(args.size)
    else:
        from fovexp import load_display

        d = load_display(args.display or DEFAULT_DISPLAY)
        size = (int(d.width_px), int(d.height_px))
    ids = [i.strip() for i in args.only.split(",") if i.strip()] if args.only else None
    stim = StimulusSet.find(args.stimuli)
    jobs = args.jobs or min(os.cpu_count() or 1, 8)
    print(f"fovexp stimuli generate: {size_text(size)} into {stim.describe()}", flush=True)
    from fovexp import progress_bar

    bars: list[Any] = []

    def started(todo: list[str]) -> None:
        bars.append(progress_bar(total=len(todo), desc="fovexp stimuli generate",
                                 unit="scene"))

    def wrote(image_id: str, n_bytes: int, sha256: str) -> None:
        bars[0].set_postfix_str(f"{image_id} {n_bytes / 1e6:.1f} MB", refresh=False)
        bars[0].update(1)

    try:
        done = generate_scenes(stim, size, ids, force=args.force, jobs=jobs, progress=wrote,
                               on_todo=started)
    finally:
        for bar in bars:
            bar.close()
    if done.recorded:
        print(f"fovexp stimuli generate: {size_text(size)} is not a pinned resolution; the "
              f"scenes' sha256 were recorded in {stim.manifest_path}")
    if done.other_zlib:
        import zlib

        print(f"fovexp stimuli generate: note: {len(done.other_zlib)} PNG file(s) differ from "
              f"the pinned bytes although their pixels are the pinned ones (this Python's zlib "
              f"{zlib.ZLIB_RUNTIME_VERSION} deflates differently); sessions accept them by "
              "their pixels")
    kept = f", {len(done.up_to_date)} up to date" if done.up_to_date else ""
    print(f"fovexp stimuli generate: wrote {len(done.written)} scene(s){kept} in {done.folder} "
          f"({done.n_bytes / 1e6:.0f} MB, {done.seconds:.1f} s, {done.jobs} job(s))")
    return 0


# -- add -----------------------------------------------------------------------------------------
def parse_time(text: str) -> float:
    """``"310.5"``, ``"5:10"``, ``"00:05:10.25"`` -> seconds."""
    m = re.fullmatch(r"\s*(?:(?:(\d+):)?(\d{1,2}):)?(\d+(?:\.\d*)?)\s*", text)
    if m is None:
        raise FovexpError(f"--at {text!r}: expected seconds or [HH:]MM:SS[.fff]")
    h, mnt, sec = m.groups()
    return int(h or 0) * 3600 + int(mnt or 0) * 60 + float(sec)


def read_video_frame(path: Path, at_s: float):  # noqa: ANN201  (numpy array)
    """The first frame at or after ``at_s`` seconds, as uint8 RGB, or uint16 RGB when the
    video's samples have more than 8 bits (10-bit masters stay deep)."""
    import imageio_ffmpeg
    import numpy as np

    def frames(pix_fmt: str):  # noqa: ANN202
        return imageio_ffmpeg.read_frames(str(path), pix_fmt=pix_fmt,
                                          bpp=6 if pix_fmt == "rgb48le" else 3,
                                          input_params=["-ss", f"{at_s:.6f}"],
                                          output_params=["-frames:v", "1"])

    try:
        gen = frames("rgb24")
        meta = next(gen)
        gen.close()
        src = str(meta.get("pix_fmt", "")).split("(")[0]
        deep = re.search(r"(?:9|10|12|14|16)(?:le|be)$|48|64", src) is not None
        gen = frames("rgb48le" if deep else "rgb24")
        meta = next(gen)
        try:
            data = next(gen)
        except StopIteration:
            raise FovexpError(f"{path}: no frame at {at_s:g} s (the video is "
                              f"{meta.get('duration', '?')} s long)") from None
        finally:
            gen.close()
    except FovexpError:
        raise
    except Exception as exc:  # ffmpeg's errors come as RuntimeError/OSError/IOError
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise FovexpError(f"{path}: cannot read a frame at {at_s:g} s ({first})") from None
    w, h = meta["size"]
    dtype = np.dtype("<u2") if deep else np.uint8
    a = np.frombuffer(data, dtype).reshape(h, w, 3)
    return a.astype(np.uint16) if deep else a.copy()


def add_command(args: argparse.Namespace) -> int:
    return _run("add", _add, args)


def _add(args: argparse.Namespace) -> int:
    import hashlib
    import re as _re

    from fovexp import load_display

    from . import scenes
    from .folder import FRAMES, StimulusEntry, StimulusSet, read_samples, size_text

    if _re.fullmatch(r"[A-Za-z0-9_.-]{1,64}", args.id) is None:
        raise FovexpError(f"--id {args.id!r}: use 1 to 64 of A-Z a-z 0-9 _ . -")
    if args.id in scenes.SCENE_IDS:
        raise FovexpError(f"--id {args.id}: that is a generated scene's id; choose another")
    src: Path = args.source_file
    if not src.is_file():
        raise FovexpError(f"{src}: no such file")
    video = src.suffix.lower() in VIDEO_SUFFIXES
    if video and args.at is None:
        raise FovexpError(f"{src} is a video: give the frame's time stamp with --at TIME")
    if not video and args.at is not None:
        raise FovexpError(f"--at is for videos; {src} is read as an image")
    display = load_display(args.display)
    need = (int(display.width_px), int(display.height_px))
    stim = StimulusSet.find(args.stimuli)
    if args.id in stim.frames and not args.replace:
        raise FovexpError(f"id {args.id!r} is already in {stim.manifest_path} (add --replace "
                          "to replace it)")
    if video:
        at_s = parse_time(args.at)
        pixels = read_video_frame(src, at_s)
        where = f"{src.name} at {args.at}"
    else:
        pixels = read_samples(src)
        where = src.name
    have = (pixels.shape[1], pixels.shape[0])
    if have != need:
        raise FovexpError(f"{where} is {size_text(have)}; display {display.name} shows "
                          f"{size_text(need)} and a real session never rescales a stimulus "
                          "(export it at that size, or name the display with --display)")
    data = scenes.png_bytes(pixels)
    rel = f"{FRAMES}/{args.id}.png"
    from fovexp import write_bytes_atomic

    write_bytes_atomic(stim.folder / rel, data)
    entry = StimulusEntry(id=args.id, path=rel, source=args.source or where,
                          licence=args.licence, sha256=hashlib.sha256(data).hexdigest())
    stim.lab.images = [e for e in stim.lab.images if e.id != args.id] + [entry]
    stim.write_manifest()
    depth = 8 * pixels.itemsize
    kind = "RGB" if pixels.ndim == 3 else "grey"
    print(f"fovexp stimuli add: {args.id}: {where} -> {stim.folder / rel} ({size_text(have)}, "
          f"{depth}-bit {kind}, {len(data) / 1e6:.1f} MB, sha256 {entry.sha256[:12]}...), "
          f"listed in {stim.manifest_path}")
    if args.licence == "unspecified":
        print("fovexp stimuli add: warning: no --licence given; state who may use it in "
              f"{stim.manifest_path}", file=sys.stderr)
    return 0


# -- pan, stereo --------------------------------------------------------------------------------
#: 16-bit PNG disparity maps hold d * DISPARITY_PNG_SCALE (fovexp stereo reads them so).
DISPARITY_PNG_SCALE = 256


def _scene_index(scene: str) -> int:
    from . import scenes

    if scene not in scenes.SCENE_IDS:
        raise FovexpError(f"--scene {scene!r}: not a generated scene ({scenes.SCENE_IDS[0]} ... "
                          f"{scenes.SCENE_IDS[-1]})")
    return scenes.SCENE_IDS.index(scene)


def pan_command(args: argparse.Namespace) -> int:
    return _run("pan", _pan, args)


def _pan(args: argparse.Namespace) -> int:
    from fovexp import write_bytes_atomic

    from . import scenes
    from .folder import parse_size, size_text

    index = _scene_index(args.scene)
    size = parse_size(args.size)
    if args.frames < 2:
        raise FovexpError(f"--frames {args.frames}: a pan needs 2 frames or more")
    if not 0 <= args.step <= size[0]:
        raise FovexpError(f"--step {args.step}: must be 0 to the frame width ({size[0]} px)")
    frames = scenes.render_pan(index, size[0], size[1], args.frames, args.step)
    for k, frame in enumerate(frames):
        write_bytes_atomic(args.out / f"frame-{k:04d}.png", scenes.png_bytes(frame))
    print(f"fovexp stimuli pan: {args.frames} frames of {size_text(size)} ({args.scene}, "
          f"{args.step} px per frame to the left) in {args.out}")
    return 0


def stereo_command(args: argparse.Namespace) -> int:
    return _run("stereo", _stereo, args)


def _stereo(args: argparse.Namespace) -> int:
    import io

    import numpy as np

    from fovexp import write_bytes_atomic

    from . import scenes
    from .folder import parse_size, size_text

    index = _scene_index(args.scene)
    size = parse_size(args.size)
    if not 0 <= args.far < args.near:
        raise FovexpError(f"--far {args.far} --near {args.near}: need 0 <= far < near (px)")
    if args.near * DISPARITY_PNG_SCALE > 65535 or args.near >= size[0] // 4:
        raise FovexpError(f"--near {args.near}: too large for a {size_text(size)} pair")
    left, right, disp = scenes.render_stereo_pair(index, size[0], size[1], args.far, args.near)
    write_bytes_atomic(args.out / "left.png", scenes.png_bytes(left))
    write_bytes_atomic(args.out / "right.png", scenes.png_bytes(right))
    buf = io.BytesIO()
    np.save(buf, disp)
    write_bytes_atomic(args.out / "disparity.npy", buf.getvalue())
    coded = np.round(disp * DISPARITY_PNG_SCALE).astype(np.uint16)
    write_bytes_atomic(args.out / "disparity.png", scenes.png_bytes(coded))
    print(f"fovexp stimuli stereo: {size_text(size)} pair ({args.scene}; far plane "
          f"{args.far} px, near rectangle {args.near} px of disparity) in {args.out}")
    return 0


# -- check ---------------------------------------------------------------------------------------
def check_command(args: argparse.Namespace) -> int:
    return _run("check", _check, args)


def _check(args: argparse.Namespace) -> int:
    """Each protocol in turn (a blank line between them); 2 when any would refuse an image or
    cannot be read (its error on one line, the others still checked)."""
    code = 0
    for n, name in enumerate(args.protocol):
        if n:
            print()
        try:
            code = max(code, _check_one(name, args))
        except FovexpError as exc:
            print(f"fovexp stimuli check: error: {exc}", file=sys.stderr)
            code = 2
    return code


def _check_one(name: str, args: argparse.Namespace) -> int:
    from fovexp import find_protocol, load_display

    from ..experiment.protocol.spec import protocol_display, protocol_stimuli, read_protocol
    from .folder import DRY_RUN_SIZE, may_scale, parse_size, size_text

    path = find_protocol(name)
    _, spec = read_protocol(path)
    if args.display is not None:
        display = load_display(args.display)
    else:
        display = protocol_display(path, spec)[1]
    native = (int(display.width_px), int(display.height_px))
    frame = parse_size(args.window) if args.window else (
        DRY_RUN_SIZE if args.dry_run else native)
    stim = protocol_stimuli(path, spec, args.stimuli)
    scale = may_scale(args.dry_run, frame, native)
    rows = stim.check_all(spec.images, frame, scale)
    mode = ("a real session" if not args.dry_run else "a dry run" if scale else
            "a dry run at the display's size (a rehearsal: nothing scaled)")
    print(f"protocol {path}")
    print(f"stimulus folder {stim.describe()}")
    print(f"display {display.name} ({size_text(native)}); {mode} shows {size_text(frame)}")
    table = [("id", "file", "size", "sha256", "status")]
    for r in rows:
        file = "-"
        if r.path is not None:
            try:
                file = str(r.path.relative_to(stim.folder))
            except ValueError:
                file = str(r.path)
        status = r.status
        if r.scaled and r.size is not None:
            status = f"scaled from {size_text(r.size)}"
        elif r.status == "refused" and r.size is not None:
            status = f"refused: {size_text(r.size)} is not {size_text(frame)}"
        table.append((r.id, file, size_text(r.size) if r.size else "-", r.sha, status))
    widths = [max(len(row[k]) for row in table) for k in range(4)]
    for row in table:
        print("  ".join(v.ljust(w) for v, w in zip(row[:4], widths, strict=True)) + "  " + row[4])
    bad = [r for r in rows if not r.usable]
    if not bad:
        print(f"all {len(rows)} images can be shown by {mode}")
        return 0
    print(f"{len(bad)} of {len(rows)} images would be refused by {mode}:")
    for fix in dict.fromkeys(r.fix for r in bad if r.fix):
        print(f"  {fix}")
    return 2
