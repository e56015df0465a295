"""A session: plan, resume, tracker set-up, instructions, practice, trials, breaks, logs.

The frame loop of a trial follows paper section 6.1 ("Task"): the reference's left half on the
left, the mirrored half processed with the current value on the right, a fixation cross on the
seam; the wheel changes the value, Enter confirms; whenever the gaze leaves the 1.25 deg window
around the cross (or is invalid or lost) the next frame is black. The loop itself is
:class:`fovexp.experiment.frameloop.TrialLoop`. The window is a :class:`Screen`
(``fovexp.experiment.window.PsychoScreen``); everything here runs without one except
:meth:`Session.run`.

Between trials the screen shows the cross alone from the first flip after Enter until the next
trial's stimulus (or a message). File writes stay off the frame loop: the gaze, frame and
blanking logs are written by their flusher thread, events go to the session file through its
writer thread, and the trial row (the commit point) is written after the black frame.
"""

from __future__ import annotations

import csv
import datetime as _dt
import json
import os
import platform
import signal
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from filelock import FileLock, Timeout

from fovexp import FovexpError

from .calibration import (
    QUIT_KEYS,
    QUIT_PROMPT,
    QUIT_QUESTION,
    CalibrationFlow,
    CalibrationTiming,
    DriftCheck,
    SimulatedCalibration,
)
from .frameloop import TrialIO, TrialLoop, display_thread_first
from .gaze import (
    BlankingMonitor,
    DisplayArea,
    FixationGeometry,
    GazeSample,
    MouseGaze,
    SimGazeParams,
    SimulatedGaze,
    check_display_area,
    sample_row,
)
from .logs import (
    BLANKING_COLUMNS,
    FRAME_COLUMNS,
    GAZE_COLUMNS,
    BatchLog,
    JsonWriter,
    PeriodicFlusher,
    TrialLog,
    json_text,
    read_trials,
    write_json_atomic,
)
from .operator import DISPLAY_CHECKLIST, checklist_text, eta_s, trial_line
from .participant import SimTruth, SimulatedParticipant
from .protocol import LoadedProtocol, Trial
from .quality import target_points
from .stimuli import load_stimulus, split_screen
from .trial import InputEvent, Key, TrialState, ValueAdjuster
from .validation import check_participant

EXIT_OK = 0
EXIT_ERROR = 2
EXIT_ABORTED = 3
EXIT_INTERRUPTED = 130
#: held (an OS file lock) in the participant's folder while a run uses it
LOCK_FILE = ".fovexp-run.lock"
#: the quit key's confirmation screen
QUIT_TEXT = f"{QUIT_QUESTION}\n\n{QUIT_PROMPT}"


class Screen(Protocol):
    """What a session needs from its window (``window.PsychoScreen``)."""

    size: tuple[int, int]

    refresh_hz: float

    def measure_display(self) -> tuple[float | None, tuple[int, int], tuple[int, int]]: ...
    def message(self, text: str, keys: list[str] | None, timeout_s: float | None,
                each_frame: Callable[[], None] | None = None) -> str | None: ...
    def calibration_frame(self, view: Any) -> list[str]: ...
    def take_operator_keys(self) -> set[str]: ...
    def set_reference(self, left: np.ndarray) -> None: ...
    def set_test(self, right: Any) -> None: ...
    def prepare(self, blank: bool) -> None: ...
    def flip(self) -> float: ...
    def draw(self, blank: bool) -> float: ...
    def poll_input(self) -> list[InputEvent]: ...
    def mouse_position(self) -> tuple[float, float] | None: ...
    def close(self) -> None: ...


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


class Aborted(Exception):
    """The operator quit (Escape, then Q to confirm); progress is saved."""


class Interrupted(Exception):
    """SIGINT/SIGTERM: stop at once; progress is saved."""


def software_version() -> str:
    try:
        from importlib.metadata import version

        return version("fovexp")
    except Exception:
        import fovexp

        return str(getattr(fovexp, "__version__", "unknown"))


def _versions() -> dict[str, str]:
    out = {"python": platform.python_version(), "fovexp": software_version(),
           "platform": platform.platform()}
    for mod in ("numpy", "scipy", "pydantic", "psychopy", "pyglet", "tobii_research"):
        m = sys.modules.get(mod)
        if m is None:
            try:
                m = __import__(mod)
            except Exception:
                continue
        # pyglet keeps its version in ``version``
        out[mod] = str(getattr(m, "__version__", getattr(m, "version", "?")))
    return out


def now_iso() -> str:
    return _dt.datetime.now().astimezone().isoformat(timespec="milliseconds")


def new_session_id(folder: Path) -> str:
    """``YYYYmmdd-HHMMSS``; waits a second if that id is taken in ``folder``."""
    while True:
        sid = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
        if not (folder / f"session-{sid}.json").exists():
            return sid
        time.sleep(0.2)


def find_sessions(folder: Path) -> list[dict[str, Any]]:
    out = []
    for p in sorted(folder.glob("session-*.json")):
        try:
            info = json.loads(p.read_text())
        except (OSError, json.JSONDecodeError):
            continue
        info["_path"] = str(p)
        out.append(info)
    return out


class Session:
    """One participant's run of one protocol (see the module docstring)."""

    def __init__(self, protocol: LoadedProtocol, opts: SessionOptions) -> None:
        from fovexp import load_display

        self.protocol = protocol
        self.opts = opts
        self.participant = check_participant(opts.participant)
        if opts.dry_run and opts.tracker != "simulated":
            raise FovexpError("--dry-run uses simulated gaze: leave out --tracker or use "
                              "--tracker simulated")
        self.display = load_display(protocol.display_name)
        # Every image checked for the frames this session shows, before anything is written:
        # a real session refuses any size but the window's (the display's own, unless
        # --window), a dry run scales (recorded in the session file's "stimuli").
        self.frame_size = tuple(opts.window_size or protocol.native_size)
        self.images = protocol.prepare_images(self.frame_size, opts.dry_run)
        self.stimuli_record = protocol.stimuli_record()
        self.folder = Path(opts.results_root) / protocol.experiment / self.participant
        self._info_lock = threading.Lock()
        self._writer: JsonWriter | None = None
        self._lock = self._lock_folder()
        try:
            self.fixation = FixationGeometry(self.display)
            self._prepare_session()
        except BaseException:
            self.release()
            raise
        self.gaze: Any = None
        self.screen: Any = None
        self.renderer: Any = None
        self.sim: SimulatedParticipant | None = None
        self.events: list[dict[str, Any]] = []
        self.refresh_hz: float = float(self.display.refresh_hz)
        self._trial_seconds: list[float] = []  # this run's trial durations (the console's ETA)
        self._operator_notes: list[str] = []  # shown with the instructions (backend, budget)

    # -- the participant's folder: one run at a time ---------------------------------------------
    def _lock_folder(self) -> FileLock:
        """Create the folder and hold its lock for this run: a second ``fovexp run`` (say a
        ``--resume`` while the session still runs) would log every trial twice. The operating
        system drops the lock when the process dies, so a killed session resumes at once."""
        folder = self.folder
        self._created = [p for p in (*reversed(folder.parents), folder) if not p.exists()]
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise FovexpError(f"--results {self.opts.results_root}: cannot create {folder}: "
                              f"{exc.strerror}") from None
        lock = FileLock(str(folder / LOCK_FILE), thread_local=False, is_singleton=True)
        try:
            lock.acquire(timeout=0)
        except Timeout:
            raise FovexpError(
                f"{folder} is in use by another fovexp run (participant {self.participant}, "
                f"{self.protocol.experiment}): wait for it to end, or stop it first") from None
        return lock

    def release(self) -> None:
        """Let go of the folder's lock; a folder this run created and wrote nothing to (a
        missing tracker, a failed display check) is removed again."""
        lock = getattr(self, "_lock", None)
        if lock is None:
            return
        self._lock = None
        if lock.is_locked:
            lock.release()
        if lock.is_locked:  # still held by another Session of this process
            return
        if [p for p in self.folder.iterdir() if p.name != LOCK_FILE]:
            return
        (self.folder / LOCK_FILE).unlink(missing_ok=True)
        for p in reversed(self._created):
            try:
                p.rmdir()
            except OSError:  # not empty (another participant's folder appeared): keep it
                break

    # -- plan and resume (no window) -----------------------------------------------------------
    def _prepare_session(self) -> None:
        opts, proto = self.opts, self.protocol
        sessions = find_sessions(self.folder)
        # A session that failed before its first trial (tracker calibration or validation,
        # a bad stimulus) has nothing to continue: it blocks nothing.
        incomplete = [s for s in sessions if not s.get("completed")
                      and not (s.get("state") == "failed" and not s.get("n_completed"))]
        self.info: dict[str, Any]
        if opts.resume:
            if not incomplete:
                raise FovexpError(
                    f"--resume: no incomplete session of {proto.experiment} for participant "
                    f"{self.participant} in {self.folder}")
            info = incomplete[-1]
            info.pop("_path", None)
            if info.get("protocol_sha256") != proto.sha256:
                raise FovexpError(
                    f"--resume: protocol {proto.path} changed since session {info['session']} "
                    f"started (sha256 {proto.sha256[:12]}... vs "
                    f"{str(info.get('protocol_sha256'))[:12]}...); resuming would mix protocol "
                    "versions")
            first = (info.get("runs") or [{}])[0]
            if (first.get("dry_run"), first.get("tracker")) not in (
                    (None, None), (opts.dry_run, opts.tracker)):
                # a dry run must never finish a participant's session, nor a mouse a tracker's
                mode = "a dry run" if first.get("dry_run") else "a session"
                raise FovexpError(
                    f"--resume: session {info['session']} started as {mode} with "
                    f"--tracker {first.get('tracker')}; resume it the same way "
                    f"({'--dry-run' if first.get('dry_run') else 'without --dry-run'}, "
                    f"--tracker {first.get('tracker')}), or start a --new-session")
            self.session_id = str(info["session"])
            self._reuse_derived(info)
            plan = info.get("plan", {})
            self.limit = plan.get("limit_trials")
            self.practice = plan.get("practice_trials")
            self.info = info
        else:
            if incomplete and not opts.new_session:
                sid = incomplete[-1].get("session")
                raise FovexpError(
                    f"participant {self.participant} has an incomplete session {sid} of "
                    f"{proto.experiment} in {self.folder}: add --resume to continue it, or "
                    "--new-session to start a new one")
            self.session_id = new_session_id(self.folder)
            self.limit, self.practice = opts.limit_trials, opts.practice_trials
            self.info = {}
        self.seed, self.trials = proto.plan(self.participant, self.limit, self.practice)
        rows, _ = read_trials(self.folder / "trials.csv")
        self.done = {int(r["trial_index"]) for r in rows if r["session"] == self.session_id}
        self.remaining = [t for t in self.trials if t.index not in self.done]
        #: attempts begun per trial (all runs): a resumed session numbers on from these
        self.attempts = self._attempts_so_far()

    def _attempts_so_far(self) -> dict[int, int]:
        """Attempts already begun per trial index: those the session file recorded at each
        attempt's start, or, for an attempt whose start a kill kept out of it, those in the
        frame and blanking logs."""
        out = {int(k): int(v) for k, v in (self.info.get("attempts") or {}).items()}
        for name in (f"frames-{self.session_id}.csv", f"blanking-{self.session_id}.csv"):
            path = self.folder / name
            if not path.exists():
                continue
            with open(path, encoding="utf-8", newline="") as fh:
                for row in csv.DictReader(fh):
                    try:
                        i, a = int(row["trial_index"]), int(row["attempt"])
                    except (KeyError, TypeError, ValueError):  # a torn last line
                        continue
                    out[i] = max(out.get(i, 0), a + 1)
        return out

    def _reuse_derived(self, info: dict[str, Any]) -> None:
        """Resume with the dependency values (f_e per blur-rate, s_k lines, tables) the session
        started with, even when the results they came from changed since (more participants):
        one session never mixes two sets."""
        proto = self.protocol
        stored = info.get("derived")
        if stored is None:
            if proto.derived:
                raise FovexpError(
                    f"--resume: session {info['session']} did not record the values it derived "
                    f"from {', '.join(sorted(proto.dependency_folders.values()))}; resuming "
                    "could mix two sets of them: start a --new-session")
            return
        if stored != proto.derived:
            changed = sorted(k for k in set(stored) | set(proto.derived)
                             if stored.get(k) != proto.derived.get(k))
            info.setdefault("events", []).append({
                "time": now_iso(), "event": "derived_values_reused", "parameters": changed,
                "note": "the dependency results changed since the session started; the "
                        "session's own values are used"})
            proto.use_derived(stored)

    def finish_without_trials(self) -> None:
        """Nothing left to run (all trials logged before the last run ended): mark the session
        complete, without opening a window or a tracker."""
        self._write_info(state="completed", completed=True, ended=now_iso(),
                         n_completed=len(self.done))
        self.release()

    def _session_path(self) -> Path:
        return self.folder / f"session-{self.session_id}.json"

    def _write_info(self, **update: Any) -> None:
        """Update the session file and write it now (atomic, fsync'ed; after a write the
        writer thread has under way). Not for the frame loop: :meth:`_event` is."""
        with self._info_lock:
            self.info.update(update)
        if self._writer is not None:
            self._writer.write_now()
        else:
            write_json_atomic(self._session_path(), self._info_text())

    def _info_text(self) -> str:
        with self._info_lock:
            return json_text(self.info)

    def _start_info(self) -> None:
        proto, opts = self.protocol, self.opts
        run = {"started": now_iso(), "dry_run": opts.dry_run, "tracker": opts.tracker,
               "pid": os.getpid(), "remaining_trials": len(self.remaining)}
        if not self.info:
            self.info = {
                "session": self.session_id,
                "participant": self.participant,
                "experiment": proto.experiment,
                "protocol_path": str(proto.path),
                "protocol_sha256": proto.sha256,
                "protocol": proto.text,
                "dependencies": proto.dependency_folders,
                "derived": proto.derived,
                "display": self.display.model_dump(),
                "seed": self.seed,
                "plan": {"limit_trials": self.limit, "practice_trials": self.practice,
                         "n_trials": len(self.trials)},
                "software_version": software_version(),
                "started": run["started"],
                "ended": None,
                "state": "running",
                "completed": False,
                "runs": [],
                "tracker_quality": [],
                "events": [],
            }
        if "participant_info" not in self.info:  # asked at the first start; resume keeps it
            self.info["participant_info"] = (
                {**opts.participant_info, "time": run["started"]}
                if opts.participant_info is not None
                else {"skipped": opts.participant_info_note or
                      ("dry run" if opts.dry_run else "not asked")})
        run["screen"] = opts.screen
        self.info["runs"].append(run)
        self.info["stimuli"] = self.stimuli_record
        self.info["versions"] = _versions()
        if opts.dry_run:
            self.info["simulated_participant"] = {
                "truth": opts.sim_truth.model_dump(), "speed": opts.sim_speed,
                "noise_scale": opts.sim_noise_scale, "seed": self._sim_seed()}
        self._write_info(state="running", completed=False)

    def _sim_seed(self) -> int:
        return self.opts.sim_seed if self.opts.sim_seed is not None else self.seed

    # -- gaze ----------------------------------------------------------------------------------
    def make_gaze(self) -> Any:
        """The gaze source; ``--tracker tobii`` fails here, before a window opens."""
        kind = self.opts.tracker
        if kind == "tobii":
            from .tobii import TobiiGaze

            return TobiiGaze(self.protocol.spec.tracker.sampling_hz, self.opts.tracker_address)
        if kind == "simulated":
            n_runs = len(self.info.get("runs", [])) if self.info else 0
            params = self.opts.sim_gaze or SimGazeParams(
                rate_hz=self.protocol.spec.tracker.sampling_hz)
            # A resumed run gets fresh gaze noise (different seed) but stays reproducible.
            return SimulatedGaze(self.fixation, seed=self._sim_seed() + 7919 * n_runs,
                                 params=params)
        if kind == "mouse":
            return MouseGaze()
        raise FovexpError(f"--tracker {kind!r}: choose tobii, simulated or mouse")

    # -- the run -------------------------------------------------------------------------------
    def _say(self, line: str) -> None:
        """A line for the operator's console."""
        (self.opts.console or (lambda t: print(t, file=sys.stderr, flush=True)))(line)

    def run(self, screen_factory: Any = None, gaze: Any = None) -> int:
        """Run the remaining trials; returns an exit status (0 done, 3 aborted, 130 killed)."""
        proto = self.protocol
        if not self.remaining:
            if not self.info.get("completed"):
                self.finish_without_trials()
            return EXIT_OK
        try:
            self.gaze = gaze if gaze is not None else self.make_gaze()
            # the tracker's display area against the profile: before any window opens
            self.area, area_info = self._display_area()
            if screen_factory is None:
                from .window import PsychoScreen

                screen_factory = PsychoScreen
            # The window and its display check come first: a failed check writes nothing.
            size = self.opts.window_size or (self.display.width_px, self.display.height_px)
            self.screen = screen_factory(
                size=size, fullscreen=self.opts.fullscreen and not self.opts.dry_run,
                cross_px=self._cross_px(size), dry_run=self.opts.dry_run,
                refresh_hz=self.display.refresh_hz, screen=self.opts.screen)
            check = self._check_display()
        except BaseException:
            self.release()
            raise
        if isinstance(self.gaze, MouseGaze):
            self.gaze.position = self.screen.mouse_position
        self._start_info()
        self._writer = JsonWriter(self._session_path(), self._info_text)
        self._write_info(display_check={**check, "screen": self.opts.screen},
                         display_area=area_info)
        self.trial_log = TrialLog(self.folder / "trials.csv")
        sid = self.session_id
        self.gaze_log = BatchLog(self.folder / f"gaze-{sid}.csv", GAZE_COLUMNS,
                                 formatter=self._gaze_row)
        self.frame_log = BatchLog(self.folder / f"frames-{sid}.csv", FRAME_COLUMNS)
        self.blank_log = BatchLog(self.folder / f"blanking-{sid}.csv", BLANKING_COLUMNS)
        flusher = PeriodicFlusher([self.gaze_log, self.frame_log, self.blank_log]).start()
        old_handlers = self._install_signals()
        state = "interrupted"
        code = EXIT_INTERRUPTED
        failure: str | None = None
        try:
            from .render import TestRenderer

            share = getattr(self.screen, "gl_share", None)
            self.renderer = TestRenderer(
                self.display, proto.spec.preset, proto.spec.geometry_model, self.opts.backend,
                gl_share=share() if share is not None and self.opts.backend != "cpu" else None)
            self._write_info(render=self.renderer.info())
            self.gaze.start()
            self._write_info(tracker=self.gaze.info())
            if self.opts.dry_run:
                self.sim = SimulatedParticipant(self.opts.sim_truth, self._sim_seed() + 1,
                                                self.opts.sim_speed, self.opts.sim_noise_scale)
            self._display_setup()
            self._check_render_budget()
            self._tracker_setup()
            self._instructions()
            with display_thread_first() as priority:
                with self._info_lock:
                    self.info["runs"][-1]["display_thread"] = priority
                self._trials()
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
            import traceback

            state, failure = "failed", f"{type(exc).__name__}: {exc}"
            self.info["failure_traceback"] = traceback.format_exc()
            raise FovexpError(f"internal error: {failure} (traceback in "
                              f"{self._session_path()})") from None
        finally:
            self._restore_signals(old_handlers)
            # The tracker stops first, then what its buffer still holds (the last screen's
            # samples) goes into the gaze log before the final flush.
            for step in (self.gaze.stop, self._drain_gaze):
                try:
                    step()
                except Exception:  # closing after an error must not hide the error
                    pass
            flusher.stop()
            # the renderer lets go of the window's shared GL context before the window closes
            for closer in (getattr(self.renderer, "close", None),
                           getattr(self.screen, "close", None)):
                if closer is not None:
                    try:
                        closer()
                    except Exception:  # closing after an error must not hide the error
                        pass
            done = {int(r["trial_index"]) for r in self.trial_log.rows
                    if r["session"] == self.session_id} if hasattr(self, "trial_log") else set()
            complete = state == "completed" and len(done) == len(self.trials)
            extra = {"failure": failure} if failure is not None else {}
            writer, self._writer = self._writer, None
            try:
                writer.close()  # the events it had still to write are in the final write below
            except Exception:
                pass
            self._write_info(state=state if not (state == "completed" and not complete)
                             else "incomplete", completed=complete, ended=now_iso(),
                             n_completed=len(done), events=self.info.get("events", []), **extra)
            self.release()
        return code

    def _display_setup(self) -> None:
        """The operator confirms the display checklist (docs/EXPERIMENT.md) with C; recorded
        per run. A dry run records it as skipped."""
        if self.opts.dry_run:
            entry: dict[str, Any] = {"skipped": "dry run"}
        else:
            self._message(checklist_text(), ["c"], None)
            entry = {"confirmed": True, "time": now_iso(), "items": list(DISPLAY_CHECKLIST)}
        with self._info_lock:
            self.info["runs"][-1]["display_setup"] = entry
        self._write_info()

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
        v0 = trial.start_value
        v1 = v0 + adj.step if v0 + adj.step <= adj.range[1] else v0 - adj.step
        times = []
        for v in (v0, v1):
            deadline = time.monotonic() + 300
            serial = self.renderer.request(self._params(trial, v))
            while True:  # the cross alone meanwhile
                try:
                    times.append(self.renderer.wait(serial, timeout=0.05).seconds)
                    break
                except TimeoutError:
                    if time.monotonic() > deadline:
                        raise FovexpError("the warm-up render took more than 300 s") from None
                    self.screen.draw(blank=True)
                    self._drain_gaze()
        step_ms = 1e3 * times[1]
        budget = spec.render.max_step_ms
        result = {"parameter": adj.parameter, "first_render_ms": round(1e3 * times[0], 1),
                  "step_ms": round(step_ms, 1), "max_step_ms": budget,
                  "within_budget": step_ms <= budget}
        self._write_info(render={**info, "wheel_step": result})
        if step_ms > budget:
            self._operator_note(
                f"a wheel step ({adj.parameter}) takes {step_ms:.0f} ms on the "
                f"{info['backend']} backend, above the protocol's render.max_step_ms = "
                f"{budget:g} ms", "render_budget_exceeded", **result)

    def _operator_note(self, text: str, event: str, **detail: Any) -> None:
        """A warning for the operator: console, session file (event), instruction screen."""
        self._say(f"fovexp run: warning: {text}")
        self._operator_notes.append(text)
        self._event(event, **detail)

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

    def _event(self, kind: str, **detail: Any) -> None:
        """An event for the session file, written by its writer thread (the frame loop calls
        this: it never waits on the disk); before the run's writer exists, at once."""
        with self._info_lock:
            self.info.setdefault("events", []).append(
                {"time": now_iso(), "event": kind, **detail})
        if self._writer is not None:
            self._writer.request()
        else:
            self._write_info()

    def _message(self, text: str, keys: list[str], timeout_s: float | None = None) -> str | None:
        """A message screen; the gaze stream keeps going into the gaze log meanwhile (a long
        break would otherwise overflow the tracker's buffer). Escape or Q (where Q is not one of
        the message's own keys) asks to quit (:meth:`confirm_quit`); going back shows the
        message again."""
        if self.opts.dry_run:
            timeout_s = self.opts.dry_message_s
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
            self._event("aborted", trial_index=trial_index)
            raise Aborted()

    def _drain_gaze(self) -> None:
        """Samples that arrived outside a trial's frame loop, into the gaze log (trial empty)."""
        self.gaze_log.extend(self._gaze_rows(None, self.gaze.poll()))

    # -- tracker calibration, validation and drift checks ---------------------------------------
    def _display_area(self) -> tuple[DisplayArea, dict[str, Any]]:
        """The display area the gaze source's normalised coordinates refer to: a Tobii's own
        (refused when its size is more than a few mm off the display profile's), else the
        profile's nominal one. Returns it and what goes into the session file."""
        get = getattr(self.gaze, "display_area", None)
        area = get() if get is not None else DisplayArea.nominal(self.display)
        if area.source != "tracker":
            return area, {"source": area.source, "display_area": area.to_dict()}
        try:
            info = check_display_area(area, self.display)
        except FovexpError as exc:
            raise FovexpError(f"{exc} ({self.protocol.display_name})") from None
        return area, {"source": "tracker", **info}

    def _ppd_px(self) -> float:
        """Window pixels per degree at the screen centre."""
        return self.fixation.ppd_centre * self.screen.size[0] / self.display.width_px

    def _cal_timing(self) -> CalibrationTiming:
        if self.opts.calibration_timing is not None:
            return self.opts.calibration_timing
        return CalibrationTiming.dry_run() if self.opts.dry_run else CalibrationTiming()

    def _tracker_setup(self, reason: str = "start") -> None:
        """Calibrate and validate on the calibration screen (``fovexp.experiment.calibration``:
        head position, animated targets, per-point results with accept / redo). Every
        calibration and validation goes into the session file's ``tracker_quality`` (with
        ``reason``: ``start``, ``operator`` (C between trials) or ``drift``); only a validation
        within the protocol's limits can be accepted. A failed set-up at the start stops the
        session with the reason; the operator's Q (confirmed) quits, progress saved."""
        spec = self.protocol.spec
        if not getattr(self.gaze, "validated", True):  # the mouse (and test scripts)
            self.info["tracker_quality"].append({"time": now_iso(), "skipped": self.gaze.name})
            self._write_info()
            return
        if hasattr(self.gaze, "calibration"):  # a real tracker
            backend = self.gaze.calibration()
        else:
            backend = SimulatedCalibration(self.gaze)

        def record(rec: dict[str, Any], new: bool) -> None:
            if new:
                rec["reason"] = reason
                self.info["tracker_quality"].append(rec)  # the same dict: updates rewrite it
            self._write_info()

        flow = CalibrationFlow(
            backend, target_points(spec.tracker.calibration_points),
            target_points(spec.tracker.validation_points), spec.quality_limits, self.area,
            10.0 * self.display.distance_cm, spec.tracker.sampling_hz, self.screen.size,
            self._ppd_px(), spec.fixation.radius_deg, timing=self._cal_timing(),
            look_at=getattr(self.gaze, "look_at", None), on_record=record,
            auto=self.opts.dry_run, seed=self.seed + len(self.info["tracker_quality"]),
            now_iso=now_iso)
        self._run_flow(flow)
        if flow.outcome == "accepted":
            self._since_drift = 0
            return
        if flow.outcome == "failed" or (reason == "start" and flow.failure):
            self._event("tracker_setup_failed", reason=flow.failure, stage=reason)
            raise FovexpError(flow.failure or "eye-tracker set-up failed")
        self._event("aborted", during=f"eye-tracker calibration ({reason})")
        raise Aborted()

    def _run_flow(self, flow: CalibrationFlow | DriftCheck) -> None:
        """Drive a calibration screen or a drift check: draw its view, read the keys, feed it
        the gaze (which goes to the gaze log, between trials) until it has an outcome."""
        flow.start(self.gaze.now_us())
        try:
            while not flow.finished:
                keys = self.screen.calibration_frame(flow.view())
                for ev in self.gaze.poll_events():
                    self._event(ev.kind, **ev.detail)
                samples = self.gaze.poll()
                self.gaze_log.extend(self._gaze_rows(None, samples))
                flow.feed(samples)
                flow.step(keys, self.gaze.now_us())
        finally:
            flow.close()

    def _between_trials_checks(self, trial: Trial) -> None:
        """After ``trial`` (called from :meth:`_trials`): the operator's C (pressed during the
        trial or after it) recalibrates; D, or ``tracker.drift_check_every`` main trials since
        the last check or calibration, runs a drift check (:meth:`_drift_check`). Nothing after
        the last trial, nor with a source that is not calibrated (the mouse)."""
        keys = self.screen.take_operator_keys()
        if not getattr(self.gaze, "validated", True):
            return
        if not any(t.index > trial.index for t in self.remaining):
            return
        self._since_drift = getattr(self, "_since_drift", 0) + (not trial.practice)
        every = self.protocol.spec.tracker.drift_check_every
        if "c" in keys:
            self._event("recalibration", reason="operator", after_trial=trial.index)
            self._tracker_setup("operator")
        elif "d" in keys or (every and self._since_drift >= every):
            self._drift_check(trial, "operator" if "d" in keys else "scheduled")

    def _drift_check(self, trial: Trial, why: str) -> None:
        """The central target; the offset of the mean gaze per eye against the protocol's
        drift limit (``tracker.max_drift_deg``, by default the central accuracy limit); logged
        as a ``drift_check`` event; a recalibration when the operator (or a dry run) asks."""
        spec = self.protocol.spec
        check = DriftCheck(self.area, 10.0 * self.display.distance_cm, spec.tracker.sampling_hz,
                           self.screen.size, self._ppd_px(), spec.drift_limit_deg,
                           spec.tracker.max_data_loss, timing=self._cal_timing(),
                           look_at=getattr(self.gaze, "look_at", None), auto=self.opts.dry_run)
        self._run_flow(check)
        self._since_drift = 0
        self._event("drift_check", why=why, after_trial=trial.index, outcome=check.outcome,
                    checks=[r.to_dict() for r in check.results])
        if check.outcome == "recalibrate":
            self._event("recalibration", reason="drift", after_trial=trial.index)
            self._tracker_setup("drift")
        elif check.outcome == "quit":
            self._event("aborted", during="drift check", after_trial=trial.index)
            raise Aborted()

    # -- instructions, practice, trials, breaks --------------------------------------------------
    def _instructions(self) -> None:
        text = self.protocol.spec.instructions.strip() or "Adjust the right half to match the left."
        resumed = " (continuing where the last session stopped)" if self.done else ""
        notes = "".join(f"\n\nOperator: {n}" for n in self._operator_notes)
        self._message(f"{self.protocol.spec.title}{resumed}\n\n{text}\n\nPress Space to start."
                      f"{notes}", ["space"])

    def _trials(self) -> None:
        spec = self.protocol.spec
        practice_announced = False
        main_announced = bool(self.done)
        n_main = sum(not t.practice for t in self.trials)
        for trial in self.remaining:
            if trial.practice and not practice_announced:
                practice_announced = True
                self._message("Practice trials first.\n\nPress Space.", ["space"])
            if not trial.practice and not main_announced:
                main_announced = True
                if practice_announced:
                    self._message("Practice finished. The experiment starts now.\n\n"
                                  "Press Space.", ["space"])
            t0 = time.monotonic()
            while True:  # a pause or a lost tracker restarts the trial: the next attempt
                attempt = self.attempts.get(trial.index, 0)
                self.attempts[trial.index] = attempt + 1
                # on disk before its first frame: a resumed session numbers on from it
                self._write_info(attempts={str(k): v for k, v in self.attempts.items()})
                outcome = self._run_trial(trial, attempt)
                if outcome == "done":
                    break
                if outcome == "pause":
                    self._event("paused", trial_index=trial.index)
                    # Waits for the operator even in a dry run (no auto-continue).
                    key = self.screen.message(
                        "Paused.\n\nSpace: continue (this trial starts again)\n"
                        "Q: quit - progress is saved; continue later with --resume",
                        ["space", "q"], None, self._drain_gaze)
                    if key == "q":
                        self._event("aborted", trial_index=trial.index)
                        raise Aborted()
                elif outcome == "disconnected":
                    self._wait_reconnect(trial)
            self._trial_seconds.append(time.monotonic() - t0)
            left = len([t for t in self.remaining if t.index > trial.index])
            self._console_line(trial, left)
            main_done = sum(not t.practice and t.index in self.done for t in self.trials)
            # breaks at the same places of the plan whatever runs it took (resume)
            if (not trial.practice and spec.break_every and left
                    and main_done % spec.break_every == 0):
                self._message(f"Break. {n_main - main_done} trials to go.\n\n"
                              "Press Space to continue.", ["space"])
            self._between_trials_checks(trial)  # drift check / recalibration (D, C, every N)

    def _console_line(self, trial: Trial, left: int) -> None:
        """trial i/N, blanked %, dropped frames, gaze-to-flip latency, ETA (docs/EXPERIMENT.md)."""
        st = self._last_state
        lat = np.array(self._last_latency_ms, dtype=float)
        position = sum(t.practice == trial.practice and t.index <= trial.index
                       for t in self.trials)
        total = sum(t.practice == trial.practice for t in self.trials)
        self._say(trial_line(position=position, total=total, practice=trial.practice,
                             blanked_fraction=st.blanking.fraction, dropped=st.timer.dropped,
                             frames=st.n_frames, latency_ms=lat,
                             eta_s=eta_s(self._trial_seconds, left)))

    def _wait_reconnect(self, trial: Trial) -> None:
        """Tracker lost mid-session: screen blanked, a message, wait; Q quits (saved)."""
        self._event("tracker_disconnected", trial_index=trial.index)
        text = ("The eye tracker connection was lost. The trial will start again when it is "
                "back.\n\nQ: quit (progress is saved; continue later with --resume)")
        while not self.gaze.connected:
            # The stream is drained here too: a stalled tracker counts as back only when its
            # samples arrive again (and they belong in the gaze log, between trials).
            self._drain_gaze()
            for ev in self.gaze.poll_events():
                self._event(ev.kind, **ev.detail)
            key = self.screen.message(text, ["q", "escape"], 0.1, self._drain_gaze)
            if key is not None:
                self.confirm_quit(trial.index)
        self._event("tracker_reconnected", trial_index=trial.index)

    def _params(self, trial: Trial, value: float) -> Any:
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
            io=TrialIO(frame=frame_row,
                       gaze=lambda i, a, samples: self.gaze_log.extend(
                           self._gaze_rows(i, samples, a)),
                       event=lambda kind, detail: self._event(kind, **detail)))
        self._last_state, self._last_latency_ms = st, latency_ms
        try:
            loop.show_first()
            outcome = loop.run()
        finally:
            st.finish(time.monotonic())  # when the loop could not flip its closing frame
            self.blank_log.extend(
                (trial.index, attempt, round(e.start_s, 6), round(e.end_s, 6), e.frames,
                 e.reason) for e in st.blanking.episodes if e.end_s is not None)
        if outcome != "done":
            return outcome
        # Side logs first (synced), then the trial row: the row is the commit point.
        for log in (self.gaze_log, self.frame_log, self.blank_log):
            log.flush(sync=True)
        self.trial_log.append(self._row(trial, st))
        self.done.add(trial.index)
        return "done"

    def _gaze_rows(self, trial_index: int | None, samples: list[GazeSample],
                   attempt: int | None = None) -> list[Any]:
        """What the gaze log gets for ``samples`` (its rows are made by :meth:`_gaze_row`
        when written, on the flusher thread); ``attempt`` only within a trial."""
        a = attempt if trial_index is not None else None
        return [(trial_index, a, s) for s in samples]

    def _gaze_row(self, item: tuple[int | None, int | None, GazeSample]) -> tuple[Any, ...]:
        trial_index, attempt, s = item
        return sample_row(trial_index, attempt, s, self.fixation.eccentricity(s.point))

    def _row(self, trial: Trial, st: TrialState) -> dict[str, Any]:
        spec = self.protocol.spec
        vals = self.protocol.parameter_values(trial, st.shown_value)
        return {
            "participant": self.participant,
            "session": self.session_id,
            "experiment": spec.experiment,
            "protocol_sha256": self.protocol.sha256,
            "trial_index": trial.index,
            "practice": trial.practice,
            "repetition": trial.repetition,
            "image": trial.image,
            "blur_rate": vals["blur_rate"],
            "method": trial.method,
            "adjusted_parameter": spec.adjust.parameter,
            "f_e": vals["f_e"],
            "s_k": vals["s_k"],
            "s_f": vals["s_f"],
            "start_value": st.start_value,
            "final_value": st.shown_value,
            "response_time_s": round(st.response_time_s, 4),
            "wheel_events": st.adjuster.notches,
            "blanked_fraction": round(st.blanking.fraction, 5),
            "dropped_frames": st.timer.dropped,
            "tracker": self.gaze.name,
            "seed": self.seed,
            "software_version": software_version(),
            "timestamp": now_iso(),
        }


__all__ = ["Session", "SessionOptions", "Screen", "Key", "EXIT_OK", "EXIT_ERROR",
           "EXIT_ABORTED", "EXIT_INTERRUPTED"]
