"""A session: one participant's run of one protocol, from the plan to the last trial's row.

:meth:`Session.run` orchestrates the parts, each its own module and testable without a window:

- :mod:`.lock`: one run at a time in the participant's folder;
- :mod:`.resume`: a new session or the incomplete one it continues, the trials already logged,
  the attempts begun;
- :mod:`.sessionfile`: the session file, written off the frame loop by its own thread;
- :mod:`.tracker_setup`: the tracker's display area, calibration, validation, drift checks;
- :mod:`.sequence`: the announcements and breaks around the trials, the console's position;
- :mod:`.render_budget`: whether the renderer shows a wheel step within the protocol's budget;
- :mod:`.frameloop`: the frames of one attempt at a trial (paper section 5.1, "Task": the
  reference's left half on the left, the mirrored half processed with the current value on
  the right, a fixation cross on the seam; the wheel changes the value, Enter confirms;
  whenever the gaze leaves the 1.25 deg window around the cross, or is invalid or lost, the
  next frame is black);
- :mod:`.rows`: the trial, gaze and blanking logs' rows;
- :mod:`.operator`: the operator's console line and checklist;
- :mod:`.live`: the live status file ``fovexp monitor`` reads (its own thread; the display
  thread only queues the rows it gives the frame and gaze logs).

The window is a :class:`~fovexp.experiment.interfaces.Screen` (``window.PsychoScreen``), the
gaze a :class:`~fovexp.experiment.interfaces.GazeSource`. Between trials the screen shows the
cross alone from the first flip after Enter until the next trial's stimulus (or a message).
File writes stay off the frame loop: the gaze, frame and blanking logs are written by their
flusher thread, events go to the session file through its writer thread, and the trial row
(the commit point) is written after the black frame.
"""

from __future__ import annotations

import signal
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from fovexp import FovexpError
from fovexp.results.format import SIMULATED_TRACKER
from fovexp.results.rigcheck import session_rig_record

from .calibration import QUIT_KEYS, QUIT_PROMPT, QUIT_QUESTION, CalibrationTiming
from .diskspace import check_space, disk_full_message, estimate_log_bytes, is_disk_full
from .frameloop import LateLatch, TrialIO, TrialLoop, display_thread_first
from .gaze import BlankingMonitor, FixationGeometry
from .interfaces import GazeSource, Renderer, Screen, ScreenFactory
from .live import LivePublisher
from .lock import LOCK_FILE, FolderLock
from .logs import (
    BLANKING_COLUMNS,
    FRAME_COLUMNS,
    GAZE_COLUMNS,
    BatchLog,
    PeriodicFlusher,
    TrialLog,
)
from .operator import DISPLAY_CHECKLIST, checklist_text, eta_s, trial_line
from .participant import SimTruth, SimulatedParticipant
from .protocol import LoadedProtocol, Trial
from .render_budget import step_result, step_values, step_warning, time_renders
from .resume import attempts_so_far, choose_session, done_trials, find_sessions, new_session_id
from .rows import GazeItem, blanking_rows, gaze_items, gaze_row, trial_row
from .sequence import TrialSequence
from .sessionfile import (
    SessionFile,
    new_record,
    now_iso,
    participant_entry,
    run_entry,
    software_version,
    versions,
)
from .stimuli import load_stimulus, split_screen
from .tracker_setup import (
    Aborted,
    TrackerSetup,
    calibration_timing,
    display_area,
    window_ppd,
)
from .trackers import iohub_config_path, make_gaze_source
from .trackers.simulated import SimGazeParams
from .trial import Key, TrialState, ValueAdjuster
from .validation import check_participant

if TYPE_CHECKING:
    from fovexp import EnhanceParams

EXIT_OK = 0
EXIT_ERROR = 2
EXIT_ABORTED = 3
EXIT_INTERRUPTED = 130
#: the quit key's confirmation screen
QUIT_TEXT = f"{QUIT_QUESTION}\n\n{QUIT_PROMPT}"


@dataclass
class SessionOptions:
    """Everything the CLI decides (docs/EXPERIMENT.md lists the flags)."""

    participant: str
    results_root: Path = Path("results")
    tracker: str = "tobii"  # tobii / simulated / mouse
    dry_run: bool = False
    resume: bool = False
    new_session: bool = False
    limit_trials: int | None = None
    practice_trials: int | None = None
    window_size: tuple[int, int] | None = None
    fullscreen: bool = True
    skip_display_check: bool = False
    tracker_address: str | None = None
    #: ``--tracker iohub``: the ioHub configuration (default: the protocol's
    #: ``tracker.iohub_config``)
    tracker_config: Path | None = None
    #: enhancer backend: auto (a hardware GPU if there is one), cpu or gpu
    backend: str = "auto"
    #: the monitor of a multi-monitor rig (PsychoPy's ``screen``)
    screen: int = 0
    #: the participant form (age, sex, vision correction; each may be None), or None when it
    #: was not asked (dry runs, no terminal, --no-form); recorded at the first start
    participant_info: dict[str, Any] | None = None
    #: why the form was not asked, recorded instead of it
    participant_info_note: str | None = None
    #: where the per-trial console line and warnings go (default: stderr)
    console: Callable[[str], None] | None = None
    sim_truth: SimTruth = field(default_factory=SimTruth)
    sim_speed: float = 4.0
    sim_noise_scale: float = 1.0
    sim_seed: int | None = None
    sim_gaze: SimGazeParams | None = None
    #: seconds of each instruction/break screen in a dry run (no key presses there)
    dry_message_s: float = 0.2
    #: the calibration screens' durations (default Titta's; a dry run's are shorter)
    calibration_timing: CalibrationTiming | None = None


class Interrupted(Exception):
    """SIGINT/SIGTERM: stop at once; progress is saved."""


class Session:
    """One participant's run of one protocol (see the module docstring)."""

    def __init__(self, protocol: LoadedProtocol, opts: SessionOptions) -> None:
        from fovexp import load_display

        self.protocol = protocol
        self.opts = opts
        self.participant = check_participant(opts.participant)
        if opts.dry_run and opts.tracker not in ("simulated", "iohub"):
            raise FovexpError("--dry-run uses simulated gaze: leave out --tracker or use "
                              "--tracker simulated (or --tracker iohub, to test an ioHub "
                              "configuration)")
        self.display = load_display(protocol.display_name)
        # Every image checked for the frames this session shows, before anything is written:
        # a real session refuses any size but the window's (the display's own, unless
        # --window), a dry run scales (recorded in the session file's "stimuli").
        self.frame_size = tuple(opts.window_size or protocol.native_size)
        self.images = protocol.prepare_images(self.frame_size, opts.dry_run)
        self.stimuli_record = protocol.stimuli_record()
        self.folder = Path(opts.results_root) / protocol.experiment / self.participant
        self._lock: FolderLock | None = FolderLock(
            self.folder, f"participant {self.participant}, {protocol.experiment}",
            opts.results_root)
        try:
            self.fixation = FixationGeometry(self.display)
            self._prepare_session()
        except BaseException:
            self.release()
            raise
        self.gaze: GazeSource | None = None
        self.screen: Screen | None = None
        self.renderer: Renderer | None = None
        self.tracker: TrackerSetup | None = None
        self.sim: SimulatedParticipant | None = None
        self.refresh_hz: float = float(self.display.refresh_hz)
        self.latch: LateLatch | None = None  # made with the window (its refresh rate)
        self._trial_seconds: list[float] = []  # this run's trial durations (the console's ETA)
        self._operator_notes: list[str] = []  # shown with the instructions (backend, budget)
        self._seq: TrialSequence | None = None  # the run's (set by _trials)
        spec = protocol.spec
        self.live = LivePublisher(self.folder, self.session_id, {
            "participant": self.participant, "experiment": protocol.experiment,
            "protocol_path": str(protocol.path), "protocol_title": spec.title,
            "protocol_sha256": protocol.sha256, "dry_run": opts.dry_run,
            "radius_deg": spec.fixation.radius_deg,
            "gaze_timeout_s": spec.fixation.gaze_timeout_s, "break_every": spec.break_every,
            "n_trials": len(self.trials)}, self.fixation)

    def release(self) -> None:
        """Let go of the folder's lock; a folder this run created and wrote nothing to (a
        missing tracker, a failed display check) is removed again (:mod:`.lock`)."""
        lock, self._lock = getattr(self, "_lock", None), None
        if lock is not None:
            lock.release()

    # -- plan and resume (no window) -----------------------------------------------------------
    def _prepare_session(self) -> None:
        opts, proto = self.opts, self.protocol
        choice = choose_session(
            self.folder, proto, self.participant, resume=opts.resume,
            new_session=opts.new_session, dry_run=opts.dry_run, tracker=opts.tracker,
            limit_trials=opts.limit_trials, practice_trials=opts.practice_trials)
        self.session_id = choice.session_id
        self.limit, self.practice = choice.limit_trials, choice.practice_trials
        self.file = SessionFile(self.folder / f"session-{self.session_id}.json", choice.info)
        self.seed, self.trials = proto.plan(self.participant, self.limit, self.practice)
        self.done = done_trials(self.folder / "trials.csv", self.session_id)
        self.remaining = [t for t in self.trials if t.index not in self.done]
        #: attempts begun per trial (all runs): a resumed session numbers on from these
        self.attempts = attempts_so_far(self.folder, self.session_id, self.info)

    @property
    def info(self) -> dict[str, Any]:
        """The session file's record (:class:`.sessionfile.SessionFile`)."""
        return self.file.info

    def finish_without_trials(self) -> None:
        """Nothing left to run (all trials logged before the last run ended): mark the session
        complete, without opening a window or a tracker."""
        self.file.update(state="completed", completed=True, ended=now_iso(),
                         n_completed=len(self.done))
        self.release()

    def _start_info(self) -> None:
        """This run's entry in the session file (a new session's record first)."""
        proto, opts = self.protocol, self.opts
        run = run_entry(dry_run=opts.dry_run, tracker=opts.tracker,
                        remaining_trials=len(self.remaining), screen=opts.screen)
        info = self.info
        if not info:
            info.update(new_record(
                session_id=self.session_id, participant=self.participant, protocol=proto,
                display=self.display, seed=self.seed, limit_trials=self.limit,
                practice_trials=self.practice, n_trials=len(self.trials),
                started=run["started"]))
        if "participant_info" not in info:  # asked at the first start; resume keeps it
            info["participant_info"] = participant_entry(
                opts.participant_info, opts.participant_info_note, opts.dry_run, run["started"])
        info["runs"].append(run)
        info["stimuli"] = self.stimuli_record
        info["versions"] = versions()
        if opts.dry_run:
            info["simulated_participant"] = {
                "truth": opts.sim_truth.model_dump(), "speed": opts.sim_speed,
                "noise_scale": opts.sim_noise_scale, "seed": self._sim_seed()}
        self.file.update(state="running", completed=False)

    def _sim_seed(self) -> int:
        return self.opts.sim_seed if self.opts.sim_seed is not None else self.seed

    # -- gaze ----------------------------------------------------------------------------------
    def make_gaze(self) -> GazeSource:
        """The gaze source (:func:`fovexp.experiment.trackers.make_gaze_source`); ``--tracker
        tobii`` or ``iohub`` fails here, before a window opens. A resumed run's simulated eyes
        get fresh noise (another seed) but stay reproducible."""
        n_runs = len(self.info.get("runs", [])) if self.info else 0
        return make_gaze_source(
            self.opts.tracker, protocol=self.protocol, display=self.display,
            fixation=self.fixation, dry_run=self.opts.dry_run, screen=self.opts.screen,
            tracker_address=self.opts.tracker_address, tracker_config=self.opts.tracker_config,
            sim_seed=self._sim_seed() + 7919 * n_runs, sim_params=self.opts.sim_gaze)

    def iohub_config_path(self) -> Path:
        """The ioHub configuration this session's ``--tracker iohub`` reads
        (:func:`fovexp.experiment.trackers.iohub_config_path`)."""
        return iohub_config_path(self.protocol, self.opts.tracker_config)

    def _gaze_row(self, item: GazeItem) -> tuple[Any, ...]:
        """A gaze log row (made on the log's flusher thread)."""
        return gaze_row(self.fixation, item)

    def _drain_gaze(self) -> None:
        """Samples that arrived outside a trial's frame loop, into the gaze log (trial empty)."""
        self.gaze_log.extend(gaze_items(None, self.gaze.poll()))

    # -- the run -------------------------------------------------------------------------------
    def _say(self, line: str) -> None:
        """A line for the operator's console."""
        (self.opts.console or (lambda t: print(t, file=sys.stderr, flush=True)))(line)

    def run(self, screen_factory: ScreenFactory | None = None,
            gaze: GazeSource | None = None) -> int:
        """Run the remaining trials; returns an exit status (0 done, 3 aborted, 130 killed).

        The order: the gaze source and the tracker's display area, the window and its display
        check (a failure in any of these writes nothing), the session file, the logs, the
        renderer, the tracker's stream, the display checklist, the render budget, the
        tracker's set-up, the instructions, the trials; whatever happens, the logs and the
        session file are closed with the run's state."""
        if not self.remaining:
            if not self.info.get("completed"):
                self.finish_without_trials()
            return EXIT_OK
        try:
            space = self._check_space()
            self.gaze = gaze if gaze is not None else self.make_gaze()
            # the tracker's display area against the profile: before any window opens
            self.area, area_info = display_area(self.gaze, self.display,
                                                self.protocol.display_name)
            self.screen = self._open_screen(screen_factory)
            check = self._check_display()
        except BaseException:
            self.release()
            raise
        # a source that needs the window: its place on the screen, or its pointer
        attach = getattr(self.gaze, "attach", None)
        if attach is not None:
            attach(self.screen)
        try:
            self._start_info()
            self.file.start_writer()
            self.file.set_in_run("results_disk", space, write=False)
            self.file.update(display_check={**check, "screen": self.opts.screen},
                             display_area=area_info)
            self._open_logs()
        except BaseException as exc:
            self.file.stop_writer()
            for closer in (self.gaze.stop, self.screen.close):
                try:
                    closer()
                except Exception:  # the error to report is the one above
                    pass
            self.release()
            if is_disk_full(exc):
                raise FovexpError(self._disk_full_message()) from None
            raise
        #: when each frame reads the gaze (one latch for the run: its margin carries over)
        self.latch = LateLatch(1.0 / self.refresh_hz)
        self._start_live()
        flusher = PeriodicFlusher([self.gaze_log, self.frame_log, self.blank_log]).start()
        self._flusher = flusher
        old_handlers = self._install_signals()
        state, code, failure = "interrupted", EXIT_INTERRUPTED, None
        try:
            self._start_renderer()
            self.gaze.start()
            self.file.update(tracker=self.gaze.info())
            if self.opts.dry_run:
                self.sim = SimulatedParticipant(self.opts.sim_truth, self._sim_seed() + 1,
                                                self.opts.sim_speed, self.opts.sim_noise_scale)
            self.tracker = self._make_tracker_setup()
            self._display_setup()
            self._check_keyboard()
            self._check_rig()
            self._check_render_budget()
            self.live.set_state("calibrating")
            self.tracker.setup()
            self.live.tracker_quality(self.info.get("tracker_quality"))
            self._instructions()
            with display_thread_first() as priority:
                latch = self.latch
                assert latch is not None
                self.file.set_in_run("display_thread", {**priority,
                                                        "late_latch": latch.info()},
                                     write=False)
                try:
                    self._trials()
                finally:
                    self.file.set_in_run("display_thread", {**priority,
                                                            "late_latch": latch.info()},
                                         write=False)
            state, code = "completed", EXIT_OK
            self._message("Thank you - this part is finished.", ["space", "return"], 3.0)
        except Aborted:
            state, code = "aborted", EXIT_ABORTED
        except Interrupted:
            state, code = "interrupted", EXIT_INTERRUPTED
        except FovexpError as exc:
            state, failure = "failed", str(exc)
            raise
        except Exception as exc:  # a bug: recorded with its traceback, reported in one line
            if is_disk_full(exc):  # not a bug: one line, what to do
                state, failure = "failed", self._disk_full_message()
                raise FovexpError(failure) from None
            import traceback

            state, failure = "failed", f"{type(exc).__name__}: {exc}"
            self.info["failure_traceback"] = traceback.format_exc()
            raise FovexpError(f"internal error: {failure} (traceback in "
                              f"{self.file.path})") from None
        finally:
            self._restore_signals(old_handlers)
            self._close(flusher, state, failure)
        return code

    def _open_screen(self, screen_factory: ScreenFactory | None) -> Screen:
        """The window (the display's size unless ``--window``; fullscreen unless a dry run)."""
        if screen_factory is None:
            from .window import PsychoScreen

            screen_factory = PsychoScreen
        size = self.opts.window_size or (self.display.width_px, self.display.height_px)
        return screen_factory(
            size=size, fullscreen=self.opts.fullscreen and not self.opts.dry_run,
            cross_px=self._cross_px(size), dry_run=self.opts.dry_run,
            refresh_hz=self.display.refresh_hz, screen=self.opts.screen)

    def _open_logs(self) -> None:
        sid = self.session_id
        self.trial_log = TrialLog(self.folder / "trials.csv")
        self.gaze_log = BatchLog(self.folder / f"gaze-{sid}.csv", GAZE_COLUMNS,
                                 formatter=self._gaze_row)
        self.frame_log = BatchLog(self.folder / f"frames-{sid}.csv", FRAME_COLUMNS)
        self.blank_log = BatchLog(self.folder / f"blanking-{sid}.csv", BLANKING_COLUMNS)

    def _start_live(self) -> None:
        """The live status file (:mod:`.live`) from now on, fed by the frame and gaze logs'
        taps (until then :attr:`live` only keeps what it is told)."""
        self.live.header.update(tracker_name=self.gaze.name, refresh_hz=self.refresh_hz,
                                remaining=len(self.remaining))
        self.live.start()
        self.gaze_log.tap = self.live.gaze
        self.frame_log.tap = self.live.frames

    def _start_renderer(self) -> None:
        from .render import TestRenderer

        share = getattr(self.screen, "gl_share", None)
        spec = self.protocol.spec
        self.renderer = TestRenderer(
            self.display, spec.preset, spec.geometry_model, self.opts.backend,
            gl_share=share() if share is not None and self.opts.backend != "cpu" else None)
        self.file.update(render=self.renderer.info())

    def _make_tracker_setup(self) -> TrackerSetup:
        return TrackerSetup(
            gaze=self.gaze, screen=self.screen, protocol_spec=self.protocol.spec,
            area=self.area, distance_mm=10.0 * self.display.distance_cm, ppd_px=self._ppd_px(),
            timing=calibration_timing(self.opts.calibration_timing, self.opts.dry_run),
            auto=self.opts.dry_run, seed=self.seed, file=self.file,
            gaze_sink=lambda samples: self.gaze_log.extend(gaze_items(None, samples)))

    def _close(self, flusher: PeriodicFlusher, state: str, failure: str | None) -> None:
        """The end of a run, however it ends: the tracker stops, then what its buffer still
        holds (the last screen's samples) goes into the gaze log before the final flush; the
        renderer lets go of the window's shared GL context before the window closes; the
        session file gets the run's state; the folder's lock is let go."""
        for step in (self.gaze.stop, self._drain_gaze):
            try:
                step()
            except Exception:  # closing after an error must not hide the error
                pass
        flusher.stop()
        # the last rows (the closing screens' samples) not written: said, never silent
        late = flusher.error if failure is None else None
        for closer in (getattr(self.renderer, "close", None),
                       getattr(self.screen, "close", None)):
            if closer is not None:
                try:
                    closer()
                except Exception:  # closing after an error must not hide the error
                    pass
        done = {int(r["trial_index"]) for r in self.trial_log.rows
                if r["session"] == self.session_id}
        complete = state == "completed" and len(done) == len(self.trials)
        self.live.stop(state if complete or state != "completed" else "incomplete")
        extra: dict[str, Any] = {"failure": failure} if failure is not None else {}
        measured = getattr(self.gaze, "measured", None)  # the sampling rate over the run
        if measured is not None and "tracker" in self.info:
            extra["tracker"] = {**self.info["tracker"], "measured": measured()}
        if late is not None:
            extra["log_error"] = f"{late.filename}: {late.strerror}"
        self.file.stop_writer()  # the events it had still to write are in the final write
        try:
            self.file.update(state=state if not (state == "completed" and not complete)
                             else "incomplete", completed=complete, ended=now_iso(),
                             n_completed=len(done), events=self.info.get("events", []),
                             **extra)
        except OSError as exc:
            # a full disk keeps the session file as last written (valid JSON, "running": it
            # resumes); the run's own error, if any, is the one to report
            if not is_disk_full(exc):
                raise
            if failure is None:
                raise FovexpError(self._disk_full_message()) from None
        finally:
            self.release()
        if late is not None:
            raise FovexpError(self._disk_full_message() if is_disk_full(late) else
                              f"cannot write {late.filename}: {late.strerror}")

    # -- the results disk ----------------------------------------------------------------------
    def _check_space(self) -> dict[str, Any]:
        """Before anything is written: the results disk's free space against this run's
        estimated logs (:mod:`.diskspace`); refuses with both figures when they cannot fit."""
        estimate = estimate_log_bytes(len(self.remaining),
                                      self.protocol.spec.tracker.sampling_hz,
                                      float(self.display.refresh_hz))
        return check_space(self.folder, estimate)

    def _resume_command(self) -> str:
        """The command that continues this session."""
        opts = self.opts
        parts = ["fovexp run", str(self.protocol.path), "--participant", self.participant]
        if Path(opts.results_root) != Path("results"):
            parts += ["--results", str(opts.results_root)]
        if opts.dry_run:
            parts.append("--dry-run")
        return " ".join(parts + ["--resume"])

    def _disk_full_message(self) -> str:
        return disk_full_message(Path(self.opts.results_root), self._resume_command())

    def _raise_log_error(self) -> None:
        """A log the flusher thread could not write (a full disk) stops the session here,
        between trials, with that error."""
        flusher = getattr(self, "_flusher", None)
        if flusher is not None and flusher.error is not None:
            raise flusher.error

    def _display_setup(self) -> None:
        """The operator confirms the display checklist (docs/EXPERIMENT.md) with C; recorded
        per run. A dry run records it as skipped."""
        if self.opts.dry_run:
            entry: dict[str, Any] = {"skipped": "dry run"}
        else:
            self._message(checklist_text(), ["c"], None)
            entry = {"confirmed": True, "time": now_iso(), "items": list(DISPLAY_CHECKLIST)}
        self.file.set_in_run("display_setup", entry)

    def _check_rig(self) -> None:
        """The newest rig check under the results root (``fovexp rig check``): its name and
        sha256 in this run's entry (``runs[].rig_check``); a warning for the operator when
        there is none from today, it failed, or it was only a dry run."""
        rec, warning = session_rig_record(self.opts.results_root, now_iso()[:10],
                                          self.opts.dry_run)
        self.file.set_in_run("rig_check", rec)
        if warning is not None and not self.opts.dry_run:
            self._operator_note(warning, "rig_check_warning", warning=warning)

    def _check_keyboard(self) -> None:
        """Record the window's keyboard (its backend, and whether keys carry the time they went
        down); warn when they do not: then an answer is the value on screen at the poll that
        saw Enter, up to a frame later than the press (a dry run's simulated participant
        answers at the poll anyway)."""
        info = self.screen.info()
        self.file.set_in_run("window", info)
        kb = info.get("keyboard") or {}
        if kb.get("key_time") != "press" and not self.opts.dry_run:
            self._operator_note(
                f"key presses are stamped when polled, not when pressed (keyboard backend "
                f"{kb.get('backend')!r}): install psychtoolbox's libjack (Debian/Ubuntu: "
                "apt-get install libjack-jackd2-0) or run an ioHub server",
                "keyboard_stamps_at_poll", backend=kb.get("backend"))

    def _check_render_budget(self) -> None:
        """Warn when the backend cannot show a wheel step within the protocol's budget
        (``render.max_step_ms``), measured on the first remaining trial's image (a warm-up
        render, then one wheel step), and when ``auto`` fell back to the CPU: on the console,
        in the session file, and with the instructions. Never stops the session."""
        spec = self.protocol.spec
        info = self.renderer.info()
        if info.get("fallback"):
            self._operator_note(f"enhancer on the CPU: {info['fallback']}", "backend_fallback",
                                reason=info["fallback"])
        for note in info.get("notes") or []:
            self._operator_note(note, "render_note", note=note)
        trial = self.remaining[0]
        frame = self._load_frame(trial)
        w = frame.shape[1]
        self.renderer.set_image(frame[:, w // 2:], (w, frame.shape[0]))
        adj = spec.adjust

        def cross_alone() -> None:
            self.screen.draw(blank=True)
            self._drain_gaze()

        first_s, step_s = time_renders(
            self.renderer, [self._params(trial, v) for v in step_values(
                trial.start_value, adj.step, adj.range[1])], cross_alone)
        budget = spec.render.max_step_ms
        result = step_result(adj.parameter, first_s, step_s, budget)
        self.file.update(render={**info, "wheel_step": result})
        warning = step_warning(adj.parameter, step_s, budget, info["backend"])
        if warning is not None:
            self._operator_note(warning, "render_budget_exceeded", **result)

    def _operator_note(self, text: str, event: str, **detail: Any) -> None:
        """A warning for the operator: console, session file (event), instruction screen."""
        self._say(f"fovexp run: warning: {text}")
        self._operator_notes.append(text)
        self.file.event(event, **detail)

    def _check_display(self) -> dict[str, Any]:
        """Measured refresh rate and window size against the profile (closes the window and
        raises on a mismatch unless ``--skip-display-check``); sets :attr:`refresh_hz`, the rate
        dropped frames are counted against: the measured one where there is one."""
        from .window import check_display

        self.refresh_hz = float(getattr(self.screen, "refresh_hz", self.display.refresh_hz))
        if self.opts.dry_run:
            return {"skipped": True, "reason": "dry run", "refresh_hz": self.refresh_hz}
        measured, size, fb = self.screen.measure_display()
        if measured is not None:
            self.refresh_hz = measured
        if self.opts.skip_display_check:
            return {"skipped": True, "reason": "--skip-display-check", "measured_refresh_hz":
                    measured, "window_size": size, "framebuffer_size": fb,
                    "refresh_hz": self.refresh_hz}
        try:
            return check_display(measured, size, fb, self.display)
        except FovexpError:
            self.screen.close()
            raise

    def _cross_px(self, size: tuple[int, int]) -> float:
        """Cross size in window pixels from the protocol's degrees at the screen centre."""
        ppd = self.fixation.ppd_centre * size[0] / self.display.width_px
        return max(7.0, self.protocol.spec.fixation.cross_size_deg * ppd)

    def _install_signals(self) -> dict[int, Any]:
        def handler(signum: int, frame: Any) -> None:
            raise Interrupted(f"signal {signum}")

        old = {}
        for sig in (signal.SIGINT, signal.SIGTERM):
            try:
                old[sig] = signal.signal(sig, handler)
            except ValueError:  # not the main thread (tests): leave signals alone
                pass
        return old

    def _restore_signals(self, old: dict[int, Any]) -> None:
        for sig, h in old.items():
            signal.signal(sig, h)

    def _message(self, text: str, keys: list[str], timeout_s: float | None = None,
                 state: str = "message") -> str | None:
        """A message screen; the gaze stream keeps going into the gaze log meanwhile (a long
        break would otherwise overflow the tracker's buffer). Escape or Q (where Q is not one of
        the message's own keys) asks to quit (:meth:`confirm_quit`); going back shows the
        message again."""
        if self.opts.dry_run:
            timeout_s = self.opts.dry_message_s
        self.live.set_state(state, text)
        quit_keys = [k for k in QUIT_KEYS if k not in keys]
        while True:
            key = self.screen.message(text, [*keys, *quit_keys], timeout_s, self._drain_gaze)
            if key not in quit_keys:
                return key
            self.confirm_quit()

    def confirm_quit(self, trial_index: int | None = None) -> None:
        """The quit keys' confirmation, for every screen (trials go through their pause
        screen): Y quits, keeping everything logged (raises :class:`Aborted`); N or Escape
        goes back. The calibration
        screens ask the same (:data:`fovexp.experiment.calibration.QUIT_QUESTION`)."""
        key = self.screen.message(QUIT_TEXT, ["y", "n", "escape"], None, self._drain_gaze)
        if key == "y":
            self.file.event("aborted", trial_index=trial_index)
            raise Aborted()

    def _ppd_px(self) -> float:
        """Window pixels per degree at the screen centre."""
        return window_ppd(self.fixation, self.display, self.screen.size[0])

    # -- instructions, practice, trials, breaks --------------------------------------------------
    def _instructions(self) -> None:
        text = self.protocol.spec.instructions.strip() or "Adjust the right half to match the left."
        resumed = " (continuing where the last session stopped)" if self.done else ""
        notes = "".join(f"\n\nOperator: {n}" for n in self._operator_notes)
        self._message(f"{self.protocol.spec.title}{resumed}\n\n{text}\n\nPress Space to start."
                      f"{notes}", ["space"])

    def _trials(self) -> None:
        """The run's trials in order (:class:`.sequence.TrialSequence`: announcements and
        breaks); each until an attempt is confirmed; after each, the tracker's checks."""
        seq = self._seq = TrialSequence(self.trials, self.remaining, self.done,
                                        self.protocol.spec.break_every)
        for trial in self.remaining:
            self._raise_log_error()
            for text in seq.before(trial):
                self._message(text, ["space"])
            t0 = time.monotonic()
            self._attempts_until_done(trial)
            self._trial_seconds.append(time.monotonic() - t0)
            left = seq.left_after(trial)
            self._console_line(trial, seq, left)
            # breaks at the same places of the plan whatever runs it took (resume)
            pause = seq.after(trial)
            if pause is not None:
                self._message(pause, ["space"], state="break")
            # drift check / recalibration (D, C, every N)
            self.live.set_state("between trials")
            self.tracker.between_trials(trial, more_trials=left > 0)
            self.live.tracker_quality(self.info.get("tracker_quality"))

    def _attempts_until_done(self, trial: Trial) -> None:
        """Attempts at ``trial`` until one is confirmed: a pause or a lost tracker restarts it
        (the next attempt); Q on the pause screen quits (:class:`Aborted`)."""
        while True:
            attempt = self.attempts.get(trial.index, 0)
            self.attempts[trial.index] = attempt + 1
            # on disk before its first frame: a resumed session numbers on from it
            self.file.update(attempts={str(k): v for k, v in self.attempts.items()})
            outcome = self._run_trial(trial, attempt)
            if outcome == "done":
                return
            if outcome == "pause":
                self.file.event("paused", trial_index=trial.index)
                self.live.set_state("paused")
                # Waits for the operator even in a dry run (no auto-continue).
                key = self.screen.message(
                    "Paused.\n\nSpace: continue (this trial starts again)\n"
                    "Q: quit - progress is saved; continue later with --resume",
                    ["space", "q"], None, self._drain_gaze)
                if key == "q":
                    self.file.event("aborted", trial_index=trial.index)
                    raise Aborted()
            elif outcome == "disconnected":
                self._wait_reconnect(trial)

    def _console_line(self, trial: Trial, seq: TrialSequence, left: int) -> None:
        """trial i/N, blanked %, dropped frames, gaze-to-flip latency, ETA (docs/EXPERIMENT.md)."""
        st = self._last_state
        position, total = seq.position(trial)
        eta = eta_s(self._trial_seconds, left)
        self.live.set_eta(eta)
        self._say(trial_line(position=position, total=total, practice=trial.practice,
                             blanked_fraction=st.blanking.fraction, dropped=st.timer.dropped,
                             frames=st.n_frames,
                             latency_ms=np.array(self._last_latency_ms, dtype=float),
                             eta_s=eta))

    def _wait_reconnect(self, trial: Trial) -> None:
        """Tracker lost mid-session: screen blanked, a message, wait; Q quits (saved)."""
        self.file.event("tracker_disconnected", trial_index=trial.index)
        self.live.set_state("disconnected")
        text = ("The eye tracker connection was lost. The trial will start again when it is "
                "back.\n\nQ: quit (progress is saved; continue later with --resume)")
        while not self.gaze.connected:
            # The stream is drained here too: a stalled tracker counts as back only when its
            # samples arrive again (and they belong in the gaze log, between trials).
            self._drain_gaze()
            for ev in self.gaze.poll_events():
                self.file.event(ev.kind, **ev.detail)
            key = self.screen.message(text, ["q", "escape"], 0.1, self._drain_gaze)
            if key is not None:
                self.confirm_quit(trial.index)
        self.file.event("tracker_reconnected", trial_index=trial.index)
        self.live.event("tracker_reconnected")

    def _params(self, trial: Trial, value: float) -> EnhanceParams:
        return self.protocol.make_params(trial, value, self.seed)

    def _load_frame(self, trial: Trial) -> np.ndarray:
        img = self.images[trial.image]
        # a dry run may scale (checked and recorded); a real session's sizes were checked
        return split_screen(load_stimulus(img.path, self.screen.size, scale=img.scaled))

    def _run_trial(self, trial: Trial, attempt: int = 0) -> str:
        """One attempt at a trial; returns ``done``, ``pause`` or ``disconnected``.

        What is logged is what was on screen: each frame's value is that of the render shown
        in it, and ``final_value`` is the value on screen when Enter was pressed (a render still
        pending then is dropped, never shown). Every frame goes to the frame log as it is shown
        and every attempt's blanking episodes to the blanking log, however the attempt ends (an
        interrupted one included), tagged with ``attempt``. From the first flip after the
        attempt ends the cross is alone on screen; the logs are synced and the trial's row
        written (the commit point) after it.
        """
        loop, st = self._trial_loop(trial, attempt)
        position, total = (self._seq.position(trial) if self._seq is not None
                           else (None, None))
        adj = self.protocol.spec.adjust
        self.live.begin_attempt(trial.index, attempt, position=position, total=total,
                                practice=trial.practice, method=trial.method,
                                image=trial.image, parameter=adj.parameter,
                                blur_rate=trial.blur_rate, start_value=trial.start_value)
        outcome = "error"
        try:
            loop.show_first()
            outcome = loop.run()
        finally:
            st.finish(time.monotonic())  # when the loop could not flip its closing frame
            self.blank_log.extend(blanking_rows(trial.index, attempt, st.blanking.episodes))
            self.live.end_attempt(outcome)
        if outcome != "done":
            return outcome
        # Side logs first (synced), then the trial row: the row is the commit point.
        for log in (self.gaze_log, self.frame_log, self.blank_log):
            log.flush(sync=True)
        self.trial_log.append(trial_row(self.protocol, trial, st, participant=self.participant,
                                        session_id=self.session_id, seed=self.seed,
                                        tracker=SIMULATED_TRACKER if self.opts.dry_run
                                        else self.gaze.name))
        self.done.add(trial.index)
        return "done"

    def _trial_loop(self, trial: Trial, attempt: int) -> tuple[TrialLoop, TrialState]:
        """The frame loop of an attempt, wired to this session's screen, gaze, renderer and
        logs (its frames' gaze-to-flip latencies kept for the console line)."""
        spec = self.protocol.spec
        adj = spec.adjust
        frame = self._load_frame(trial)
        w = frame.shape[1]
        self.screen.set_reference(frame[:, : w // 2])
        adjuster = ValueAdjuster(adj.range[0], adj.range[1], adj.step, adj.fine_step,
                                 trial.start_value)
        st = TrialState(adjuster, self.refresh_hz)
        self.renderer.set_image(frame[:, w // 2:], (w, frame.shape[0]))
        monitor = BlankingMonitor(self.fixation, spec.fixation.radius_deg,
                                  spec.fixation.gaze_timeout_s)
        participant = None
        if self.sim is not None:
            self.sim.begin(adj.parameter, trial.method, trial.blur_rate, trial.s_f,
                           adj.range[0], adj.range[1], adj.step, adj.fine_step)
            participant = self.sim.poll
        latency_ms: list[float] = []

        def frame_row(row: tuple[Any, ...]) -> None:
            self.frame_log.add(row)
            if row[8] is not None:  # gaze-to-flip, for the console line
                latency_ms.append((row[10] - row[8]) / 1e3)

        loop = TrialLoop(
            screen=self.screen, gaze=self.gaze, renderer=self.renderer, monitor=monitor,
            state=st, params_for=lambda v: self._params(trial, v), parameter=adj.parameter,
            trial_index=trial.index, attempt=attempt, participant=participant,
            latch=self.latch,
            io=TrialIO(frame=frame_row,
                       gaze=lambda i, a, samples: self.gaze_log.extend(
                           gaze_items(i, samples, a)),
                       event=lambda kind, detail: (self.file.event(kind, **detail),
                                                   self.live.event(kind, detail))))
        self._last_state, self._last_latency_ms = st, latency_ms
        return loop, st


__all__ = ["EXIT_ABORTED", "EXIT_ERROR", "EXIT_INTERRUPTED", "EXIT_OK", "LOCK_FILE", "QUIT_TEXT",
           "Aborted", "GazeSource", "Interrupted", "Key", "Screen", "Session", "SessionOptions",
           "find_sessions", "new_session_id", "now_iso", "software_version"]
