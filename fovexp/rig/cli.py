"""``fovexp rig check``: measure the rig before the first participant (docs/EXPERIMENT.md, "The
rig check"); exit 0 when every judged check passed, 1 when one failed, 2 on bad input."""

from __future__ import annotations

import argparse
import datetime as _dt
import shlex
import sys
from pathlib import Path
from typing import Any

from fovexp import BACKENDS, FovexpError, find_protocol
from fovexp.results.format import TRACKERS

from ..experiment.cli import window_size
from .checks import MIN_REFRESH_S

#: the protocol measured outside a study folder without ``--protocol``
DEFAULT_PROTOCOL = "validation"


def study_protocol(study: Path) -> Path:
    """The protocol of the study folder ``study`` (``fovexp init``) that the rig check
    measures: among those its ``fovexp-study.yaml`` lists, the one whose wheel adjusts the
    blur-rate (the study's validation, which ``init`` names after the study: its steps load
    the enhancer most, as the shipped validation's do outside a study), else the first."""
    from fovexp.experiment.protocol.spec import read_protocol
    from fovexp.experiment.protocol.study import study_protocols
    from fovexp.stimuli.folder import STUDY_FILE

    found = study_protocols(study)
    if not found:
        raise FovexpError(f"the study folder {study} lists no protocol file that exists "
                          f"({STUDY_FILE}: protocols); name one with --protocol")
    for path in found:
        if read_protocol(path)[1].adjust.parameter == "blur_rate":
            return path
    return found[0]


def rig_protocol(name: str | None, cwd: Path | None = None) -> tuple[Path, str]:
    """The protocol file ``fovexp rig check`` measures with, and why that one (the report
    says both): ``--protocol`` as ``fovexp run`` finds it; without it, inside a study folder
    (found as every command finds it: :func:`fovexp.stimuli.folder.find_study`, from ``cwd``
    or any folder below the study's) the study's own (:func:`study_protocol`); elsewhere
    :data:`DEFAULT_PROTOCOL`."""
    from fovexp.stimuli.folder import find_study

    if name is not None:
        return find_protocol(name), f"--protocol {name}"
    study = find_study(cwd if cwd is not None else Path.cwd())
    if study is not None:
        return study_protocol(study), f"the study folder {study}'s own"
    return find_protocol(DEFAULT_PROTOCOL), "the default outside a study folder"


def add_rig_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add the ``rig`` command (its one subcommand: ``check``)."""
    p = subparsers.add_parser(
        "rig", help="measure the rig: display, GPU, tracker (fovexp rig check)",
        description="What a rig holds of what the study needs, measured on the session's own "
        "window, renderer, gaze source and frame loop.")
    sub = p.add_subparsers(dest="rig_command", required=True, parser_class=type(p))
    c = sub.add_parser(
        "check", help="measure display, GPU and tracker; write a report under the results root",
        description="Measure the display's refresh rate and the frames under the session's "
        "load, the GPU, the tracker (rate, loss, gaze-to-flip latency, clock), each against a "
        "stated threshold; write rig/rig-<time>.json and .md under the results root "
        "(fovexp run records the newest). Exit 0 passed, 1 a check failed, 2 bad input.")
    c.add_argument("--protocol", default=None,
                   help="the protocol whose display, images, tracker, wheel steps and limits "
                        "to use (default: inside a study folder, the study's own protocol "
                        f"(fovexp init); elsewhere {DEFAULT_PROTOCOL}, whose blur-rate steps "
                        "load the enhancer most)")
    c.add_argument("--results", type=Path, default=Path("results"),
                   help="results root; the report goes to its rig/ folder (default ./results)")
    c.add_argument("--dry-run", action="store_true",
                   help="under Xvfb: a 480x270 window, simulated gaze (or --tracker iohub "
                        "with MouseGaze); every figure labelled as a virtual display's")
    c.add_argument("--duration", type=float, default=MIN_REFRESH_S, metavar="S",
                   help=f"seconds of each measured phase (default {MIN_REFRESH_S:g}; the "
                        f"refresh rate is judged only over at least {MIN_REFRESH_S:g} s)")
    c.add_argument("--tracker", choices=TRACKERS, default=None,
                   help="gaze source (default: tobii; simulated with --dry-run)")
    c.add_argument("--tracker-config", type=Path, default=None, metavar="FILE",
                   help="--tracker iohub: the ioHub configuration (YAML)")
    c.add_argument("--tracker-address", default=None, help="a Tobii's address or serial")
    c.add_argument("--backend", choices=BACKENDS, default="auto",
                   help="the enhancer's backend to load the display with (default auto)")
    c.add_argument("--screen", type=int, default=0, metavar="N", help="the monitor (default 0)")
    c.add_argument("--window", type=window_size, default=None, metavar="WxH",
                   help="window size instead of the display profile's")
    c.add_argument("--photodiode", action="store_true",
                   help="a corner patch on a known frame pattern, its flips logged, for a "
                        "photodiode or a Black Box Toolkit")
    c.add_argument("--stimuli", type=Path, default=None, metavar="DIR",
                   help="stimulus folder (as fovexp run)")
    c.set_defaults(func=rig_check_command)
    return p


def rig_check_command(args: argparse.Namespace) -> int:
    from fovexp.experiment.records.sessionfile import versions

    from .measure import RigOptions, run_measurements
    from .report import build_report, check_line, write_report

    def say(line: str) -> None:
        print(line, file=sys.stderr, flush=True)

    try:
        if args.duration <= 0:
            raise FovexpError("--duration must be > 0")
        if args.screen < 0:
            raise FovexpError("--screen must be 0 or more")
        if args.tracker_config is not None and args.tracker != "iohub":
            raise FovexpError("--tracker-config is for --tracker iohub")
        if args.dry_run and args.tracker not in (None, "simulated", "iohub"):
            raise FovexpError("--dry-run uses simulated gaze (or --tracker iohub)")
        protocol, chosen = rig_protocol(args.protocol)
        opts = RigOptions(results_root=args.results, protocol=protocol, protocol_chosen=chosen,
                          dry_run=args.dry_run, duration_s=args.duration, tracker=args.tracker,
                          tracker_config=args.tracker_config,
                          tracker_address=args.tracker_address, backend=args.backend,
                          screen=args.screen, window=args.window, photodiode=args.photodiode,
                          stimuli=args.stimuli, console=say)
        created = _dt.datetime.now().astimezone()
        measured = run_measurements(opts)
        report = build_report(measured.checks, measured.sections, dry_run=args.dry_run,
                              command="fovexp " + shlex.join(sys.argv[1:]) if sys.argv[1:]
                              else "fovexp rig check", created=created, versions=versions(),
                              duration_s=args.duration)
        path = write_report(args.results, report, created, measured.photodiode_rows)
    except FovexpError as exc:
        print(f"fovexp rig check: error: {exc}", file=sys.stderr)
        return 2
    for c in report["checks"]:
        say(f"fovexp rig check: {check_line(c)}")
    verdict = {True: "passed", False: "FAILED", None: "not judged"}[report["passed"]]
    failed = [c["title"] for c in report["checks"] if c["passed"] is False]
    label = " (dry run: a virtual display's figures)" if args.dry_run else ""
    say(f"fovexp rig check: {verdict}{label}: {path} and {path.with_suffix('.md').name}"
        + (f"; failed: {', '.join(failed)}" if failed else ""))
    return 1 if report["passed"] is False else 0


__all__ = ["DEFAULT_PROTOCOL", "add_rig_parser", "rig_check_command", "rig_protocol",
           "study_protocol"]
