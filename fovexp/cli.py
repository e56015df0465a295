"""``fovexp`` command line: ``enhance`` (this module), ``run`` (experiment runner) and
``analyze`` (analysis). Bad input prints one ``fovexp: error: ...`` line and exits with 2."""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

from . import __version__
from .backends import BACKENDS, make_enhancer
from .errors import FovexpError
from .geometry import load_display
from .io import IMAGE_SUFFIXES, read_image, save_npy, write_image
from .params import METHODS, PRESETS, ParameterTable, make_params
from .pipeline import MAP_NAMES, Enhancer, EnhanceResult


def _gaze(text: str) -> tuple[float, float]:
    try:
        x, y = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"gaze must be 'x,y' in normalised screen coordinates, got {text!r}"
        ) from None
    return x, y


def add_enhance_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "enhance", help="foveate and enhance an image, a folder of frames or a video",
        description="Foveation simulation, contrast enhancement and noise-based enhancement "
        "(Tariq et al. 2022). IN and OUT are image files (PNG/TIFF/JPEG), or folders of "
        "frames, or videos.",
    )
    p.add_argument("input", type=Path, metavar="IN")
    p.add_argument("output", type=Path, metavar="OUT")
    p.add_argument("--display", default="lg-oled55cx", help="display profile name or YAML path")
    p.add_argument("--gaze", type=_gaze, default=(0.5, 0.5), help="x,y in [0, 1] (x right, y down)")
    p.add_argument("--blur-rate", type=float, default=0.34, help="arcmin per deg past the fovea")
    p.add_argument("--method", choices=METHODS, default="ours")
    p.add_argument("--fe", type=float, help="contrast enhancement f_e (default: from the table)")
    p.add_argument("--sk", type=float, help="noise amplitude scale s_k (default: from the table)")
    p.add_argument("--sf", type=float, help="noise bandwidth scale s_f (default: from the table)")
    p.add_argument("--impulses", type=int, default=64, help="impulses per kernel (12 is fast)")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--preset", choices=sorted(PRESETS), default="paper")
    p.add_argument("--backend", choices=BACKENDS, default="auto",
                   help="cpu, gpu (OpenGL 4.5 compute), or auto: a hardware GPU if there is one")
    p.add_argument("--geometry", choices=("exact", "linear"), default=None,
                   help="viewing geometry of the paper preset (default exact)")
    p.add_argument("--table", type=Path, help="parameter table YAML (default: paper Table 2)")
    p.add_argument("--input-foveated", action="store_true",
                   help="IN is already foveated at --blur-rate (skip the foveation simulation)")
    p.add_argument("--sigma-map", type=Path, help="IN is already foveated with this sigma map "
                   "(.npy, px, the image's size)")
    p.add_argument("--bit-depth", type=int, choices=(8, 16), default=8)
    p.add_argument("--dump-maps", type=Path, metavar="DIR",
                   help="write every intermediate map as float32 .npy and a PNG preview")
    p.set_defaults(func=enhance_command)


def _preview(m: np.ndarray) -> np.ndarray:
    """A [0, 1] picture of a map: images as they are, other maps scaled to their finite range."""
    v = np.where(np.isfinite(m), m, np.nan)
    lo, hi = np.nanmin(v), np.nanmax(v)
    if not np.isfinite(lo) or hi <= lo:
        return np.zeros(m.shape, np.float32)
    return np.nan_to_num((v - lo) / (hi - lo), nan=1.0)


def dump_maps(result: EnhanceResult, folder: Path) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    for name in MAP_NAMES:
        m = result.map(name)
        save_npy(folder / f"{name}.npy", m)
        image_like = name in ("foveated", "contrast", "output")
        write_image(folder / f"{name}.png", m if image_like else _preview(m))


def _enhancer_and_params(args: argparse.Namespace):
    table = ParameterTable.load(args.table) if args.table else None
    enh = make_enhancer(load_display(args.display), preset=args.preset, geometry=args.geometry,
                        table=table, backend=args.backend)
    params = make_params(
        method=args.method, blur_rate=args.blur_rate, f_e=args.fe, s_k=args.sk, s_f=args.sf,
        impulses=args.impulses, seed=args.seed, preset=args.preset,
    )
    return enh, params


def _set(enh: Enhancer, image: np.ndarray, args: argparse.Namespace, sigma) -> None:
    enh.set_image(image, foveated=args.input_foveated, sigma_px=sigma)


def enhance_command(args: argparse.Namespace) -> int:
    from .sequence import is_sequence

    enh, params = _enhancer_and_params(args)
    sigma = None
    if args.sigma_map is not None:
        try:
            sigma = np.load(args.sigma_map)
        except (OSError, ValueError) as exc:
            raise FovexpError(f"{args.sigma_map}: cannot read sigma map ({exc})") from None
    if is_sequence(args.input):
        return _enhance_sequence(enh, params, args, sigma)
    if args.output.suffix.lower() not in IMAGE_SUFFIXES:
        raise FovexpError(
            f"{args.output}: unsupported output type {args.output.suffix!r} "
            f"(use {', '.join(IMAGE_SUFFIXES)})"
        )
    image = read_image(args.input)
    _set(enh, image, args, sigma)
    result = enh.enhance(args.gaze, params)
    write_image(args.output, result.output, args.bit_depth)
    if args.dump_maps:
        dump_maps(result, args.dump_maps)
    print(f"wrote {args.output} ({params.method}, blur-rate {params.blur_rate}, "
          f"f_e {result.params.f_e:.3g}, s_k {result.params.s_k:.3g}, s_f {result.params.s_f:.3g}; "
          f"{_backend_name(enh)})")
    return 0


def _backend_name(enh: Enhancer) -> str:
    return f"gpu: {enh.renderer}" if enh.backend == "gpu" else "cpu"  # type: ignore[attr-defined]


def _enhance_sequence(enh: Enhancer, params, args: argparse.Namespace, sigma) -> int:
    from tqdm import tqdm

    from .sequence import VIDEO_SUFFIXES, InterframeSSIM, VideoWriter, iter_frames

    count, fps, frames = iter_frames(args.input)
    video = VideoWriter(args.output, fps) if args.output.suffix.lower() in VIDEO_SUFFIXES else None
    if video is None:
        args.output.mkdir(parents=True, exist_ok=True)
    ssim_in, ssim_out = InterframeSSIM(), InterframeSSIM()
    n = 0
    try:
        for name, image in tqdm(frames, total=count, desc="enhance", unit="frame",
                                file=sys.stderr):
            _set(enh, image, args, sigma)  # the impulses stay: they depend on size and seed
            result = enh.enhance(args.gaze, params)
            ssim_in.add(image)
            ssim_out.add(result.output)
            if video is None:
                write_image(args.output / f"{name}.png", result.output, args.bit_depth)
            else:
                video.append(result.output)
            n += 1
    except BaseException:
        if video is not None:
            video.abort()
        raise
    if video is not None:
        video.close()
    print(f"wrote {n} frames to {args.output}; mean inter-frame SSIM: input {ssim_in.mean:.4f}, "
          f"output {ssim_out.mean:.4f}")
    return 0


class _Parser(argparse.ArgumentParser):
    """Argument errors as one line, like every other input error."""

    def error(self, message: str) -> None:  # type: ignore[override]
        print(f"fovexp: error: {message} (see '{self.prog} --help')", file=sys.stderr)
        raise SystemExit(2)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="fovexp", description=__doc__)
    parser.add_argument("--version", action="version", version=f"fovexp {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    add_enhance_parser(sub)
    from .analysis.cli import add_analyze_parser
    from .experiment.cli import add_run_parser
    from .experiment.stimuli_cli import add_stimuli_parser

    add_run_parser(sub)
    add_stimuli_parser(sub)
    add_analyze_parser(sub)
    return parser


def plain_warnings(prog: str) -> None:
    """Our warnings (a torn log row dropped, ...) as one line for the operator, not Python's
    two-line ``file:line: UserWarning`` form with a source excerpt."""
    default = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):  # noqa: ANN001
        if issubclass(category, UserWarning):
            print(f"{prog}: warning: {message}", file=sys.stderr)
        else:
            default(message, category, filename, lineno, file, line)

    warnings.showwarning = show


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    plain_warnings("fovexp")
    try:
        return int(args.func(args) or 0)
    except FovexpError as exc:
        print(f"fovexp: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
