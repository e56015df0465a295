"""``fovexp evaluate spectra|fovvdp|temporal|compression|gating`` and ``fovexp stereo``: the
paper's analyses of outputs (section 6), its stereo extension (6.4), and the gaze-contingent
blanking against the eye (``gating``, issue 28). ``fovexp.cli`` registers
:func:`add_evaluate_parser` and :func:`add_stereo_parser`; this module only parses and hands
over to the analysis modules (imported when the command runs). Bad input is one
``fovexp: error: ...`` line and exit status 2 (``fovexp.cli.main``)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

BACKEND_CHOICES = ("auto", "cpu", "gpu")


def _gaze(text: str) -> tuple[float, float]:
    from fovexp.cli import _gaze as parse  # the one gaze parser of the command line

    return parse(text)


def _common(p: argparse.ArgumentParser, blur_help: str, blur_default: str | None) -> None:
    p.add_argument("--display", default="lg-oled55cx", help="display profile name or YAML path")
    p.add_argument("--gaze", type=_gaze, default=(0.5, 0.5),
                   help="x,y in [0, 1] (x right, y down; default the centre)")
    if blur_default is None:
        p.add_argument("--blur-rate", required=True, help=blur_help)
    else:
        p.add_argument("--blur-rate", default=blur_default, help=blur_help)
    p.add_argument("--impulses", type=int, default=64, help="impulses per kernel (default 64)")
    p.add_argument("--seed", type=int, default=1, help="the impulses' seed (default 1)")
    p.add_argument("--backend", choices=BACKEND_CHOICES, default="auto",
                   help="cpu, gpu, or auto (a hardware GPU if there is one)")
    p.add_argument("--preset", choices=("paper", "release"), default="paper",
                   help="the paper's constants and Table 2 (default), or the authors' release "
                        "with its own defaults (docs/METHOD.md, 5; CPU backend)")
    p.add_argument("--out", type=Path, required=True, metavar="DIR",
                   help="folder for the CSV, the PNG figure and the Markdown note")


def _setup(args: argparse.Namespace) -> Any:
    from fovexp import FovexpError, check_parameter

    from .outputs import Setup

    for name in ("impulses", "seed"):
        try:
            check_parameter(name, getattr(args, name))
        except ValueError as exc:
            raise FovexpError(f"--{name} {getattr(args, name)}: {exc}") from None
    return Setup.make(args.display, args.backend, args.impulses, args.seed, args.gaze,
                      args.preset)


def add_evaluate_parser(sub: Any) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "evaluate", help="the paper's analyses of outputs: spectra, FovVDP, temporal, JPEG",
        description="The paper's analyses of the enhancer's outputs (section 6): output "
        "spectra per eccentricity ring (6.1), FovVDP (6.1, the [fovvdp] extra), temporal "
        "coherence (6.2), foveated JPEG compression (6.3). Each writes a CSV, a PNG figure and "
        "a Markdown note to --out.")
    ev = p.add_subparsers(dest="evaluate_command", required=True, parser_class=type(p))

    s = ev.add_parser(
        "spectra", help="power spectra of the outputs per eccentricity ring (section 6.1)",
        description="Per method (foveated, contrast, ours), blur-rate and eccentricity ring: "
        "the radially averaged power spectrum of the output over windowed patches in the "
        "ring, relative to the full-resolution image's, in dB against cycles/deg, with T_L "
        "and T_H of the ring marked. The paper's figure averages 5 scenes at three "
        "blur-rates and does not say which scenes; the scenes are this command's IMAGEs (the "
        "record, benchmarks/EVALUATION.md, assumes the 5 calibration scenes: fovexp stimuli "
        "generate; stimuli/generated/3840x2160/scene-00.png ... scene-04.png). A ring whose "
        "band lies above the image's Nyquist frequency is said in one warning line.")
    s.add_argument("images", nargs="+", type=Path, metavar="IMAGE",
                   help="full-resolution images (or folders of them), one size")
    _common(s, "blur-rates, comma-separated (default 0.11,0.34,0.57: Table 2's)",
            "0.11,0.34,0.57")
    s.add_argument("--rings", default="12,18,24",
                   help="ring centres in deg, comma-separated (default 12,18,24), each "
                   "--ring-width wide")
    s.add_argument("--ring-width", type=float, default=4.0,
                   help="width of each ring in deg (default 4)")
    s.add_argument("--patch", type=int, default=None, metavar="PX",
                   help="patch side in px (default 128 at 3840 px width, scaled)")
    s.set_defaults(func=spectra_command)

    f = ev.add_parser(
        "fovvdp", help="FovVDP JOD of each method against full resolution (section 6.1)",
        description="FovVDP (Mantiuk et al. 2021; pyfvvdp, the optional [fovvdp] extra, "
        "licensed CC BY-NC 4.0) of foveated, contrast and ours against the full-resolution "
        "image, with a display model built from the display profile (size, resolution, "
        "distance, peak luminance, gamma), fixation at the gaze; JOD per scene and the "
        "paper's three paired t-tests across scenes, in the foveated mode (the paper's) and "
        "beside it the non-foveated one, with the per-scene differences in both. A blur-rate "
        "beyond Table 2 (the paper's 0.68) clamps f_e, s_k, s_f to its last row: said in one "
        "warning line.")
    f.add_argument("images", nargs="+", type=Path, metavar="IMAGE")
    _common(f, "the blur-rate (the paper's figure: 0.68)", None)
    f.add_argument("--contrast-ratio", type=float, default=1000.0,
                   help="the display's contrast ratio for FovVDP's display model "
                   "(default 1000, pyfvvdp's)")
    f.add_argument("--device", default="cpu", help="PyTorch device (default cpu)")
    f.add_argument("--foveated-only", action="store_true",
                   help="leave out the non-foveated mode (half the metric's time)")
    f.set_defaults(func=fovvdp_command)

    t = ev.add_parser(
        "temporal", help="mean inter-frame SSIM and temporal slices (section 6.2)",
        description="The mean SSIM between consecutive frames per condition (full "
        "resolution, foveated, contrast, ours, and ours with the impulses re-seeded every "
        "frame as a control) and blur-rate, and the temporal slices of two pixels. A test "
        "sequence: fovexp stimuli pan --out DIR.")
    t.add_argument("frames", type=Path, metavar="FRAMES", help="a folder of frames or a video")
    _common(t, "blur-rates, comma-separated (default 0.11,0.34,0.57)", "0.11,0.34,0.57")
    t.add_argument("--slices", default="0.25,0.5;0.8,0.7", metavar="X,Y;X,Y",
                   help="the pixels of the temporal slices, normalised (default "
                   "0.25,0.5;0.8,0.7: left of and below right of a central gaze)")
    t.add_argument("--no-reseed", action="store_true",
                   help="leave out the re-seeded-impulses control (one enhancement less per "
                   "frame)")
    t.set_defaults(func=temporal_command)

    c = ev.add_parser(
        "compression", help="JPEG sizes at the participants' blur-rates (section 6.3)",
        description="For each validation scene: the foveated image at the blur-rate where "
        "participants judged contrast enhancement invisible and at the one for ours (their "
        "means), each encoded as JPEG quality 90 with Pillow (4:2:0 chroma subsampling); the "
        "file sizes and the saving of ours over contrast in %. The paper took the blur-rates "
        "of its 12-impulse experiment (Figure 16 right), and so does this command by default "
        "(the validation whose recorded protocol has 12 impulses, else validation-12; "
        "validation with a warning where neither is there). It also prints the saving "
        "against the blur-rate ratio and at Table 2's pair, 0.34 against 0.57.")
    c.add_argument("results", type=Path, metavar="RESULTS",
                   help="results folder holding a validation experiment's trial logs")
    c.add_argument("--experiment", default=None,
                   help="the experiment (default: the 12-impulse validation, the paper's; "
                   "see above)")
    c.add_argument("--ratios", default=None,
                   help="blur-rate ratios (ours / contrast) of the saving-against-ratio table, "
                   "comma-separated (default 1,1.25,...,2.5; 'none': no table)")
    c.add_argument("--pair", default=None, metavar="LO,HI",
                   help="the blur-rates of contrast and ours compared as a pair (default "
                   "0.34,0.57: Table 2's; 'none': not compared)")
    c.add_argument("--images", type=Path, default=None, metavar="DIR",
                   help="folder of the scenes as <image id>.png at the display's resolution "
                   "(default: the files the sessions recorded)")
    c.add_argument("--display", default="lg-oled55cx", help="display profile name or YAML path")
    c.add_argument("--gaze", type=_gaze, default=(0.5, 0.5), help="x,y in [0, 1]")
    c.add_argument("--quality", type=int, default=90, help="JPEG quality (default 90)")
    c.add_argument("--backend", choices=BACKEND_CHOICES, default="auto")
    c.add_argument("--preset", choices=("paper", "release"), default="paper",
                   help="whose foveation (the paper's 8 deg fovea, or the release's 12 deg)")
    c.add_argument("--out", type=Path, required=True, metavar="DIR")
    c.set_defaults(func=compression_command)

    g = ev.add_parser(
        "gating", help="the blanking against the eye, over delivery latencies (issue 28)",
        description="Dry runs of PROTOCOL with the simulated eye of each behaviour and each "
        "injected delivery latency (fovexp run --dry-run --sim-gaze B --gaze-latency-ms L, "
        "under Xvfb where there is no display), then from their logs: the delivery latency, "
        "the stimulus frames the latency let through, and the stimulus time on screen while "
        "the simulated eye was outside the 1.25 deg window, per session, per trial and per "
        "excursion, against 6 ms (McConkie and Loschky 2002) and 60 ms (Loschky and "
        "Wolverton 2007). Writes gating.csv, gating-trials.csv, gating-excursions.csv, "
        "gating.png and gating.md.")
    g.add_argument("--protocol", default="calibration-fe",
                   help="the protocol the dry runs run (default calibration-fe)")
    g.add_argument("--latencies", default="0,4,8,16,32,48,64", metavar="MS,...",
                   help="injected delivery latencies (default 0,4,8,16,32,48,64; one at or "
                   "above the gaze timeout is noted, not run: the stimulus would never show)")
    g.add_argument("--behaviours", default="steady,wandering", metavar="B,...",
                   help="the simulated eye's behaviours (--sim-gaze presets, with settings "
                   "joined by ';': wandering;blink_rate=0.3)")
    g.add_argument("--trials", type=int, default=3, help="main trials per dry run (default 3)")
    g.add_argument("--seed", type=int, default=5, help="the simulated eye's and participant's "
                   "seed, the same for every run (default 5)")
    g.add_argument("--sim-speed", type=float, default=12.0,
                   help="the simulated participant's time compression (default 12)")
    g.add_argument("--stimuli", type=Path, default=None, metavar="DIR",
                   help="stimulus folder of the dry runs (default as for fovexp run)")
    g.add_argument("--out", type=Path, required=True, metavar="DIR")
    g.set_defaults(func=gating_command)
    return p


def spectra_command(args: argparse.Namespace) -> int:
    from fovexp import FovexpError

    from . import spectra
    from .outputs import parse_blur_rates

    try:
        centres = [float(v) for v in args.rings.split(",")]
    except ValueError:
        raise FovexpError(f"--rings {args.rings!r}: expected degrees, comma-separated") from None
    half = 0.5 * args.ring_width
    if not (half > 0 and all(c - half >= 0 for c in centres)):  # NaN fails too
        raise FovexpError(f"--rings {args.rings} --ring-width {args.ring_width}: each ring must "
                          "lie at eccentricities >= 0 and be wider than 0 deg")
    if args.patch is not None and not 8 <= args.patch <= 4096:
        raise FovexpError(f"--patch {args.patch}: must be 8 to 4096 px")
    res = spectra.run(args.images, _setup(args), parse_blur_rates(args.blur_rate), args.out,
                      spectra.default_rings(centres, half), args.patch)
    print(f"fovexp evaluate spectra: {len(res.images)} image(s) x {len(res.blur_rates)} "
          f"blur-rate(s) x {len(res.rings)} ring(s); wrote {args.out}/spectra.csv, bands.csv, "
          "spectra.png, spectra.md")
    return 0


def fovvdp_command(args: argparse.Namespace) -> int:
    from fovexp import FovexpError

    from . import fovvdp
    from .outputs import parse_blur_rates

    rates = parse_blur_rates(args.blur_rate)
    if len(rates) != 1:
        raise FovexpError(f"--blur-rate {args.blur_rate}: give one blur-rate")
    if not args.contrast_ratio > 1:
        raise FovexpError(f"--contrast-ratio {args.contrast_ratio}: must be a number above 1")
    res = fovvdp.run(args.images, _setup(args), rates[0], args.out,
                     contrast_ratio=args.contrast_ratio, device=args.device,
                     nonfoveated=not args.foveated_only)
    print(f"fovexp evaluate fovvdp: {len(res.images)} image(s) at blur-rate {rates[0]:g}, "
          f"{' and '.join(res.modes)} mode; wrote {args.out}/fovvdp.csv, fovvdp-tests.csv, "
          "fovvdp.png, fovvdp.md")
    return 0


def _slices(text: str) -> list[tuple[float, float]]:
    from fovexp import FovexpError

    out = []
    for part in text.split(";"):
        try:
            out.append(_gaze(part.strip()))
        except argparse.ArgumentTypeError as exc:
            raise FovexpError(f"--slices {text!r}: {exc}") from None
    return out


def temporal_command(args: argparse.Namespace) -> int:
    from . import temporal
    from .outputs import parse_blur_rates

    res = temporal.run(args.frames, _setup(args), parse_blur_rates(args.blur_rate), args.out,
                       _slices(args.slices), reseed=not args.no_reseed)
    print(f"fovexp evaluate temporal: {res.n_frames} frames x {len(res.blur_rates)} "
          f"blur-rate(s); wrote {args.out}/temporal.csv, slices.csv, pairs.csv, temporal.png, "
          "temporal.md")
    return 0


def gating_command(args: argparse.Namespace) -> int:
    from fovexp import FovexpError

    from . import gating

    if args.trials < 1 or args.sim_speed <= 0:
        raise FovexpError("--trials must be at least 1 and --sim-speed above 0")
    behaviours = [b.strip().replace(";", ",") for b in args.behaviours.split(",") if b.strip()]
    table = gating.run(args.out, protocol=args.protocol,
                       latencies_ms=gating.parse_list(args.latencies, "latencies"),
                       behaviours=behaviours, trials=args.trials, seed=args.seed,
                       sim_speed=args.sim_speed, stimuli=args.stimuli)
    print(f"fovexp evaluate gating: {len(table)} dry runs; wrote {args.out}/gating.csv, "
          "gating-trials.csv, gating-excursions.csv, gating.png, gating.md")
    return 0


def compression_command(args: argparse.Namespace) -> int:
    from fovexp import FovexpError

    from . import compression
    from .outputs import Setup

    if not 1 <= args.quality <= 100:
        raise FovexpError(f"--quality {args.quality}: must be 1 to 100")
    ratios = (list(compression.RATIOS) if args.ratios is None else
              _numbers("--ratios", args.ratios, lambda r: 0 < r <= 10, "ratios in (0, 10]"))
    pair = (list(compression.TABLE2_PAIR) if args.pair is None else
            _numbers("--pair", args.pair, lambda b: 0 <= b <= 5, "two blur-rates in [0, 5]"))
    if len(pair) not in (0, 2):
        raise FovexpError(f"--pair {args.pair!r}: give two blur-rates, LO,HI")
    setup = Setup.make(args.display, args.backend, gaze=args.gaze, preset=args.preset)
    res = compression.run(args.results, setup, args.out, experiment=args.experiment,
                          images=args.images, quality=args.quality, ratios=tuple(ratios),
                          pair=(pair[0], pair[1]) if pair else None)
    print(f"fovexp evaluate compression: {len(res.table)} scene(s) of "
          f"{res.experiment_line()}; largest saving {res.max_saving_pct:.1f} %")
    print("\n".join(compression.ratio_lines(res)))
    print(f"wrote {args.out}/compression.csv, compression-ratios.csv, compression-table2.csv, "
          "compression.png, compression.md")
    return 0


def _numbers(option: str, text: str, ok: Any, what: str) -> list[float]:
    """``"1,1.5"`` -> [1.0, 1.5]; ``"none"`` -> []; each checked by ``ok``."""
    from fovexp import FovexpError

    if text.strip().lower() == "none":
        return []
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise FovexpError(f"{option} {text!r}: expected {what}, comma-separated") from None
    if not all(ok(v) for v in values):  # NaN fails too
        raise FovexpError(f"{option} {text!r}: expected {what}")
    return values


# -------------------------------------------------------------------------------- stereo
def add_stereo_parser(sub: Any) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "stereo", help="enhance a stereo pair: noise for one eye, warped to the other (6.4)",
        description="Paper section 6.4: each eye is foveated and contrast-enhanced on its own "
        "image; the noise is synthesised once, for the left eye, and forward-warped to the "
        "right eye by the disparity (d = x_left - x_right in px on the left image's grid); "
        "pixels of the right eye no left pixel lands on (disocclusions) get noise of the right "
        "eye's own parameters. Writes left.png, right.png and anaglyph.png (red-cyan). A test "
        "pair: fovexp stimuli stereo --out DIR.")
    p.add_argument("left", type=Path, metavar="LEFT")
    p.add_argument("right", type=Path, metavar="RIGHT")
    p.add_argument("--disparity", type=Path, required=True, metavar="FILE",
                   help="float32 .npy (px), or a 16-bit PNG holding d x --disparity-scale")
    p.add_argument("--disparity-scale", type=float, default=256.0,
                   help="a PNG disparity's value per px (default 256)")
    _common(p, "the blur-rate", "0.34")
    p.add_argument("--dump-maps", action="store_true",
                   help="also write each eye's noise layer (noise-left.npy, noise-right.npy, "
                   "float32, linear luminance) and the disocclusion mask (disocclusion.png)")
    p.set_defaults(func=stereo_command)
    return p


def stereo_command(args: argparse.Namespace) -> int:
    from fovexp import FovexpError

    from . import stereo
    from .outputs import parse_blur_rates

    rates = parse_blur_rates(args.blur_rate)
    if len(rates) != 1:
        raise FovexpError(f"--blur-rate {args.blur_rate}: give one blur-rate")
    rate = rates[0]
    res = stereo.run(args.left, args.right, args.disparity, _setup(args), rate, args.out,
                     disparity_scale=args.disparity_scale, dump_maps=args.dump_maps)
    print(f"fovexp stereo: wrote {args.out}/left.png, right.png, anaglyph.png; "
          f"{res.disoccluded_fraction * 100:.2f} % of the right eye disoccluded"
          + (", noise layers dumped" if args.dump_maps else ""))
    return 0
