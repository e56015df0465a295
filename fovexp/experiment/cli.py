"""``fovexp run``: run one of the protocols with a participant (docs/EXPERIMENT.md).

``fovexp.cli`` registers it with :func:`add_run_parser`; :func:`run_command` returns the exit
status: 0 finished, 2 bad input (one line on stderr, nothing opened), 3 aborted by the operator,
130 interrupted by a signal. The last two leave a session that ``--resume`` continues.

``fovexp tracker example [FAMILY]`` (:func:`add_tracker_parser`) prints the shipped example of
the ioHub configuration ``--tracker iohub --tracker-config`` reads, one per tracker family, for
a lab to save and edit (``--tracker-config example:FAMILY`` reads one as it is).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from fovexp import BACKENDS, FovexpError, find_protocol
from fovexp.results.format import SIMULATED_TRACKER, TRACKERS


def window_size(text: str) -> tuple[int, int]:
    """``--window WxH`` (the runner's and the rig check's): an even width, sides 16..16384."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not WIDTHxHEIGHT") from None
    if not (16 <= w <= 16384 and 16 <= h <= 16384) or w % 2:
        raise argparse.ArgumentTypeError(f"{text!r}: need an even width and sizes of 16..16384")
    return w, h


def add_run_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add the ``run`` subcommand to ``subparsers`` (an argparse sub-parser action)."""
    p = subparsers.add_parser(
        "run", help="run an experiment protocol with a participant",
        description="Run an experiment protocol (protocols/*.yaml): one of the paper's "
                    "adjustment experiments, or the forced-choice validation-2afc.")
    p.add_argument("protocol", help="protocol YAML, or the name of one in ./protocols or shipped "
                   "with fovexp (calibration-fe, calibration-sk, calibration-sf, validation, "
                   "validation-12, validation-2afc)")
    p.add_argument("--participant", required=True, help="participant ID ([A-Za-z0-9_-]{1,32})")
    p.add_argument("--tracker", choices=TRACKERS, default=None,
                   help="gaze source (default: tobii; simulated with --dry-run); iohub: any "
                        "eye tracker PsychoPy's ioHub reaches (EyeLink, Tobii, Gazepoint, Pupil "
                        "Labs, EyeLogic, MouseGaze), configured by --tracker-config")
    p.add_argument("--tracker-config", type=Path, default=None, metavar="FILE",
                   help="--tracker iohub: the ioHub configuration, the YAML PsychoPy Builder "
                        "or ioHub uses (default: the protocol's tracker.iohub_config); "
                        "example:FAMILY reads the shipped example of a tracker family "
                        "(fovexp tracker example prints them)")
    p.add_argument("--tracker-address", default=None,
                   help="Tobii tracker address or serial number (default: the first found)")
    p.add_argument("--dry-run", action="store_true",
                   help="simulated gaze and participant, small window, no display check")
    p.add_argument("--resume", action="store_true",
                   help="continue this participant's last incomplete session")
    p.add_argument("--new-session", action="store_true",
                   help="start a new session although an incomplete one exists")
    p.add_argument("--results", type=Path, default=Path("results"),
                   help="results root; the protocol's dependencies are read from it too "
                        "(default: ./results)")
    p.add_argument("--include-pilots", action="store_true",
                   help="let the dependencies' mouse-gaze pilot sessions count (left out by "
                        "default, as in fovexp analyze)")
    p.add_argument("--window", type=window_size, default=None, metavar="WxH",
                   help="window size instead of the display profile's (dry run: 480x270); a "
                        "real session needs its images at exactly this size, and so does a "
                        "dry run at the display's size (a rehearsal); a smaller dry run "
                        "scales them")
    p.add_argument("--stimuli", type=Path, default=None, metavar="DIR",
                   help="stimulus folder (default: the protocol's, the study folder's, "
                        "$FOVEXP_STIMULI, ./stimuli, or the user data folder; see fovexp "
                        "stimuli --help)")
    p.add_argument("--windowed", action="store_true", help="not full screen (pilots)")
    p.add_argument("--backend", choices=BACKENDS, default="auto",
                   help="enhancer backend: cpu, gpu (OpenGL 4.5 compute shaders), or auto: "
                        "a hardware GPU if there is one, else the CPU")
    p.add_argument("--screen", type=int, default=0, metavar="N",
                   help="the monitor to open the window on (multi-monitor rigs; default 0)")
    p.add_argument("--skip-display-check", action="store_true",
                   help="do not stop when the refresh rate or window size differ from the profile")
    p.add_argument("--accept-poll-keys", action="store_true",
                   help="run although key presses are stamped when polled, not when pressed "
                   "(no libjack, no ioHub keyboard); recorded in the session file")
    p.add_argument("--limit-trials", type=int, default=None, metavar="N",
                   help="only the first N main trials of the randomised order, each scene's "
                   "methods together so that they still pair (N rounded up to whole scenes; "
                   "tests, pilots). The protocol's practice trials come on top: add "
                   "--practice 0 for exactly these")
    p.add_argument("--practice", type=int, default=None, metavar="N",
                   help="practice trials (default: the protocol's)")
    m = p.add_argument_group("the operator's live view (docs/EXPERIMENT.md)")
    m.add_argument("--monitor", action="store_true",
                   help="also serve fovexp monitor's page for the results root while the run "
                        "lasts (http://127.0.0.1:8765/; a process of its own, at a lower "
                        "priority; needs fovexp[monitor])")
    m.add_argument("--monitor-host", default=None, metavar="HOST",
                   help="with --monitor: the address to serve, e.g. 0.0.0.0 for the lab's "
                        "network (a token is printed; every request needs it)")
    m.add_argument("--monitor-port", type=int, default=None, metavar="PORT",
                   help="with --monitor: the port (default 8765)")
    f = p.add_argument_group(
        "participant form (asked at the console at a participant's first session; every "
        "field optional; never in a dry run)")
    f.add_argument("--age", default=None, help="age in years")
    f.add_argument("--sex", default=None, help="female, male, other or undisclosed")
    f.add_argument("--vision", default=None,
                   help="vision correction: none, glasses, contact lenses or other")
    f.add_argument("--no-form", action="store_true", help="do not ask the form (recorded)")
    g = p.add_argument_group("simulated participant (--dry-run)")
    g.add_argument("--sim-truth", default=None, metavar="FILE|quick",
                   help="YAML ground truth (table, sk_slope, validation_blur_rate, noise_sd), "
                   "or 'quick': each trial confirmed two wheel steps from its start (a "
                   "rehearsal: a few renders per trial; its values mean nothing)")
    g.add_argument("--sim-noise-scale", type=float, default=1.0,
                   help="multiply the truth file's noise sd (0: noise-free)")
    g.add_argument("--sim-speed", type=float, default=4.0,
                   help="time compression of the participant's behaviour (default 4)")
    g.add_argument("--sim-seed", type=int, default=None, help="seed of the simulated participant")
    e = p.add_argument_group("simulated eye (--dry-run; docs/EXPERIMENT.md, \"Gaze truth\")")
    e.add_argument("--sim-gaze", default=None, metavar="PRESET[,SETTING=VALUE...]",
                   help="the simulated eye's behaviour: steady (default) or wandering "
                   "(saccades away, blinks, lost samples: a third of a trial blanked or more), "
                   "with single settings on top, e.g. wandering,blink_rate=0.3,"
                   "saccade_deg=2:6 (the settings of SimGazeParams)")
    e.add_argument("--gaze-latency-ms", type=float, default=None, metavar="MS",
                   help="the simulated tracker's delivery latency: each sample reaches the "
                   "runner MS after it was measured (its time stamps unchanged)")
    e.add_argument("--gaze-latency-jitter-ms", type=float, default=None, metavar="MS",
                   help="a normal jitter of the delivery latency, this sd (truncated at 0)")
    e.add_argument("--gaze-replay", type=Path, default=None, metavar="FILE",
                   help="drive the dry run from a recorded gaze: a fovexp gaze-<session>.csv, "
                   "or a CSV with time_s (or time_ms, time_us), x, y and optionally valid")
    e.add_argument("--gaze-replay-units", choices=("norm", "deg"), default="norm",
                   help="a plain CSV's x, y: normalised screen coordinates (x right, y down; "
                   "default) or degrees from the cross")
    e.add_argument("--gaze-replay-end", choices=("loop", "stop"), default="loop",
                   help="a replay shorter than the session: start it again (default), or stop "
                   "the session with one line")
    p.set_defaults(func=run_command)
    return p


def participant_form(args: argparse.Namespace, results_root: Path,
                     interactive: bool) -> tuple[dict[str, Any] | None, str | None]:
    """The participant form's answers and, when it was not asked, why (docs/EXPERIMENT.md):
    from the flags; else from this participant's earlier session in the results root (any
    experiment); else asked at the console when there is one. Never in a dry run or on
    resume (the session file has it)."""
    from .tasks.operator import FORM_FIELDS, ask_form, parse_form

    if args.dry_run:
        return None, "dry run"
    if args.resume:
        return None, "resume"  # the session keeps what its first start recorded
    given = {"age": args.age, "sex": args.sex, "vision_correction": args.vision}
    if any(v is not None for v in given.values()):
        return {**parse_form(given), "source": "command line"}, None
    if args.no_form:
        return None, "--no-form"
    import json

    for path in sorted(Path(results_root).glob(f"*/{args.participant}/session-*.json")):
        try:
            info = json.loads(path.read_text()).get("participant_info") or {}
        except (OSError, ValueError):
            continue
        if any(k in info for k in FORM_FIELDS):
            return ({**{k: info.get(k) for k in FORM_FIELDS},
                     "source": f"earlier session {path}"}, None)
    if not interactive:
        return None, "no terminal to ask at"
    print(f"Participant {args.participant}: first session. Optional details (Enter skips):",
          file=sys.stderr)
    try:
        answers = ask_form(input, lambda t: print(t, file=sys.stderr))
    except EOFError:  # Ctrl-D: the rest is skipped
        return None, "form closed at the console"
    return {**answers, "source": "form"}, None


def sim_gaze_params(args: argparse.Namespace, tracker: str, rate_hz: float) -> Any:
    """The simulated eye's :class:`~fovexp.experiment.trackers.simulated.SimGazeParams` from
    ``--sim-gaze`` and the latency flags, at the protocol's ``rate_hz`` unless the setting
    names one (None: the defaults); refused for any source but the simulated one."""
    import dataclasses

    from .trackers.simulated import parse_sim_gaze

    given = [f for f, v in (("--sim-gaze", args.sim_gaze),
                            ("--gaze-latency-ms", args.gaze_latency_ms),
                            ("--gaze-latency-jitter-ms", args.gaze_latency_jitter_ms),
                            ("--gaze-replay", args.gaze_replay))
             if v is not None]
    if not given:
        return None
    if tracker != SIMULATED_TRACKER:
        raise FovexpError(f"{', '.join(given)}: for the simulated eye (--dry-run), not "
                          f"--tracker {tracker}")
    params = parse_sim_gaze(args.sim_gaze or "steady")
    latency = {k: v for k, v in (("latency_ms", args.gaze_latency_ms),
                                 ("latency_jitter_ms", args.gaze_latency_jitter_ms))
               if v is not None}
    for k, v in latency.items():
        if not (v >= 0 and v < 10_000):
            raise FovexpError(f"--{k.replace('_', '-').replace('latency', 'gaze-latency')}: "
                              f"{v} is not a latency in ms (0 to 10000)")
    if "rate_hz=" not in (args.sim_gaze or ""):
        latency["rate_hz"] = rate_hz
    return dataclasses.replace(params, **latency)


def run_command(args: argparse.Namespace) -> int:
    """Validate everything, then run the session; errors print one line and return 2."""
    from .options import SessionOptions
    from .session import EXIT_ERROR, Session

    session = monitor = None
    try:
        from fovexp.stimuli.folder import DRY_RUN_SIZE

        from .protocol.spec import load_protocol
        from .records.participant_id import check_participant
        from .tasks.simulated_participant import SimTruth
        from .trackers import iohub_config_path

        check_participant(args.participant)
        if args.monitor or args.monitor_host or args.monitor_port is not None:
            from fovexp.monitor.cli import require_server

            require_server()  # a missing extra stops here, before anything is opened
        if args.limit_trials is not None and args.limit_trials < 1:
            raise FovexpError("--limit-trials must be at least 1")
        if args.practice is not None and args.practice < 0:
            raise FovexpError("--practice must be 0 or more")
        if args.sim_speed <= 0 or args.sim_noise_scale < 0:
            raise FovexpError("--sim-speed must be > 0 and --sim-noise-scale >= 0")
        if args.resume and args.new_session:
            raise FovexpError("--resume and --new-session exclude each other")
        tracker = args.tracker or (SIMULATED_TRACKER if args.dry_run else "tobii")
        if args.tracker_config is not None and tracker != "iohub":
            raise FovexpError("--tracker-config is for --tracker iohub")
        if args.screen < 0:
            raise FovexpError("--screen must be 0 or more")
        from .tasks.operator import parse_form

        parse_form({"age": args.age, "sex": args.sex, "vision_correction": args.vision})
        truth = SimTruth.named(args.sim_truth) if args.sim_truth else SimTruth()
        # dependencies come from the same results root; a participant's never from dry runs
        protocol = load_protocol(find_protocol(args.protocol), results_root=args.results,
                                 real_only=not args.dry_run and tracker != SIMULATED_TRACKER,
                                 stimuli=args.stimuli,
                                 include_pilots=args.include_pilots)
        sim_gaze = sim_gaze_params(args, tracker, protocol.spec.tracker.sampling_hz)
        if tracker == "iohub":  # a missing file said at once, not after the images are read
            config = iohub_config_path(protocol, args.tracker_config)
            if not config.is_file():
                raise FovexpError(f"{config}: no such ioHub configuration file")
        # Every image's sha256 and size, for the frames this run shows, before any window.
        frame_size = args.window or (DRY_RUN_SIZE if args.dry_run else protocol.native_size)
        images = protocol.prepare_images(frame_size, args.dry_run)
        if args.windowed or args.dry_run:  # a full-screen window is the display check's
            from .display.xscreen import check_window_fits, x_screen_size

            check_window_fits(frame_size, x_screen_size())
        scaled = sorted({(v.size, v.frame_size) for v in images.values() if v.scaled})
        if scaled:
            n = sum(v.scaled for v in images.values())
            sizes = ", ".join(f"{a[0]}x{a[1]}" for a, _ in scaled)
            print(f"fovexp run: dry run: {n} of {len(images)} images scaled from {sizes} to "
                  f"{frame_size[0]}x{frame_size[1]} (box filter; recorded in the session file)",
                  file=sys.stderr)
        opts = SessionOptions(
            participant=args.participant, results_root=args.results, tracker=tracker,
            dry_run=args.dry_run, resume=args.resume, new_session=args.new_session,
            limit_trials=args.limit_trials, practice_trials=args.practice,
            window_size=args.window or (DRY_RUN_SIZE if args.dry_run else None),
            fullscreen=not (args.windowed or args.dry_run),
            skip_display_check=args.skip_display_check, tracker_address=args.tracker_address,
            tracker_config=args.tracker_config,
            backend=args.backend, screen=args.screen,
            sim_truth=truth, sim_speed=args.sim_speed, sim_noise_scale=args.sim_noise_scale,
            sim_seed=args.sim_seed, sim_gaze=sim_gaze, accept_poll_keys=args.accept_poll_keys,
            gaze_replay=None if args.gaze_replay is None else (
                args.gaze_replay, args.gaze_replay_units, args.gaze_replay_end),
        )
        session = Session(protocol, opts)
        if not session.remaining:
            # Every trial was logged before the last run ended: no window, no tracker.
            session.finish_without_trials()
            print(f"fovexp run: session {session.session_id}: no trials left to run; marked "
                  "complete", file=sys.stderr)
            return 0
        # A tracker that is absent fails here, before any window opens.
        gaze = session.make_gaze()
        # The form last: nothing above can still refuse the session after it was filled in.
        opts.participant_info, opts.participant_info_note = participant_form(
            args, args.results, sys.stdin.isatty())
        print(f"fovexp run: {protocol.experiment}, participant {args.participant}, session "
              f"{session.session_id}, {len(session.remaining)} of {len(session.trials)} trials "
              f"to run -> {session.folder}", file=sys.stderr)
        if args.monitor or args.monitor_host or args.monitor_port is not None:
            from fovexp.monitor.cli import DEFAULT_PORT, start_beside

            monitor = start_beside(args.results, args.monitor_host,
                                   args.monitor_port if args.monitor_port is not None
                                   else DEFAULT_PORT)
        code = session.run(gaze=gaze)
    except FovexpError as exc:
        print(f"fovexp run: error: {exc}", file=sys.stderr)
        return EXIT_ERROR
    except Exception as exc:  # never a traceback for the operator (Session.run logs it)
        print(f"fovexp run: error: {type(exc).__name__}: {exc}", file=sys.stderr)
        return EXIT_ERROR
    finally:
        if session is not None:  # a session that never started leaves no empty folder
            session.release()
        if monitor is not None:
            from fovexp.monitor.cli import stop_beside

            stop_beside(monitor)
    messages = {0: "finished", 3: "aborted by the operator; continue with --resume",
                130: "interrupted; continue with --resume"}
    print(f"fovexp run: session {session.session_id} {messages.get(code, code)}", file=sys.stderr)
    return code


def add_tracker_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add the ``tracker`` command (its one subcommand: ``example``)."""
    p = subparsers.add_parser(
        "tracker", help="example ioHub configurations of the eye-tracker families",
        description="The eye trackers of --tracker iohub (docs/EXPERIMENT.md, \"Eye trackers\").")
    sub = p.add_subparsers(dest="tracker_command", required=True, parser_class=type(p))
    e = sub.add_parser(
        "example", help="print the example ioHub configuration of a tracker family",
        description="Print the shipped example ioHub configuration of a tracker family (the "
        "YAML --tracker-config reads), to save, edit (the tracker's address, model, rate, "
        "eyes) and pass to --tracker iohub --tracker-config FILE; without FAMILY, list the "
        "families. --tracker-config example:FAMILY reads an example as it is.")
    e.add_argument("family", nargs="?", default=None, metavar="FAMILY",
                   help="eyelink, tobii, gazepoint, pupil-labs, eyelogic or mousegaze")
    e.set_defaults(func=tracker_example_command)
    return p


def tracker_example_command(args: argparse.Namespace) -> int:
    """The example of ``args.family`` on stdout (``> lab/eyelink.yaml``), or the families (key,
    label, device class path, what installs the plugin); an unknown family is one line naming
    them (exit 2)."""
    from .trackers.families import FAMILIES, example_path

    if args.family is None:
        for fam in FAMILIES:
            print(f"{fam.key:<11} {fam.label}: {fam.device_class} ({fam.install})")
        return 0
    try:
        path = example_path(args.family)
    except FovexpError as exc:
        print(f"fovexp tracker example: error: {exc}", file=sys.stderr)
        return 2
    sys.stdout.write(path.read_text(encoding="utf-8"))
    return 0
