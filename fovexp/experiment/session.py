"""A session: plan, resume, tracker set-up, instructions, practice, trials, breaks, logs.

The frame loop of a trial follows paper section 6.1 ("Task"): the reference's left half on the
left, the mirrored half processed with the current value on the right, a fixation cross on the
seam; the wheel changes the value, Enter confirms; whenever the gaze leaves the 1.25 deg window
around the cross (or is invalid or lost) the next frame is black. The window itself is a
:class:`Screen` (``fovexp.experiment.window.PsychoScreen``); everything here runs without one
except :meth:`Session.run`.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
import platform
import signal
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from filelock import FileLock, Timeout

from fovexp import FovexpError

from .gaze import (
    BlankingMonitor,
    FixationGeometry,
    GazeSample,
    MouseGaze,
    SimGazeParams,
    SimulatedGaze,
    sample_row,
)
from .logs import (
    BLANKING_COLUMNS,
    FRAME_COLUMNS,
    GAZE_COLUMNS,
    BatchLog,
    PeriodicFlusher,
    TrialLog,
    read_trials,
    write_json_atomic,
)
from .participant import SimTruth, SimulatedParticipant
from .protocol import LoadedProtocol, Trial
from .quality import target_points, validation_result
from .stimuli import load_stimulus, split_screen
from .trial import InputEvent, Key, TrialState, ValueAdjuster
from .validation import check_participant

EXIT_OK = 0
EXIT_ERROR = 2
EXIT_ABORTED = 3
EXIT_INTERRUPTED = 130
#: held (an OS file lock) in the participant's folder while a run uses it
LOCK_FILE = ".fovexp-run.lock"


class Screen(Protocol):
    """What a session needs from its window (``window.PsychoScreen``)."""

    size: tuple[int, int]

    refresh_hz: float

    def measure_display(self) -> tuple[float | None, tuple[int, int], tuple[int, int]]: ...
    def message(self, text: str, keys: list[str] | None, timeout_s: float | None,
                each_frame: Callable[[], None] | None = None) -> str | None: ...
    def show_point(self, x: float, y: float) -> None: ...
    def set_reference(self, left: np.ndarray) -> None: ...
    def set_test(self, right: np.ndarray) -> None: ...
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
    sim_truth: SimTruth = field(default_factory=SimTruth)
    sim_speed: float = 4.0
    sim_noise_scale: float = 1.0
    sim_seed: int | None = None
    sim_gaze: SimGazeParams | None = None
    #: seconds of each instruction/break screen in a dry run (no key presses there)
    dry_message_s: float = 0.2


class Aborted(Exception):
    """The operator quit (Escape then Q); progress is saved."""


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
        self.info.update(update)
        write_json_atomic(self._session_path(), self.info)

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
    def run(self, screen_factory: Any = None, gaze: Any = None) -> int:
        """Run the remaining trials; returns an exit status (0 done, 3 aborted, 130 killed)."""
        proto = self.protocol
        if not self.remaining:
            if not self.info.get("completed"):
                self.finish_without_trials()
            return EXIT_OK
        try:
            self.gaze = gaze if gaze is not None else self.make_gaze()
            if screen_factory is None:
                from .window import PsychoScreen

                screen_factory = PsychoScreen
            # The window and its display check come first: a failed check writes nothing.
            size = self.opts.window_size or (self.display.width_px, self.display.height_px)
            self.screen = screen_factory(
                size=size, fullscreen=self.opts.fullscreen and not self.opts.dry_run,
                cross_px=self._cross_px(size), dry_run=self.opts.dry_run,
                refresh_hz=self.display.refresh_hz)
            check = self._check_display()
        except BaseException:
            self.release()
            raise
        if isinstance(self.gaze, MouseGaze):
            self.gaze.position = self.screen.mouse_position
        self._start_info()
        self._write_info(display_check=check)
        self.trial_log = TrialLog(self.folder / "trials.csv")
        sid = self.session_id
        self.gaze_log = BatchLog(self.folder / f"gaze-{sid}.csv", GAZE_COLUMNS)
        self.frame_log = BatchLog(self.folder / f"frames-{sid}.csv", FRAME_COLUMNS)
        self.blank_log = BatchLog(self.folder / f"blanking-{sid}.csv", BLANKING_COLUMNS)
        flusher = PeriodicFlusher([self.gaze_log, self.frame_log, self.blank_log]).start()
        old_handlers = self._install_signals()
        state = "interrupted"
        code = EXIT_INTERRUPTED
        failure: str | None = None
        try:
            from .render import TestRenderer

            self.renderer = TestRenderer(self.display, proto.spec.preset,
                                         proto.spec.geometry_model, self.opts.backend)
            self._write_info(render=self.renderer.info())
            self.gaze.start()
            self._write_info(tracker=self.gaze.info())
            if self.opts.dry_run:
                self.sim = SimulatedParticipant(self.opts.sim_truth, self._sim_seed() + 1,
                                                self.opts.sim_speed, self.opts.sim_noise_scale)
            self._tracker_setup()
            self._instructions()
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
            self._write_info(state=state if not (state == "completed" and not complete)
                             else "incomplete", completed=complete, ended=now_iso(),
                             n_completed=len(done), events=self.info.get("events", []), **extra)
            self.release()
        return code

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
        self.info.setdefault("events", []).append({"time": now_iso(), "event": kind, **detail})
        self._write_info()

    def _message(self, text: str, keys: list[str], timeout_s: float | None = None) -> str | None:
        """A message screen; the gaze stream keeps going into the gaze log meanwhile (a long
        break would otherwise overflow the tracker's buffer)."""
        if self.opts.dry_run:
            timeout_s = self.opts.dry_message_s
        return self.screen.message(text, keys, timeout_s, self._drain_gaze)

    def _drain_gaze(self) -> None:
        """Samples that arrived outside a trial's frame loop, into the gaze log (trial empty)."""
        self.gaze_log.extend(self._gaze_rows(None, self.gaze.poll()))

    # -- tracker calibration and validation ------------------------------------------------------
    def _tracker_setup(self) -> None:
        """Calibrate (Tobii) and validate; refuse to start when accuracy is worse than the
        protocol's limit (``tracker.max_accuracy_deg``) or too many samples were lost
        (``tracker.max_data_loss``). A failed calibration or validation offers a new one."""
        spec = self.protocol.spec.tracker
        if not getattr(self.gaze, "validated", True):  # the mouse (and test scripts)
            self.info["tracker_quality"].append({"time": now_iso(), "skipped": self.gaze.name})
            self._write_info()
            return
        while True:
            if hasattr(self.gaze, "calibrate"):  # a real tracker
                self._message("Eye-tracker calibration: look at each dot until it moves.\n\n"
                              "Press Space to start.", ["space"])
                cal = self.gaze.calibrate(target_points(spec.calibration_points),
                                          self._show_calibration_point)
            else:
                cal = {"status": "simulated", "failed": False}
            if cal.get("failed"):
                self.info["tracker_quality"].append({"time": now_iso(), "calibration": cal})
                self._write_info()
                self._retry_or_stop(f"eye-tracker calibration failed ({cal.get('reason')})")
                continue
            per_target = []
            for x, y in target_points(spec.validation_points):
                self.screen.show_point(x, y)
                per_target.append(((x, y), self._collect(x, y)))
            res = validation_result(self.fixation, per_target, spec.max_accuracy_deg,
                                    spec.max_data_loss)
            self.info["tracker_quality"].append(
                {"time": now_iso(), "calibration": cal, "validation": res.to_dict()})
            self._write_info()
            if res.failure is None:
                self._message(f"Eye tracker OK. {res.summary()}", ["space"], 1.0)
                return
            self._retry_or_stop(f"eye-tracker validation failed: {res.failure}",
                                res.summary(), accuracy_deg=res.accuracy_deg,
                                data_loss=res.data_loss)

    def _retry_or_stop(self, why: str, detail: str = "", **event: Any) -> None:
        """R recalibrates (returns); anything else stops the session with ``why``."""
        key = self._message(f"{why[0].upper()}{why[1:]}.\n{detail}\n\nR: recalibrate    Q: quit",
                            ["r", "q"])
        if key != "r":
            self._event("tracker_setup_failed", reason=why, **event)
            raise FovexpError(f"{why} ({detail})" if detail else why)

    def _show_calibration_point(self, x: float, y: float) -> None:
        self.screen.show_point(x, y)
        t_end = time.monotonic() + 1.0
        while time.monotonic() < t_end:
            self.screen.show_point(x, y)

    def _collect(self, x: float, y: float, settle_s: float = 0.5,
                 collect_s: float = 0.8) -> list[GazeSample]:
        if isinstance(self.gaze, SimulatedGaze):
            self._drain_gaze()  # the stream so far; the simulated eye then "looks" at the dot
            return self.gaze.fixate((x, y), int(collect_s * self.gaze.p.rate_hz))
        t0 = time.monotonic()
        out: list[GazeSample] = []
        while time.monotonic() - t0 < settle_s + collect_s:
            self.screen.show_point(x, y)
            s = self.gaze.poll()
            self.gaze_log.extend(self._gaze_rows(None, s))
            if time.monotonic() - t0 >= settle_s:
                out.extend(s)
        return out

    # -- instructions, practice, trials, breaks --------------------------------------------------
    def _instructions(self) -> None:
        text = self.protocol.spec.instructions.strip() or "Adjust the right half to match the left."
        resumed = " (continuing where the last session stopped)" if self.done else ""
        self._message(f"{self.protocol.spec.title}{resumed}\n\n{text}\n\nPress Space to start.",
                      ["space"])

    def _trials(self) -> None:
        spec = self.protocol.spec
        main_done_this_run = 0
        practice_announced = False
        main_announced = bool(self.done)
        for trial in self.remaining:
            if trial.practice and not practice_announced:
                practice_announced = True
                self._message("Practice trials first.\n\nPress Space.", ["space"])
            if not trial.practice and not main_announced:
                main_announced = True
                if practice_announced:
                    self._message("Practice finished. The experiment starts now.\n\n"
                                  "Press Space.", ["space"])
            attempt = 0  # a pause or a lost tracker restarts the trial: the next attempt
            while True:
                outcome = self._run_trial(trial, attempt)
                if outcome == "done":
                    break
                attempt += 1
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
            if not trial.practice:
                main_done_this_run += 1
                left = len([t for t in self.remaining if t.index > trial.index])
                if spec.break_every and left and main_done_this_run % spec.break_every == 0:
                    self._message(f"Break. {left} trials to go.\n\nPress Space to continue.",
                                  ["space"])

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
            key = self.screen.message(text, ["q"], 0.1, self._drain_gaze)
            if key == "q":
                self._event("aborted", trial_index=trial.index)
                raise Aborted()
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
        in it, and Enter pressed while a newer render is pending is accepted on the first frame
        that shows it (``final_value`` is the value the participant saw when confirming). Every
        frame goes to the frame log as it is shown and every attempt's blanking episodes to the
        blanking log, however the attempt ends (an interrupted one included), tagged with
        ``attempt``.
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
        latest = self.renderer.request(self._params(trial, adjuster.value))
        # The cross alone while the first frame of the trial is computed.
        while True:
            try:
                shown_serial, shown_params, right, _ = self.renderer.wait(latest, timeout=0.05)
                break
            except TimeoutError:
                self.screen.draw(blank=True)
                self._drain_gaze()
        self.screen.set_test(right)
        st.show(float(getattr(shown_params, adj.parameter)))
        monitor = BlankingMonitor(self.fixation, spec.fixation.radius_deg,
                                  spec.fixation.gaze_timeout_s)
        if self.sim is not None:
            self.sim.begin(adj.parameter, trial.method, trial.blur_rate, trial.s_f,
                           adj.range[0], adj.range[1], adj.step, adj.fine_step)
        # Samples from before the stimulus belong to no trial, but they tell the monitor where
        # the gaze is, so the first frame is not blanked as "lost".
        early = self.gaze.poll()
        monitor.update(early, self.gaze.now_us())
        self.gaze_log.extend(self._gaze_rows(None, early))
        decision = None
        confirmed = False  # Enter pressed; waiting for the pending render to be shown
        drawn_serial = -1  # the render in the last frame drawn
        try:
            while True:
                for ev in self.gaze.poll_events():
                    self._event(ev.kind, trial_index=trial.index, **ev.detail)
                if not self.gaze.connected:
                    return "disconnected"  # the trial restarts once the tracker is back
                samples = self.gaze.poll()
                decision = monitor.update(samples, self.gaze.now_us())
                self.gaze_log.extend(self._gaze_rows(trial.index, samples))
                events = self.screen.poll_input()
                if confirmed:
                    # After Enter only a pause counts; the wheel no longer changes the value.
                    events = [e for e in events if isinstance(e, Key) and e.name == "escape"]
                elif self.sim is not None and st.t_start is not None:
                    t_trial = time.monotonic() - st.t_start
                    events = events + self.sim.poll(t_trial, st.value, not decision.blank)
                outcome = st.handle(events)
                if outcome == "pause":
                    return "pause"
                if outcome == "confirm":
                    confirmed = True
                    st.confirm(time.monotonic())
                if outcome == "changed":
                    latest = self.renderer.request(self._params(trial, st.value))
                got = self.renderer.poll()
                if got is not None:
                    shown_serial, shown_params, right, _ = got
                    self.screen.set_test(right)
                    st.show(float(getattr(shown_params, adj.parameter)))
                if confirmed and drawn_serial >= latest:
                    break  # the last frame drawn showed the confirmed value
                t = self.screen.draw(blank=decision.blank)
                drawn_serial = shown_serial
                dt, dropped = st.flip(t, decision.blank, decision.reason)
                self.frame_log.add((trial.index, attempt, st.n_frames - 1, round(t, 6),
                                    None if dt is None else round(dt, 6), dropped,
                                    decision.blank, st.shown_value))
        finally:
            st.finish(time.monotonic())
            self.blank_log.extend(
                (trial.index, attempt, round(e.start_s, 6), round(e.end_s, 6), e.frames,
                 e.reason) for e in st.blanking.episodes if e.end_s is not None)
        # Side logs first (synced), then the trial row: the row is the commit point.
        for log in (self.gaze_log, self.frame_log, self.blank_log):
            log.flush(sync=True)
        self.trial_log.append(self._row(trial, st))
        self.done.add(trial.index)
        return "done"

    def _gaze_rows(self, trial_index: int | None, samples: list[GazeSample]) -> list[Any]:
        return [sample_row(trial_index, s, self.fixation.eccentricity(s.point)) for s in samples]

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
