"""A session: one participant's run of one protocol, from the plan to the last trial's row.

This module keeps only the order of a session's steps; each is done in the room it belongs to
(docs/EXPERIMENT.md, "The runner's rooms"), testable without a window: ``records`` (the
folder's lock, resume, disk space, session file, logs, live status), ``trackers`` (the gaze
source, display area, calibration, drift checks), ``display`` (the window and its checks, the
renderer, the render budget) and ``tasks`` (the screens around trials and the adjustment
trials, :class:`~fovexp.experiment.tasks.adjust.AdjustmentTask`). The window is a
:class:`~fovexp.experiment.interfaces.Screen`, the gaze a
:class:`~fovexp.experiment.interfaces.GazeSource`. File writes stay off the frame loop.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from fovexp import FovexpError, Steps
from fovexp.results.format import SIMULATED_TRACKER, now_iso
from fovexp.stimuli.folder import load_stimulus, split_screen

from .display import checks
from .interfaces import GazeSource, Renderer, Screen, ScreenFactory
from .options import SessionOptions
from .protocol.spec import LoadedProtocol, Trial
from .records.diskspace import check_space, disk_full_message, estimate_log_bytes, is_disk_full
from .records.live import LivePublisher
from .records.lock import FolderLock
from .records.participant_id import check_participant
from .records.resume import attempts_so_far, choose_session, done_trials, resume_command
from .records.runlogs import RunLogs
from .records.sessionfile import SessionFile, end_run, run_entry, start_run
from .tasks.adjust import AdjustmentTask
from .tasks.forced_choice import TASKS
from .tasks.frameloop import Interrupted, LateLatch, display_thread_first, interruptible
from .tasks.screens import Screens
from .tasks.simulated_participant import SimulatedParticipant
from .trackers import iohub_config_path, make_gaze_source
from .trackers.gaze import FixationGeometry, rule_record
from .trackers.setup import Aborted, TrackerSetup, calibration_timing, display_area, window_ppd

EXIT_OK = 0
EXIT_ERROR = 2
EXIT_ABORTED = 3
EXIT_INTERRUPTED = 130
#: the steps before the first trial, as the operator's console shows them
PREPARATION = ["renderer", "tracker", "display checklist", "render budget", "tracker set-up"]


def _quietly(*steps: Callable[[], Any] | None) -> None:
    """Each step, its error ignored: closing after an error must not hide the error."""
    for step in steps:
        try:
            if step is not None:
                step()
        except Exception:
            pass


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
        self.logs: RunLogs | None = None
        self.screens: Screens | None = None
        self.refresh_hz: float = float(self.display.refresh_hz)
        self.latch: LateLatch | None = None  # made with the window (its refresh rate)
        self._operator_notes: list[str] = []  # shown with the instructions (backend, budget)
        self.live = LivePublisher.for_session(self.folder, self.session_id, protocol,
                                              self.participant, opts.dry_run, len(self.trials),
                                              self.fixation)

    def release(self) -> None:
        """Let go of the folder's lock; a folder this run created and wrote nothing to (a
        missing tracker, a failed display check) is removed again (``records.lock``)."""
        lock, self._lock = getattr(self, "_lock", None), None
        if lock is not None:
            lock.release()

    # -- plan and resume (no window) -------------------------------------------------------------
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
        """The session file's record (``records.sessionfile.SessionFile``)."""
        return self.file.info

    def finish_without_trials(self) -> None:
        """Nothing left to run (all trials logged before the last run ended): mark the session
        complete, without opening a window or a tracker."""
        self.file.update(state="completed", completed=True, ended=now_iso(),
                         n_completed=len(self.done))
        self.release()

    def _start_info(self) -> None:
        """This run's entry in the session file (a new session's record first)."""
        opts = self.opts
        simulated = None if not opts.dry_run else {
            "truth": opts.sim_truth.model_dump(), "speed": opts.sim_speed,
            "noise_scale": opts.sim_noise_scale, "seed": self._sim_seed()}
        start_run(self.file, new=dict(
            session_id=self.session_id, participant=self.participant, protocol=self.protocol,
            display=self.display, seed=self.seed, limit_trials=self.limit,
            practice_trials=self.practice, n_trials=len(self.trials)),
            run=run_entry(dry_run=opts.dry_run, tracker=opts.tracker,
                          remaining_trials=len(self.remaining), screen=opts.screen),
            form=opts.participant_info, form_note=opts.participant_info_note,
            dry_run=opts.dry_run, stimuli=self.stimuli_record, simulated=simulated)

    def _sim_seed(self) -> int:
        return self.opts.sim_seed if self.opts.sim_seed is not None else self.seed

    # -- gaze ------------------------------------------------------------------------------------
    def make_gaze(self) -> GazeSource:
        """The gaze source (:func:`fovexp.experiment.trackers.make_gaze_source`); ``--tracker
        tobii`` or ``iohub`` fails here, before a window opens. A resumed run's simulated eyes
        get fresh noise (another seed) but stay reproducible."""
        n_runs = len(self.info.get("runs", [])) if self.info else 0
        return make_gaze_source(
            self.opts.tracker, protocol=self.protocol, display=self.display,
            fixation=self.fixation, dry_run=self.opts.dry_run, screen=self.opts.screen,
            tracker_address=self.opts.tracker_address, tracker_config=self.opts.tracker_config,
            sim_seed=self._sim_seed() + 7919 * n_runs, sim_params=self.opts.sim_gaze,
            replay=self.opts.gaze_replay)

    def iohub_config_path(self) -> Path:
        """The ioHub configuration this session's ``--tracker iohub`` reads."""
        return iohub_config_path(self.protocol, self.opts.tracker_config)

    def _drain_gaze(self) -> None:
        """Samples that arrived outside a trial's frame loop, into the gaze log (trial empty)."""
        self.logs.gaze(None, None, self.gaze.poll())

    # -- the run ---------------------------------------------------------------------------------
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
        opts, spec = self.opts, self.protocol.spec
        try:
            space = check_space(self.folder, estimate_log_bytes(
                len(self.remaining), spec.tracker.sampling_hz, float(self.display.refresh_hz)))
            self.gaze = gaze if gaze is not None else self.make_gaze()
            # the tracker's display area against the profile: before any window opens
            self.area, area_info = display_area(self.gaze, self.display,
                                                self.protocol.display_name)
            self.screen = checks.open_screen(
                screen_factory, self.display, window_size=opts.window_size,
                fullscreen=opts.fullscreen, dry_run=opts.dry_run, screen=opts.screen,
                ppd_centre=self.fixation.ppd_centre, cross_size_deg=spec.fixation.cross_size_deg)
            check, self.refresh_hz = checks.check_display(
                self.screen, self.display, dry_run=opts.dry_run, skip=opts.skip_display_check)
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
            self.file.update(display_check={**check, "screen": opts.screen},
                             display_area=area_info, blanking_rule=rule_record(
                                 spec.fixation.radius_deg, spec.fixation.gaze_timeout_s))
            self.logs = RunLogs(self.folder, self.session_id, self.fixation, spec.task)
        except BaseException as exc:
            self.file.stop_writer()
            _quietly(self.gaze.stop, self.screen.close)  # the error to report is this one
            self.release()
            if is_disk_full(exc):
                raise FovexpError(self._disk_full_message()) from None
            raise
        #: when each frame reads the gaze (one latch for the run: its margin carries over)
        self.latch = LateLatch(1.0 / self.refresh_hz)
        self.live.header.update(tracker_name=self.gaze.name, refresh_hz=self.refresh_hz,
                                remaining=len(self.remaining))
        self.live.start()
        self.logs.start(self.live)
        self.screens = Screens(self.screen, self.file, self.live, self._drain_gaze,
                               opts.dry_message_s if opts.dry_run else None)
        state, code, failure = "interrupted", EXIT_INTERRUPTED, None
        try:
            with interruptible():
                self._before_trials()
                with display_thread_first() as priority:
                    try:
                        self._task().run()
                    finally:
                        self.file.set_in_run("display_thread", {
                            **priority, "late_latch": self.latch.info()}, write=False)
                state, code = "completed", EXIT_OK
                self.screens.message("Thank you - this part is finished.", ["space", "return"],
                                     3.0)
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
            self._close(state, failure)
        return code

    def _before_trials(self) -> None:
        """The renderer, the tracker's stream, the display checklist, the keyboard, the rig
        check, the render budget, the tracker's set-up and the instructions, in this order;
        the operator sees each step start (``fovexp.progress``: minutes at 4K on a CPU)."""
        opts, spec = self.opts, self.protocol.spec
        with Steps(PREPARATION, desc="fovexp run: preparing") as step:
            step("renderer")
            self.renderer = checks.start_renderer(self.display, spec, opts.backend, self.screen)
            self.file.update(render=self.renderer.info())
            step("tracker")
            self.gaze.start()
            self.file.update(tracker=self.gaze.info())
            self.tracker = self._make_tracker_setup()
            step("display checklist")
            self.screens.display_checklist(opts.dry_run)
            window = self.screen.info()
            self.file.set_in_run("window", window)
            self._operator_note(checks.keyboard_note(window, opts.dry_run, opts.accept_poll_keys))
            self._operator_note(checks.rig_note(opts.results_root, opts.dry_run, self.file))
            step("render budget")
            self._check_render_budget()
            step("tracker set-up")
            self.live.set_state("calibrating")
            self.tracker.setup()
        self.live.tracker_quality(self.info.get("tracker_quality"))
        self.screens.instructions(spec.title, spec.instructions, bool(self.done),
                                  self._operator_notes)

    def _task(self) -> AdjustmentTask:
        """The run's trials, wired to this session's screen, gaze, renderer and logs."""
        sim = None
        if self.opts.dry_run:
            opts = self.opts
            sim = SimulatedParticipant(opts.sim_truth, self._sim_seed() + 1, opts.sim_speed,
                                       opts.sim_noise_scale)
        return TASKS[self.protocol.spec.task](
            protocol=self.protocol, participant=self.participant, seed=self.seed,
            tracker=SIMULATED_TRACKER if self.opts.dry_run else self.gaze.name,
            trials=self.trials, remaining=self.remaining, done=self.done,
            attempts=self.attempts, screen=self.screen, gaze=self.gaze,
            renderer=self.renderer, fixation=self.fixation, refresh_hz=self.refresh_hz,
            latch=self.latch, screens=self.screens, file=self.file, live=self.live,
            sink=self.logs, load_frame=self._load_frame,
            between_trials=self.tracker.between_trials, say=self._say, sim=sim)

    def _make_tracker_setup(self) -> TrackerSetup:
        return TrackerSetup(
            gaze=self.gaze, screen=self.screen, protocol_spec=self.protocol.spec,
            area=self.area, distance_mm=10.0 * self.display.distance_cm,
            ppd_px=window_ppd(self.fixation, self.display, self.screen.size[0]),
            timing=calibration_timing(self.opts.calibration_timing, self.opts.dry_run),
            auto=self.opts.dry_run, seed=self.seed, file=self.file,
            gaze_sink=lambda samples: self.logs.gaze(None, None, samples))

    def _close(self, state: str, failure: str | None) -> None:
        """The end of a run, however it ends: the tracker stops, then what its buffer still
        holds (the last screen's samples) goes into the gaze log before the final flush; the
        renderer lets go of the window's shared GL context before the window closes; the
        session file gets the run's state; the folder's lock is let go."""
        _quietly(self.gaze.stop, self._drain_gaze)
        late = self.logs.stop()
        # the last rows (the closing screens' samples) not written: said, never silent
        late = late if failure is None else None
        _quietly(getattr(self.renderer, "close", None), getattr(self.screen, "close", None))
        done = self.logs.done()
        complete = state == "completed" and len(done) == len(self.trials)
        self.live.stop(state if complete or state != "completed" else "incomplete")
        measured = getattr(self.gaze, "measured", None)  # the sampling rate over the run
        try:
            end_run(self.file, state=state, complete=complete, n_completed=len(done),
                    failure=failure, measured=measured() if measured is not None else None,
                    log_error=late)
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

    def _disk_full_message(self) -> str:
        return disk_full_message(Path(self.opts.results_root), resume_command(
            self.protocol.path, self.participant, self.opts.results_root, self.opts.dry_run))

    # -- checks before the first trial -----------------------------------------------------------
    def _operator_note(self, note: checks.Note | None) -> None:
        """A warning for the operator: console, session file (event), instruction screen."""
        if note is None:
            return
        text, event, detail = note
        self._say(f"fovexp run: warning: {text}")
        self._operator_notes.append(text)
        self.file.event(event, **detail)

    def _check_render_budget(self) -> None:
        """The renderer's own warnings, then the wheel step's render time against the
        protocol's budget, on the first remaining trial's image (``display.checks``)."""
        info = self.renderer.info()
        for note in checks.renderer_notes(info):
            self._operator_note(note)
        trial = self.remaining[0]

        def cross_alone() -> None:
            self.screen.draw(blank=True)
            self._drain_gaze()

        result, note = checks.render_budget(
            self.renderer, self.protocol.spec, self._load_frame(trial), trial.start_value,
            lambda v: self.protocol.make_params(trial, v, self.seed), cross_alone)
        self.file.update(render={**info, "wheel_step": result})
        self._operator_note(note)

    def _load_frame(self, trial: Trial) -> np.ndarray:
        img = self.images[trial.image]  # a dry run may scale (checked and recorded)
        return split_screen(load_stimulus(img.path, self.screen.size, scale=img.scaled))


__all__ = ["EXIT_ABORTED", "EXIT_ERROR", "EXIT_INTERRUPTED", "EXIT_OK", "Session"]
