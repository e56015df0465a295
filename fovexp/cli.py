"""``fovexp`` command line: ``enhance`` and ``compile`` (this module), ``run`` (experiment
runner), ``init`` (a study folder, :mod:`fovexp.experiment.protocol.study`), ``analyze`` (analysis),
``monitor`` (the live view of running sessions), ``docs`` (the documentation site,
:mod:`fovexp.docsite`) and ``bench`` (run time against error, :mod:`fovexp.bench`).
Bad input prints one ``fovexp: error: ...`` line and exits with 2.

A command's module, and what it imports, is loaded only when that command runs (or its
``--help`` is asked for): ``fovexp enhance`` loads neither the runner nor the analysis (nor
pandas, matplotlib unless ``--dump-maps``, PsychoPy), and ``fovexp --help`` and ``--version``
load no command at all.
"""

from __future__ import annotations

import argparse
import gc
import importlib
import os
import sys
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ._version import __version__
from .errors import FovexpError

#: The commands: name -> (module, function adding the command's arguments to its parser, the
#: line ``fovexp --help`` shows).
COMMANDS: dict[str, tuple[str, str, str]] = {
    "enhance": ("fovexp.cli", "add_enhance_parser",
                "foveate and enhance an image, a folder of frames or a video"),
    "run": ("fovexp.experiment.cli", "add_run_parser",
            "run an experiment protocol with a participant"),
    "stimuli": ("fovexp.stimuli.cli", "add_stimuli_parser",
                "generate scenes, add a lab's frames, check a protocol's images"),
    "analyze": ("fovexp.analysis.cli", "add_analyze_parser",
                "turn trial logs into the paper's results (Table 2, validation tests)"),
    "monitor": ("fovexp.monitor.cli", "add_monitor_parser",
                "watch running sessions in a browser (read-only)"),
    "init": ("fovexp.experiment.protocol.study", "add_init_parser",
             "make a study folder: copies of the shipped protocols, stimuli/, results/"),
    "docs": ("fovexp.docsite", "add_docs_parser",
             "the documentation: print where the built site is, or open it"),
    "compile": ("fovexp.cli", "add_compile_parser",
                "compile the Numba kernels ahead of the first run (once after installing)"),
    "bench": ("fovexp.bench", "add_bench_parser",
              "measure run time against error of the engine's options, and against size"),
    "evaluate": ("fovexp.evaluation.cli", "add_evaluate_parser",
                 "the paper's analyses of outputs: spectra, FovVDP, temporal, JPEG (section 6)"),
    "stereo": ("fovexp.evaluation.cli", "add_stereo_parser",
               "enhance a stereo pair: noise for one eye, warped to the other (section 6.4)"),
    "rig": ("fovexp.rig.cli", "add_rig_parser",
            "measure the rig before the first participant: display, GPU, tracker"),
    "tracker": ("fovexp.experiment.cli", "add_tracker_parser",
                "print the example ioHub configuration of an eye-tracker family"),
    "export": ("fovexp.export.bids", "add_export_parser",
               "share a study: a results folder as a BIDS dataset (docs/SHARING.md)"),
}


# --------------------------------------------------------------------------------- enhance
def _parameter(name: str) -> Callable[[str], float | int]:
    """An argparse type: the value of parameter ``name`` within its accepted range
    (:func:`fovexp.params.check_parameter`), else a one-line error naming the range."""

    def parse(text: str) -> float | int:
        from .params import check_parameter

        try:
            return check_parameter(name, text)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(f"{text!r}: {exc}") from None

    parse.__name__ = name  # argparse names the type in some messages
    return parse


def _gaze(text: str) -> tuple[float, float]:
    try:
        x, y = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"gaze must be 'x,y' in normalised screen coordinates, got {text!r}"
        ) from None
    if not all(0.0 <= v <= 1.0 for v in (x, y)):  # NaN fails every comparison
        raise argparse.ArgumentTypeError(
            f"{text!r}: x and y must be finite numbers in [0, 1] (normalised screen "
            "coordinates, x right, y down; 0 and 1 are the screen's edges)"
        )
    return x, y


def add_enhance_parser(sub: Any) -> argparse.ArgumentParser:
    from .backends import BACKENDS
    from .io import BIT_DEPTHS
    from .params import METHODS, PRESETS

    p = sub.add_parser(
        "enhance", help=COMMANDS["enhance"][2],
        description="Foveation simulation, contrast enhancement and noise-based enhancement "
        "(Tariq et al. 2022). IN and OUT are image files (PNG/TIFF/JPEG; grey or RGB, with or "
        "without alpha, which passes through unchanged), or folders of frames, or videos.",
    )
    p.add_argument("input", type=Path, metavar="IN")
    p.add_argument("output", type=Path, metavar="OUT")
    p.add_argument("--display", default="lg-oled55cx", help="display profile name or YAML path")
    p.add_argument("--gaze", type=_gaze, default=(0.5, 0.5), help="x,y in [0, 1] (x right, y down)")
    p.add_argument("--blur-rate", type=_parameter("blur_rate"), default=0.34,
                   help="arcmin per deg past the fovea")
    p.add_argument("--method", choices=METHODS, default="ours")
    p.add_argument("--fe", type=_parameter("f_e"),
                   help="contrast enhancement f_e (default: from the table)")
    p.add_argument("--sk", type=_parameter("s_k"),
                   help="noise amplitude scale s_k (default: from the table)")
    p.add_argument("--sf", type=_parameter("s_f"),
                   help="noise bandwidth scale s_f (default: from the table)")
    p.add_argument("--impulses", type=_parameter("impulses"), default=64,
                   help="impulses per kernel (12 is fast)")
    p.add_argument("--seed", type=_parameter("seed"), default=1)
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
    p.add_argument("--bit-depth", type=int, choices=BIT_DEPTHS, default=None,
                   help="bits per sample of OUT (default: IN's; JPEG and videos are 8-bit)")
    p.add_argument("--dump-maps", type=Path, metavar="DIR",
                   help="write every intermediate map as float32 .npy and a PNG preview")
    p.set_defaults(func=enhance_command)
    return p


def _enhancer_and_params(args: argparse.Namespace):
    from .backends import make_enhancer
    from .geometry import load_display
    from .params import ParameterTable, make_params

    table = ParameterTable.load(args.table) if args.table else None
    enh = make_enhancer(load_display(args.display), preset=args.preset, geometry=args.geometry,
                        table=table, backend=args.backend)
    params = make_params(
        method=args.method, blur_rate=args.blur_rate, f_e=args.fe, s_k=args.sk, s_f=args.sf,
        impulses=args.impulses, seed=args.seed, preset=args.preset,
    )
    return enh, params


def _set(enh: Any, image: Any, args: argparse.Namespace, sigma: Any) -> None:
    enh.set_image(image, foveated=args.input_foveated, sigma_px=sigma)


def _output_depth(args: argparse.Namespace, path: Path, input_depth: int) -> int:
    """``--bit-depth``, else the input's depth where the output format has it (JPEG: 8)."""
    if args.bit_depth is not None:
        return args.bit_depth
    return 8 if path.suffix.lower() in (".jpg", ".jpeg") else input_depth


def enhance_command(args: argparse.Namespace) -> int:
    import numpy as np

    from .io import IMAGE_SUFFIXES, write_image
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
    from .progress import Steps

    names = ["read", "enhance", "write"] + (["maps"] if args.dump_maps else [])
    with Steps(names, desc="fovexp enhance") as step:
        step("read")
        image, depth = _read_loading_kernels(args, enh, params, sigma)
        step("enhance")
        _set(enh, image, args, sigma)
        result = enh.enhance(args.gaze, params)
        step("write")
        write_image(args.output, result.output, _output_depth(args, args.output, depth))
        if args.dump_maps:
            from .maps import dump_maps

            step("maps")
            dump_maps(result, args.dump_maps, on_map=lambda name: step("maps", name))
    print(f"wrote {args.output} ({params.method}, blur-rate {params.blur_rate}, "
          f"f_e {result.params.f_e:.3g}, s_k {result.params.s_k:.3g}, s_f {result.params.s_f:.3g}; "
          f"{_backend_name(enh)})")
    global _DONE
    _DONE = True
    return 0


def _read_loading_kernels(args: argparse.Namespace, enh: Any, params: Any,
                          sigma: Any) -> tuple[Any, int]:
    """:func:`fovexp.io.read_image_with_depth` of ``IN`` on a thread of its own while this one
    loads the kernels the frame will call (:func:`fovexp.warmup.load_frame_kernels`): the
    decoder releases the GIL, the loading is mostly Python. A warm 4K ``fovexp enhance`` of
    the Sponza JPEG: median 1.60 -> 1.55 s (five runs each, alternating)."""
    from concurrent.futures import ThreadPoolExecutor

    from .io import read_image_with_depth
    from .warmup import load_frame_kernels

    with ThreadPoolExecutor(1, thread_name_prefix="fovexp-read") as reader:
        pending = reader.submit(read_image_with_depth, args.input)
        try:
            load_frame_kernels(enh, params, foveated=args.input_foveated or sigma is not None)
        finally:
            image, depth = pending.result()  # the read's own error first, if any
    return image, depth


def _backend_name(enh: Any) -> str:
    return f"gpu: {enh.renderer}" if enh.backend == "gpu" else "cpu"


def _enhance_sequence(enh: Any, params: Any, args: argparse.Namespace, sigma: Any) -> int:
    from .io import write_image
    from .progress import progress_bar
    from .sequence import VIDEO_SUFFIXES, InterframeSSIM, VideoWriter, iter_frames

    count, fps, frames = iter_frames(args.input)
    video = VideoWriter(args.output, fps) if args.output.suffix.lower() in VIDEO_SUFFIXES else None
    if video is None:
        args.output.mkdir(parents=True, exist_ok=True)
    ssim_in, ssim_out = InterframeSSIM(), InterframeSSIM()
    n = 0
    try:
        for name, image, depth in progress_bar(frames, total=count, desc="fovexp enhance",
                                           unit="frame"):
            _set(enh, image, args, sigma)  # the impulses stay: they depend on size and seed
            result = enh.enhance(args.gaze, params)
            ssim_in.add(image)
            ssim_out.add(result.output)
            if video is None:
                out = args.output / f"{name}.png"
                write_image(out, result.output, _output_depth(args, out, depth))
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


# --------------------------------------------------------------------------------- compile
def add_compile_parser(sub: Any) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "compile", help=COMMANDS["compile"][2],
        description="Compile every Numba kernel of the enhancer into Numba's on-disk cache, so "
        "that the first 'fovexp enhance' or 'fovexp run' does not spend about 20 s doing it. "
        "Run it once after installing or upgrading fovexp, as the user who runs fovexp "
        "(./dev setup does). The cache is $NUMBA_CACHE_DIR when set, else beside the "
        "installed package when that folder is writable, else ~/.cache/numba.",
    )
    p.set_defaults(func=compile_command)
    return p


def compile_command(args: argparse.Namespace) -> int:
    from .warmup import compile_kernels

    report = compile_kernels(show_progress=True)
    where = ", ".join(sorted(report.cache_dirs)) or "no cache folder"
    print(f"fovexp compile: {report.total} kernels: {len(report.compiled)} compiled, "
          f"{len(report.loaded)} loaded from the cache, {len(report.inlined)} inside the "
          f"kernels that call them; {report.seconds:.1f} s; cache: {where}")
    return 0


# --------------------------------------------------------------------------------- parser
class _Parser(argparse.ArgumentParser):
    """Argument errors as one line, like every other input error. A command's parser is
    filled in (its module imported) only when it parses or shows its help."""

    def __init__(self, *args: Any, fill: Callable[[_Parser], None] | None = None,
                 **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._fill = fill

    def _filled(self) -> None:
        fill, self._fill = self._fill, None
        if fill is not None:
            fill(self)

    def parse_known_args(self, args=None, namespace=None):  # noqa: ANN001, ANN201
        self._filled()
        return super().parse_known_args(args, namespace)

    def format_help(self) -> str:
        self._filled()
        return super().format_help()

    def format_usage(self) -> str:
        self._filled()
        return super().format_usage()

    def error(self, message: str) -> None:  # type: ignore[override]
        print(f"fovexp: error: {message} (see '{self.prog} --help')", file=sys.stderr)
        raise SystemExit(2)


class _Into:
    """What a command's ``add_*_parser(subparsers)`` is given: ``add_parser`` returns the
    command's parser, already made, with the description (and formatting) it asks for."""

    def __init__(self, parser: _Parser) -> None:
        self._parser = parser

    def add_parser(self, name: str, **kwargs: Any) -> _Parser:
        for key in ("description", "epilog", "formatter_class"):
            if key in kwargs:
                setattr(self._parser, key, kwargs[key])
        return self._parser


def _filler(module: str, function: str) -> Callable[[_Parser], None]:
    def fill(parser: _Parser) -> None:
        getattr(importlib.import_module(module), function)(_Into(parser))

    return fill


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="fovexp",
        description="Noise-based enhancement for foveated rendering (Tariq, Tursun, Didyk 2022): "
        "enhance frames, run the experiments, analyse their logs. Bad input prints one "
        "'fovexp: error: ...' line and exits with status 2.",
    )
    parser.add_argument("--version", action="version", version=f"fovexp {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for name, (module, function, line) in COMMANDS.items():
        sub.add_parser(name, help=line, fill=_filler(module, function))
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


#: Set by a command that has finished everything it does (files closed and in place, no
#: process or thread of its own left): :func:`entry` then ends the process at once.
_DONE = False


def main(argv: list[str] | None = None) -> int:
    global _DONE
    _DONE = False  # a command of this call says so itself
    parser = build_parser()
    args = parser.parse_args(argv)
    plain_warnings("fovexp")
    try:
        return int(args.func(args) or 0)
    except FovexpError as exc:
        print(f"fovexp: error: {exc}", file=sys.stderr)
        return 2


def entry() -> None:
    """The ``fovexp`` program (console script, ``python -m fovexp``): :func:`main` with the
    garbage collector tuned for a short process (measured on the 2-core VM, 4K ``enhance``).

    - Its young generation is collected every 20,000 allocations, not 700: loading Numba and
      its kernels allocates millions of objects, which triggered 320 collections (0.1 s, and
      0.2 s end to end at the median of six runs).
    - The process exits without the interpreter's last full collection. Once Numba has loaded
      a kernel, that pass walks its compiler's objects: 0.27 s of every command's exit, with
      nothing of ours left to collect (files are closed and renamed into place by then).

    - NumPy does not ask for transparent huge pages (``NUMPY_MADVISE_HUGEPAGE=0``, NumPy's
      own setting, unless the environment sets it): a command touches its arrays' pages once
      or a few times, and a huge page costs its whole 2 MB zeroed at the first touch. A warm
      4K ``fovexp enhance`` took 2.17-2.56 s with them and 1.61-1.86 s without (six runs
      each, alternating; system time 1.1-2.1 -> 0.4-0.7 s); the frames of a long run, whose
      arrays are the last frame's buffers (:class:`fovexp.memory.FramePool`), the same
      either way.

    - A command that says it has nothing left to finish (:data:`_DONE`: ``fovexp enhance``,
      its files written, closed and renamed into place) ends the process at once, after
      flushing its output: the interpreter's teardown (its modules, Numba's and LLVM's
      objects, the thread pools) took 40-80 ms of every run.

    :func:`main` itself leaves the collector alone: tests call it in-process."""
    if "numpy" not in sys.modules:  # read once, when NumPy is imported
        os.environ.setdefault("NUMPY_MADVISE_HUGEPAGE", "0")
    gc.set_threshold(20_000, 20, 20)
    code = main()
    if _DONE:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    gc.freeze()  # the final collection skips frozen objects
    sys.exit(code)


if __name__ == "__main__":
    entry()
