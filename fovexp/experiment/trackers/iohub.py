"""Any ioHub eye tracker as a gaze source (PsychoPy's common eye-tracker interface).

:class:`IoHubGaze` starts ioHub's server process with the lab's configuration
(:mod:`.families`: the same YAML PsychoPy Builder and ioHub use; the ``Display`` is the display
profile's) and satisfies :class:`~fovexp.experiment.interfaces.GazeSource`: the frame loop,
the blanking rule, the logs and the analysis do not change.

**Clock.** ioHub stamps every sample on PsychoPy's clock: its ``time`` field is the sample's
time in seconds on ``psychopy.clock.monotonicClock`` (ioHub's ``Computer.getTime()``; the
server process starts with this process's clock offset, so both read one clock), with the
transfer delay the plugin measures already subtracted (EyeLink's: ``time = logged_time -
delay``); ``device_time`` is the same sample on the tracker's own clock, in seconds. The logs'
columns (docs/LOGS.md) are::

    system_time_us = round(1e6 * time)          # gaze log, and the frame log's gaze_system_time_us
    device_time_us = round(1e6 * device_time)   # gaze log

and :meth:`IoHubGaze.now_us` reads ``Computer.getTime()`` in this process (no round trip to the
server), so the frame loop's flip (``now_us`` read right after it) and the samples are on one
clock: ``flip_system_time_us - gaze_system_time_us`` is the gaze-to-flip latency, as with a
Tobii (:func:`system_time_us`, :func:`device_time_us`; tested against the real server).

**Positions.** fovexp's ``Display`` reports positions in pixels from the screen's centre, y
up; :class:`PixelMap` turns them into the runner's normalised coordinates (origin top-left of
the window, y down; in a real session the window is the whole screen).

**Samples.** ``MonocularEyeSampleEvent`` (one eye: the other is invalid) and
``BinocularEyeSampleEvent`` / ``GazepointSampleEvent`` (both), by the field names of the event
class (:class:`SampleLayout`). An eye is valid when the sample's ``status`` does not flag it
missing (ioHub's convention: ``+20`` left eye missing, ``+2`` right eye missing; a monocular
sample: any non-zero status) and its position is finite; invalid and missing samples blank the
next frame as with every source.

**Lost tracker.** A reader thread asks the server for events every millisecond and puts them in
a :class:`~fovexp.experiment.trackers.gaze.SampleBuffer`; the frame loop only drains it (it never
waits on the server). The tracker is lost when the server process is gone (checked before every
request), when the tracker says it is not connected (``isConnected``, every 0.25 s), or when no
sample came for ``stall_s``: the frame loop then takes the lost-tracker path (black at once,
the trial restarts when the tracker is back). A server that exited is started again (once by
default); when that fails, :meth:`IoHubGaze.poll_events` raises one clear FovexpError and the
session ends saved.

**Calibration.** A tracker's own set-up (``runSetupProcedure``: on an EyeLink the camera set-up
of its host PC) through :class:`IoHubCalibration`; then fovexp's validation
(``fovexp.experiment.trackers.quality``), as for every tracker. MouseGaze has nothing to calibrate:
a pilot session skips the set-up as ``--tracker mouse`` does, and a dry run moves the pointer to
the targets itself (``pointer=True``: X's XTest, as xdotool does) so that the calibration
screen and the validation run on real ioHub samples.
"""

from __future__ import annotations

import atexit
import math
import socket
import tempfile
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fovexp import FovexpError

from .calibration import CalibrationOutcome, TrackerOwnCalibration
from .families import IoHubConfig, check_device_module, check_plugin, hub_config
from .gaze import GAZE_BUFFER_S, GazeSample, SampleBuffer, SourceEvent

#: ioHub's status flags of a binocular sample (its plugins' convention)
LEFT_MISSING = 20
RIGHT_MISSING = 2
#: ioHub's eye codes (``EyeTrackerConstants``)
LEFT_EYE, RIGHT_EYE = 21, 22
#: ``EyeTrackerConstants.EYETRACKER_INTERFACE_METHOD_NOT_SUPPORTED``
NOT_SUPPORTED = 202
#: the reader thread's pause between requests (s) and how often it asks the tracker's status
POLL_INTERVAL_S = 0.001
STATUS_INTERVAL_S = 0.25
#: a request the server has not answered in this long counts as unanswered (s)
RPC_TIMEOUT_S = 0.1


def system_time_us(iohub_time_s: float) -> int:
    """A sample's ``time`` (s on PsychoPy's clock, as ioHub stamps it) -> the logs'
    ``system_time_us`` (module docstring)."""
    return int(round(1e6 * float(iohub_time_s)))


def device_time_us(device_time_s: float) -> int:
    """A sample's ``device_time`` (s on the tracker's clock) -> the gaze log's
    ``device_time_us``."""
    return int(round(1e6 * float(device_time_s)))


@dataclass(frozen=True)
class PixelMap:
    """ioHub display positions (px from the centre of a ``display_px`` screen, y up) -> the
    runner's normalised coordinates of ``rect`` (the window on that screen: left, top, width,
    height in px from its top-left corner; x right, y down)."""

    display_px: tuple[int, int]
    rect: tuple[float, float, float, float]

    @classmethod
    def whole(cls, display_px: tuple[int, int]) -> PixelMap:
        return cls(display_px, (0.0, 0.0, float(display_px[0]), float(display_px[1])))

    def to_norm(self, x: float, y: float) -> tuple[float, float]:
        w, h = self.display_px
        left, top, rw, rh = self.rect
        return ((x + 0.5 * w - left) / rw, (0.5 * h - y - top) / rh)

    def to_screen_px(self, u: float, v: float) -> tuple[float, float]:
        """Normalised window coordinates -> px from the screen's top-left corner."""
        left, top, rw, rh = self.rect
        return left + u * rw, top + v * rh


@dataclass(frozen=True)
class SampleLayout:
    """Where an ioHub sample event class keeps its fields (indices into the event's list)."""

    device_time: int
    time: int
    status: int
    binocular: bool
    #: monocular: ``eye``, ``gaze_x``, ``gaze_y``; binocular: left and right gaze
    eye: int | None
    xy: tuple[int, int, int, int]

    @classmethod
    def of(cls, names: Sequence[str]) -> SampleLayout:
        """From the event class's ``CLASS_ATTRIBUTE_NAMES``."""
        ix = {n: i for i, n in enumerate(names)}
        if "left_gaze_x" in ix:
            return cls(ix["device_time"], ix["time"], ix["status"], True, None,
                       (ix["left_gaze_x"], ix["left_gaze_y"], ix["right_gaze_x"],
                        ix["right_gaze_y"]))
        return cls(ix["device_time"], ix["time"], ix["status"], False, ix["eye"],
                   (ix["gaze_x"], ix["gaze_y"], ix["gaze_x"], ix["gaze_y"]))


def _finite(*v: Any) -> bool:
    try:
        return all(math.isfinite(float(x)) for x in v)
    except (TypeError, ValueError):
        return False


def sample_from_event(ev: Sequence[Any], layout: SampleLayout, pixels: PixelMap) -> GazeSample:
    """A gaze sample from an ioHub sample event (a list, ``getEvents(asType='list')``): times
    by :func:`system_time_us` / :func:`device_time_us`, each eye's position normalised by
    ``pixels``, validity from the status flags (module docstring)."""
    status = int(ev[layout.status] or 0)
    lx, ly, rx, ry = (ev[i] for i in layout.xy)
    if layout.binocular:
        lv = status < LEFT_MISSING and _finite(lx, ly)
        rv = status % 10 != RIGHT_MISSING and _finite(rx, ry)
    else:
        ok = status == 0 and _finite(lx, ly)
        assert layout.eye is not None
        eye = int(ev[layout.eye] or 0)
        lv = ok and eye != RIGHT_EYE
        rv = ok and eye != LEFT_EYE
    nan = math.nan
    left = pixels.to_norm(float(lx), float(ly)) if lv else (nan, nan)
    right = pixels.to_norm(float(rx), float(ry)) if rv else (nan, nan)
    return GazeSample(device_time_us(ev[layout.device_time]), system_time_us(ev[layout.time]),
                      left[0], left[1], lv, right[0], right[1], rv)


def eyes_of(track_eyes: str | None, pilot: bool) -> tuple[str, ...]:
    """The eyes a configuration records (``runtime_settings.track_eyes``); MouseGaze's samples
    are the right eye's."""
    t = (track_eyes or "").upper()
    if pilot or t.startswith("RIGHT"):
        return ("right",)
    if t.startswith("LEFT"):
        return ("left",)
    return ("left", "right")


class RateMeter:
    """The sampling rate over a whole run from the samples' device times: intervals longer than
    ``gap_periods`` nominal periods (a lost tracker, a calibration) are left out."""

    def __init__(self, nominal_hz: float | None, gap_periods: float = 10.0) -> None:
        self.nominal_hz = nominal_hz
        self.gap_us = 1e6 * gap_periods / nominal_hz if nominal_hz else 50_000.0
        self.samples = 0
        self.span_us = 0.0
        self.intervals = 0
        self.gaps = 0
        self._last: int | None = None

    def add(self, device_times_us: Sequence[int]) -> None:
        for t in device_times_us:
            self.samples += 1
            if self._last is not None:
                dt = t - self._last
                if 0 < dt <= self.gap_us:
                    self.span_us += dt
                    self.intervals += 1
                elif dt > self.gap_us:
                    self.gaps += 1
            self._last = t

    @property
    def rate_hz(self) -> float | None:
        return self.intervals / (self.span_us / 1e6) if self.span_us > 0 else None

    def to_dict(self) -> dict[str, Any]:
        r = self.rate_hz
        return {"rate_hz": None if r is None else round(r, 3), "nominal_hz": self.nominal_hz,
                "samples": self.samples, "seconds": round(self.span_us / 1e6, 3),
                "gaps": self.gaps}


def _describe_exit(code: int) -> str:
    return f"killed by signal {-code}" if code < 0 else f"exit status {code}"


class IoHubGaze:
    """An ioHub eye tracker (module docstring). The server starts here, so that a missing
    plugin, a tracker that is not connected or a server that does not start stop the run
    before any window opens (one FovexpError).

    ``display`` is the display profile, ``screen`` the session's monitor; ``pointer``: a dry
    run's MouseGaze, whose :meth:`look_at` moves the pointer to calibration targets.
    """

    def __init__(self, config: IoHubConfig, display: Any, screen: int = 0, *,
                 pointer: bool = False, poll_interval_s: float = POLL_INTERVAL_S,
                 stall_s: float = 0.5, restarts: int = 1,
                 rpc_timeout_s: float = RPC_TIMEOUT_S) -> None:
        self.config, self.display, self.screen = config, display, int(screen)
        self.family = config.family
        self.plugin_version = check_plugin(self.family)
        # a class path no module answers to: one line here, not ioHub's tracebacks
        check_device_module(config)
        self.pilot = self.family.pilot
        self.pointer = bool(pointer and self.pilot)
        #: the trials' ``tracker`` column: a mouse is a pilot whatever carries it
        self.name = "mouse" if self.pilot else "iohub"
        #: calibrated and validated at the start (a pilot's mouse is not; a dry run's is)
        self.validated = not self.pilot or self.pointer
        self.eyes = eyes_of(config.track_eyes, self.pilot)
        self.rate_hz = config.sampling_hz
        self.poll_interval_s, self.rpc_timeout_s = float(poll_interval_s), float(rpc_timeout_s)
        self._stall_us = int(stall_s * 1e6)
        self._restarts = int(restarts)
        self.buffer = SampleBuffer(maxlen=int((self.rate_hz or 2000.0) * GAZE_BUFFER_S))
        self._notes = SampleBuffer(maxlen=1000)
        #: the connection's socket: one request and its reply at a time, whichever thread
        #: asks (PsychoPy's keyboard on the display thread shares it: PsychoScreen takes
        #: ioHub's keyboard when a server runs); re-entrant for a caller's own sections
        self._lock = threading.RLock()
        self._reader_send: Any = None
        self._halt = threading.Event()
        self._thread: threading.Thread | None = None
        self._recording = False
        self._calibrating = False
        self._connected = True
        self._stalled = False
        self._server_gone: str | None = None
        #: the frame loop saw the server's process gone (before the reader thread did)
        self._proc_dead = False
        self._fatal: str | None = None
        self._last_sample_us: int | None = None
        self._layouts: dict[int, SampleLayout] = {}
        self.meter = RateMeter(self.rate_hz)
        self.restarted = 0
        self.io: Any = None
        self.tracker: Any = None
        self._proc: Any = None
        self._config_file: Path | None = None
        self._launch()
        atexit.register(self._shutdown_server)

    # -- the server ------------------------------------------------------------------------------
    def _launch(self) -> None:
        """Start the server with the lab's tracker and fovexp's display (raises FovexpError)."""
        try:
            import yaml
            from psychopy.iohub import launchHubServer
            from psychopy.iohub.client import ioHubConnection
            from psychopy.iohub.constants import EventConstants
        except ImportError as exc:
            raise FovexpError(f"--tracker iohub needs PsychoPy's ioHub ({exc}): pip install "
                              "'fovexp[experiment]'") from None
        fam = self.family
        where = f"{fam.label} ({self.config.device_class}, {self.config.path})"
        self.orphans_stopped = stop_orphan_servers()
        # launchHubServer reads the Display from a file (keyword arguments would add a second)
        with tempfile.NamedTemporaryFile("w", suffix=".yaml", prefix="fovexp-iohub-",
                                         delete=False) as fh:
            yaml.safe_dump(hub_config(self.config, self.display, self.screen), fh)
            self._config_file = Path(fh.name)
        ioHubConnection.ACTIVE_CONNECTION = None  # a dead server's connection is not reused
        try:
            io = launchHubServer(iohub_config_name=str(self._config_file))
        except Exception as exc:  # ioHub raises bare RuntimeErrors and its own types
            raise FovexpError(f"the ioHub server did not start for the {where}: "
                              f"{type(exc).__name__}: {exc}") from None
        self.io, self._proc = io, io._server_process
        send = io._sendToHubServer

        def one_at_a_time(tx: Any) -> Any:
            with self._lock:
                return send(tx)

        io._sendToHubServer = one_at_a_time  # device views look it up at every call
        tracker: Any = getattr(io.devices, self.config.name, None)
        methods = getattr(tracker, "_methods", None) if tracker is not None else None
        if tracker is None or not isinstance(methods, (list, tuple)) \
                or "getEvents" not in methods:
            self._shutdown_server()
            raise FovexpError(
                f"the ioHub server could not create the {where}: its messages above say why "
                "(no tracker found or connected, a wrong address or model name, a missing "
                "vendor library)")
        self.tracker = tracker
        io.udp_client.sock.settimeout(self.rpc_timeout_s)
        self._reader_send = _own_socket_sender(io, self.rpc_timeout_s)
        try:
            cfg = tracker.getConfiguration() or {}
            res = io.devices.display.getPixelResolution()
        except Exception as exc:
            self._shutdown_server()
            raise FovexpError(f"the ioHub server does not answer for the {where}: "
                              f"{type(exc).__name__}: {exc}") from None
        self.device_config = dict(cfg)
        rt = cfg.get("runtime_settings") or {}
        if self.rate_hz is None and rt.get("sampling_rate") is not None:
            try:
                self.rate_hz = float(rt["sampling_rate"])
                self.meter = RateMeter(self.rate_hz)
            except (TypeError, ValueError):  # a plugin's "Auto", "default": no rate stated
                pass
        self.display_px = (int(res[0]), int(res[1]))
        if not hasattr(self, "pixels"):
            self.pixels = PixelMap.whole(self.display_px)
        self._layouts = {}
        types = [EventConstants.MONOCULAR_EYE_SAMPLE, EventConstants.BINOCULAR_EYE_SAMPLE,
                 getattr(EventConstants, "GAZEPOINT_SAMPLE", None)]
        for type_id in (t for t in types if t is not None):
            cls = EventConstants.getClass(type_id)
            if cls is not None:
                try:
                    self._layouts[int(type_id)] = SampleLayout.of(cls.CLASS_ATTRIBUTE_NAMES)
                except KeyError:  # a sample class without gaze fields
                    pass
        self._probe(where)
        self._own_move_callback()  # a new connection took the window's moves again

    def _probe(self, where: str, timeout_s: float = 3.0) -> None:
        """Record until the first sample arrives (a plugin may say it is connected when it is
        not: EyeLink's without its host PC): none within ``timeout_s`` stops the run."""
        tracker = self.tracker
        got = False
        try:
            tracker.setRecordingState(True)
            t_end = time.monotonic() + timeout_s
            while not got and time.monotonic() < t_end:
                evs = tracker.getEvents(asType="list") or []
                got = any(int(e[4]) in self._layouts for e in evs)
                time.sleep(0.01)
            tracker.setRecordingState(False)
        except Exception as exc:  # the plugin's own errors
            self._shutdown_server()
            raise FovexpError(f"the {where} failed when asked to record: "
                              f"{type(exc).__name__}: {exc}") from None
        if not got:
            self._shutdown_server()
            raise FovexpError(
                f"the {where} sent no gaze sample within {timeout_s:g} s of recording: check "
                "that it is connected and powered, its address, and that its vendor software "
                "sees it")

    def _shutdown_server(self) -> None:
        """Stop the server (asking it first; killed when it does not stop within 5 s)."""
        io, self.io = self.io, None
        proc = self._proc
        reader, self._reader_send = self._reader_send, None
        if reader is not None:
            reader.close()
        if io is not None:
            t = threading.Thread(target=io.quit, daemon=True, name="fovexp-iohub-quit")
            t.start()
            t.join(5.0)
        if proc is not None and proc.poll() is None:
            proc.kill()
        try:
            from psychopy.iohub.client import ioHubConnection

            ioHubConnection.ACTIVE_CONNECTION = None
        except ImportError:
            pass
        if self._config_file is not None:
            self._config_file.unlink(missing_ok=True)
            self._config_file = None

    @property
    def server_pid(self) -> int | None:
        return None if self._proc is None else int(self._proc.pid)

    # -- GazeSource --------------------------------------------------------------------------------
    def attach(self, screen: Any) -> None:
        """The session's window: positions are normalised over its area on the screen
        (``screen.window_rect()``; a full-screen window's is the whole screen)."""
        rect = getattr(screen, "window_rect", None)
        if rect is not None:
            left, top, w, h = rect()
            self.pixels = PixelMap(self.display_px, (float(left), float(top), float(w), float(h)))
        self._win = getattr(screen, "win", None)
        self._own_move_callback()

    def _own_move_callback(self) -> None:
        """ioHub's client asks its server on every move of a PsychoPy window (on the display
        thread, over the reader thread's socket): the window's moves update the map here
        instead."""
        win = getattr(self, "_win", None)
        if win is None:
            return

        def moved(_win: Any, x: int, y: int) -> None:
            _, _, w, h = self.pixels.rect
            self.pixels = PixelMap(self.display_px, (float(x), float(y), w, h))

        win.backend.onMoveCallback = moved

    def start(self) -> None:
        with self._lock:
            self.tracker.setRecordingState(True)
        self._recording = True
        self._last_sample_us = self.now_us()
        self._halt.clear()
        self._thread = threading.Thread(target=self._read, daemon=True, name="fovexp-iohub")
        self._thread.start()

    def stop(self) -> None:
        self._halt.set()
        if self._thread is not None:
            # a restart under way finishes first (then shuts its server down: see below)
            self._thread.join(60.0 if self._server_gone is not None else 2.0)
            self._thread = None
        if self.io is not None and self._server_gone is None:
            try:
                with self._lock:
                    self.tracker.setRecordingState(False)
            except Exception:  # stopping: the server may be gone already
                pass
        self._recording = False
        self._shutdown_server()

    def now_us(self) -> int:
        """PsychoPy's clock (ioHub's ``Computer.getTime()``), read in this process."""
        from psychopy.iohub.devices import Computer

        return system_time_us(Computer.getTime())

    @property
    def connected(self) -> bool:
        return (self._connected and not self._stalled and self._server_gone is None
                and not self._proc_dead)

    def poll(self) -> list[GazeSample]:
        out = []
        for ev, received_us in self.buffer.drain():
            layout = self._layouts.get(int(ev[4]))
            if layout is None:
                continue  # fixations, saccades, blinks: the samples say it all
            try:
                out.append(sample_from_event(ev, layout, self.pixels)._replace(
                    received_system_time_us=received_us))
            except (IndexError, TypeError, ValueError):
                continue  # a malformed sample counts as lost
        if out:
            self._last_sample_us = out[-1].system_time_us
            self.meter.add([s.device_time_us for s in out])
        return out

    def poll_events(self) -> list[SourceEvent]:
        events = []
        for kind, t_us, detail in self._notes.drain():
            if kind in ("connection_lost", "connection_restored"):
                self._connected = kind == "connection_restored"
                if self._connected:
                    self._last_sample_us = self.now_us()
            events.append(SourceEvent(kind, t_us, detail))
        if self._fatal is not None:
            raise FovexpError(self._fatal)
        proc = self._proc
        if proc is not None and self._server_gone is None and proc.poll() is not None:
            self._proc_dead = True  # lost now; the reader thread notes why and restarts it
        now = self.now_us()
        watch = self._recording and not self._calibrating and self._server_gone is None
        stalled = (watch and self._last_sample_us is not None
                   and now - self._last_sample_us > self._stall_us)
        if stalled != self._stalled:
            self._stalled = stalled
            events.append(SourceEvent("stream_stalled" if stalled else "stream_resumed", now, {}))
        return events

    def info(self) -> dict[str, Any]:
        cfg = getattr(self, "device_config", {})
        try:
            import psychopy

            pp = str(psychopy.__version__)
        except ImportError:
            pp = None
        fam = self.family
        return {
            "name": self.name, "source": "iohub", "family": fam.key, "label": fam.label,
            "device_class": self.config.device_class,
            "model": cfg.get("model_name"), "manufacturer": cfg.get("manufacturer_name"),
            "serial_number": cfg.get("serial_number"),
            "plugin": fam.distribution or "psychopy (built in)",
            "plugin_version": self.plugin_version or pp, "psychopy_version": pp,
            "nominal_rate_hz": self.rate_hz, "eyes": list(self.eyes),
            "track_eyes": (cfg.get("runtime_settings") or {}).get("track_eyes"),
            "calibration": ("the tracker's own (runSetupProcedure), then fovexp's validation"
                            if fam.calibration == "own" else "none (a pilot: the mouse)"
                            if not self.pointer else "fovexp's screen (a dry run's pointer)"),
            "clock": "system_time_us = round(1e6 * ioHub time), PsychoPy's clock; "
                     f"device_time_us = round(1e6 * device_time), {fam.clock}",
            "server_pid": self.server_pid, "config": self.config.to_dict(),
            "orphan_servers_stopped": getattr(self, "orphans_stopped", []),
            "display_px": list(getattr(self, "display_px", ())),
            "window_px": list(self.pixels.rect) if hasattr(self, "pixels") else None,
        }

    def measured(self) -> dict[str, Any]:
        """The sampling rate measured over the run so far, and the server restarts."""
        return {**self.meter.to_dict(), "server_restarts": self.restarted}

    # -- calibration -------------------------------------------------------------------------------
    def calibration(self) -> Any:
        """The calibration flow's backend: the tracker's own set-up, or (a dry run's MouseGaze)
        nothing to calibrate."""
        if self.pointer:
            return PointerCalibration()
        return IoHubCalibration(self)

    def look_at(self, target: tuple[float, float] | None) -> None:
        """A dry run's MouseGaze: the pointer to ``target`` (normalised; None: the cross)."""
        if not self.pointer:
            return
        u, v = target if target is not None else (0.5, 0.5)
        x, y = self.pixels.to_screen_px(u, v)
        move_pointer(int(round(x)), int(round(y)))

    def run_setup(self) -> dict[str, Any]:
        """``runSetupProcedure`` (blocking: minutes, with the operator at the tracker's own
        screens), the reader thread held off; the server watched meanwhile."""
        with self._lock:
            self._calibrating = True
            sock = self.io.udp_client.sock
            sock.settimeout(None)
            try:
                result = self.tracker.runSetupProcedure()
            except Exception as exc:  # the server gone meanwhile (woken by the reader thread)
                if self._server_gone is not None:
                    raise FovexpError(self._server_gone) from None
                raise FovexpError(f"the tracker's set-up failed: {type(exc).__name__}: "
                                  f"{exc}") from None
            finally:
                if self.io is not None:
                    sock.settimeout(self.rpc_timeout_s)
                self._calibrating = False
                self._last_sample_us = self.now_us()
        if self._server_gone is not None:
            raise FovexpError(self._server_gone)
        return {"result": result} if not isinstance(result, dict) else result

    # -- the reader thread -------------------------------------------------------------------------
    def _note(self, kind: str, **detail: Any) -> None:
        self._notes.append((kind, self.now_us(), detail))

    def _read(self) -> None:
        next_status = 0.0
        while not self._halt.is_set():
            proc = self._proc
            code = proc.poll() if proc is not None else None
            if code is not None:
                self._on_server_exit(int(code))
                continue
            rpc, device = self._reader_send, self.tracker.device_class
            status = None
            try:  # on the reader's own socket: no other thread's reply can be taken for its
                evs = rpc(device, "getEvents", asType="list")
                if evs is not None and time.monotonic() >= next_status:
                    next_status = time.monotonic() + STATUS_INTERVAL_S
                    status = rpc(device, "isConnected")
            except Exception:  # noqa: BLE001 (a reply that did not come; the server is checked)
                evs = None
            if evs is None:
                rpc.drain()
                continue
            received_us = self.now_us()  # when they reached the runner (the delivery latency)
            for ev in evs:
                self.buffer.append((ev, received_us))
            if isinstance(status, bool) and status != self._tracker_ok:
                self._tracker_ok = status
                self._note("connection_restored" if status else "connection_lost",
                           reason="the tracker reports it is " + ("connected" if status else
                                                                   "not connected"))
            self._halt.wait(self.poll_interval_s)

    _tracker_ok = True

    def _on_server_exit(self, code: int) -> None:
        """The server is gone: the tracker is lost (at once); start it again, or end the
        session with one line (:meth:`poll_events` raises it)."""
        pid = self.server_pid
        why = f"the ioHub server (pid {pid}) exited ({_describe_exit(code)})"
        self._server_gone = why
        self._note("connection_lost", reason=why)
        self._proc = None
        reader, self._reader_send = self._reader_send, None
        if reader is not None:
            reader.close()
        if self._calibrating and self.io is not None:  # its request would wait for ever
            try:
                wake_socket(self.io.udp_client.sock, why)
            except OSError:
                pass
        try:
            from psychopy.iohub.client import ioHubConnection

            ioHubConnection.ACTIVE_CONNECTION = None
            if self.io is not None:
                self.io._shutdown_attempted = True  # nothing left to ask it
        except ImportError:
            pass
        self.io = None
        error = ""
        for _ in range(self._restarts):
            try:
                self._launch()
                with self._lock:
                    self.tracker.setRecordingState(True)
            except Exception as exc:  # noqa: BLE001 (reported in the one line below)
                error = str(exc)
                self._shutdown_server()
                continue
            if self._halt.is_set():  # stopped meanwhile: no server may outlive the source
                self._shutdown_server()
                return
            self.restarted += 1
            self._server_gone = None
            self._proc_dead = False
            self._note("connection_restored", reason="the ioHub server was started again",
                       pid=self.server_pid)
            return
        self._fatal = (f"{why} and did not start again{': ' + error if error else ''}; "
                       "everything logged so far is saved")
        self._halt.set()


class _OwnSocketRPC:
    """Device calls to the server on a socket of the reader thread's own (ioHub's client has
    one socket per connection, and its replies carry no request id)."""

    def __init__(self, io: Any, timeout_s: float) -> None:
        from psychopy.iohub.net import UDPClientConnection

        self.io = io
        self.timeout_s = timeout_s
        port = (io._iohub_server_config or {}).get("udp_port", 9000)
        self.conn = UDPClientConnection(remote_port=port, timeout=timeout_s)

    def __call__(self, device: str, method: str, *args: Any, **kwargs: Any) -> Any:
        from psychopy.iohub.errors import ioHubError

        self.conn.sendTo(("EXP_DEVICE", "DEV_RPC", device, method, args, kwargs))
        got = self.conn.receive()  # None when no reply came in time
        if not got:
            return None
        reply = got[0]
        if type(self.io)._isErrorReply(reply):
            raise ioHubError(reply)
        if isinstance(reply, (list, tuple)):
            reply = self.io._convertList(reply)
        r = reply[1:]
        return r[0] if len(r) == 1 else r

    def drain(self) -> None:
        """A late reply must not be taken for the next request's."""
        sock = self.conn.sock
        try:
            sock.setblocking(False)
            while True:
                sock.recvfrom(65536)
        except OSError:  # BlockingIOError: nothing left
            pass
        finally:
            try:
                sock.settimeout(self.timeout_s)
            except OSError:
                pass

    def close(self) -> None:
        self.conn.close()


def _own_socket_sender(io: Any, timeout_s: float) -> _OwnSocketRPC:
    return _OwnSocketRPC(io, timeout_s)


class IoHubCalibration(TrackerOwnCalibration):
    """The tracker's own set-up (``runSetupProcedure``) as the calibration flow's backend
    (``fovexp.experiment.trackers.calibration.CalibrationBackend`` with ``own_procedure``): the flow
    runs it on its worker thread, shows what is going on meanwhile, then validates on fovexp's
    targets."""

    def __init__(self, gaze: IoHubGaze) -> None:
        self.gaze = gaze
        fam = gaze.family
        self.own_procedure = (
            "the EyeLink's camera set-up and calibration (on its host PC's screen and this one)"
            if fam.key == "eyelink" else f"the {fam.label}'s own calibration")

    def compute(self) -> CalibrationOutcome:
        result = self.gaze.run_setup()
        text = str(result.get("RESULT", result.get("result", result)))
        if result.get("result") == NOT_SUPPORTED:
            # no set-up through ioHub: calibrated with the vendor's software; the validation
            # measures the tracker as it is
            return CalibrationOutcome(failed=False, status="not offered through ioHub")
        failed = any(w in text.upper() for w in ("ABORT", "FAIL", "ERROR"))
        return CalibrationOutcome(failed=failed, status=text,
                                  reason=f"the tracker's set-up ended with {text}"
                                  if failed else "")


class PointerCalibration(TrackerOwnCalibration):
    """A dry run's MouseGaze: nothing to calibrate (the pointer is where :meth:`IoHubGaze.
    look_at` puts it); fovexp's screen shows its targets and validates."""

    def compute(self) -> CalibrationOutcome:
        return CalibrationOutcome(failed=False, status="MouseGaze: nothing to calibrate")


def stop_orphan_servers() -> list[int]:
    """Kill ioHub servers whose experiment process is gone (a session killed with SIGKILL
    leaves its server running, holding the tracker and ioHub's port); their pids. ioHub passes
    the experiment's pid as the server's last argument."""
    import psutil

    out = []
    for p in psutil.process_iter(["pid", "cmdline"]):
        cmd = p.info.get("cmdline") or []
        if len(cmd) < 5 or not str(cmd[1]).endswith("start_iohub_process.py"):
            continue
        try:
            parent = int(cmd[-1])
        except ValueError:
            continue
        if not psutil.pid_exists(parent):
            try:
                p.kill()
                out.append(int(p.info["pid"]))
            except psutil.Error:
                pass
    return out


_xdisplay: Any = None


def move_pointer(x: int, y: int) -> None:
    """The X pointer to screen pixel ``(x, y)`` through XTest (a device event, as xdotool's:
    ioHub's mouse sees it as a move)."""
    global _xdisplay
    from Xlib import X
    from Xlib.display import Display
    from Xlib.ext import xtest

    if _xdisplay is None:
        _xdisplay = Display()
    xtest.fake_input(_xdisplay, X.MotionNotify, x=x, y=y)
    _xdisplay.sync()


def wake_socket(sock: socket.socket, reason: str) -> None:
    """Send ``sock`` (a client's socket blocked waiting for the server's reply) an ioHub error
    reply, so that the request waiting on it raises instead of waiting for ever."""
    import msgpack

    port = sock.getsockname()[1]
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.sendto(msgpack.packb(("IOHUB_ERROR", reason)), ("127.0.0.1", port))


__all__ = ["IoHubCalibration", "IoHubGaze", "PixelMap", "PointerCalibration", "RateMeter",
           "SampleLayout", "device_time_us", "eyes_of", "move_pointer", "sample_from_event",
           "stop_orphan_servers", "system_time_us", "wake_socket"]
