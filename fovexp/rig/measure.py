"""The rig check's measurements, on the session's own parts: its window (``PsychoScreen``),
renderer (``TestRenderer``), gaze sources and frame loop (``TrialLoop``, the one every trial
runs through; the rig check only adds measuring around it).

Phases, in one window at the display's resolution (a dry run's: 480x270 under Xvfb):

1. **refresh**: blank frames with the cross for ``duration_s`` (the photodiode patch on its
   pattern when asked), flip times logged; the gaze source polled as in a session, and its
   clock read against PsychoPy's after every flip;
2. **wheel step**: the first image's start value, then one wheel step, rendered by the chosen
   backend (the session's start-of-run measurement, ``render_budget.time_renders``);
3. **load**: ``duration_s`` of the session's frame loop: the two textured halves at the
   window's resolution, a wheel step every 100 ms rendered on the chosen backend, the gaze
   source polled, every frame's row as the frame log has it;
4. **GPU stages**: ``fovexp.profile_stages`` on the test half the session renders.
"""

from __future__ import annotations

import math
import platform
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fovexp import FovexpError, find_protocol, load_display, make_enhancer

from . import checks as C
from .report import protocol_text

#: the simulated participant turns the wheel this often during the load phase (s)
WHEEL_EVERY_S = 0.1


@dataclass
class RigOptions:
    """What ``fovexp rig check`` was asked (docs/EXPERIMENT.md, "The rig check")."""

    results_root: Path = Path("results")
    #: a protocol's name or file (``fovexp.rig.cli.rig_protocol`` chooses it)
    protocol: str | Path = "validation"
    #: why that protocol, for the report ("the study folder's own", "--protocol", ...)
    protocol_chosen: str = "the default"
    dry_run: bool = False
    duration_s: float = C.MIN_REFRESH_S
    tracker: str | None = None
    tracker_config: Path | None = None
    tracker_address: str | None = None
    backend: str = "auto"
    screen: int = 0
    window: tuple[int, int] | None = None
    photodiode: bool = False
    stimuli: Path | None = None
    console: Callable[[str], None] = field(default=lambda line: None)


@dataclass
class Measured:
    """Everything measured, for the report."""

    checks: list[C.Check] = field(default_factory=list)
    sections: dict[str, Any] = field(default_factory=dict)
    photodiode_rows: list[tuple[Any, ...]] = field(default_factory=list)


def _pct(v: list[float], q: float) -> float:
    return float(np.percentile(v, q)) if v else math.nan


def load_rig_protocol(opts: RigOptions) -> tuple[Any, dict[str, Any]]:
    """The protocol ``opts`` names, loaded as for a session (its display, stimulus folder,
    tracker settings; not its dependencies: a rig check runs no trial), and the report's
    ``protocol`` section: which one, from which file, and why that one."""
    from fovexp.experiment.protocol.spec import load_protocol

    path = find_protocol(opts.protocol)
    protocol = load_protocol(path, check_dependencies=False, results_root=opts.results_root,
                             stimuli=opts.stimuli)
    return protocol, {"experiment": protocol.experiment, "path": str(path),
                      "sha256": protocol.sha256, "chosen": opts.protocol_chosen}


def run_measurements(opts: RigOptions) -> Measured:
    """The whole check (module docstring); returns the figures and verdicts."""
    from fovexp.experiment.display.checks import cross_px, keys_at_poll
    from fovexp.experiment.display.render import TestRenderer
    from fovexp.experiment.display.render_budget import step_values, time_renders
    from fovexp.experiment.display.window import PsychoScreen
    from fovexp.experiment.tasks.frameloop import (
        LateLatch,
        TrialIO,
        TrialLoop,
        display_thread_first,
    )
    from fovexp.experiment.tasks.trial import TrialState, ValueAdjuster, Wheel
    from fovexp.experiment.trackers import make_gaze_source
    from fovexp.experiment.trackers.gaze import BlankDecision, BlankingMonitor, FixationGeometry
    from fovexp.experiment.trackers.iohub import RateMeter
    from fovexp.stimuli.folder import DRY_RUN_SIZE, load_stimulus, split_screen

    class NeverBlank(BlankingMonitor):
        """The session's blanking monitor (the sample each frame used: the latency), with the
        halves always drawn: a rig check measures the session's load without a participant
        in front of the tracker."""

        def update(self, samples: list[Any], now_us: int) -> BlankDecision:
            d = super().update(samples, now_us)
            return BlankDecision(False, "", d.eccentricity_deg)

    out = Measured()
    say = opts.console
    protocol, about = load_rig_protocol(opts)
    spec = protocol.spec
    say(f"fovexp rig check: protocol {protocol_text(about)}")
    display = load_display(protocol.display_name)
    fixation = FixationGeometry(display)
    w_px, h_px = opts.window or (DRY_RUN_SIZE if opts.dry_run else protocol.native_size)
    size = (int(w_px), int(h_px))
    images = protocol.prepare_images(size, opts.dry_run)
    seed, trials = protocol.plan("rig", 1, 0)
    trial = trials[0]
    virtual = opts.dry_run

    # -- the gaze source (before any window, as a session) ----------------------------------
    kind = opts.tracker or ("simulated" if opts.dry_run else "tobii")
    error = ""
    try:
        gaze = make_gaze_source(kind, protocol=protocol, display=display, fixation=fixation,
                                dry_run=opts.dry_run, screen=opts.screen,
                                tracker_address=opts.tracker_address,
                                tracker_config=opts.tracker_config)
        found = True
    except FovexpError as exc:
        from fovexp.experiment.trackers.simulated import SimulatedGaze

        error, found = str(exc), False
        say(f"fovexp rig check: tracker: {exc}; the display and GPU are checked with "
            "simulated gaze")
        gaze = SimulatedGaze(fixation, seed=1)
    out.checks.append(C.tracker_found_check(found, C.source_name(kind, gaze.name), error))

    screen = PsychoScreen(size=size, fullscreen=not opts.dry_run,
                          cross_px=cross_px(size, display, fixation.ppd_centre,
                                            spec.fixation.cross_size_deg),
                          dry_run=opts.dry_run, refresh_hz=display.refresh_hz, screen=opts.screen,
                          command="fovexp rig check")
    window = screen.info()
    out.checks.append(C.keyboard_check((window.get("keyboard") or {}).get("backend"),
                                       keys_at_poll(window), virtual))
    renderer = None
    try:
        attach = getattr(gaze, "attach", None)
        if attach is not None:
            attach(screen)
        gaze.start()
        nominal_rate = getattr(gaze, "rate_hz", None) or spec.tracker.sampling_hz
        meter = RateMeter(nominal_rate)
        samples: list[Any] = []

        def keep(got: list[Any]) -> None:
            samples.extend(got)
            meter.add([s.device_time_us for s in got])

        def take() -> None:
            keep(gaze.poll())

        # 1. refresh (and the photodiode, and the clocks) ---------------------------------
        say(f"fovexp rig check: display: {opts.duration_s:g} s of frames")
        pattern = C.photodiode_pattern(31)
        flips: list[float] = []
        clock_x: list[float] = []
        clock_y: list[int] = []
        t_cap = time.monotonic() + 2 * opts.duration_s + 5.0  # a display that never flips
        k = 0
        # until the flips span the duration (the rate is judged over at least 10 s of them)
        while (len(flips) < 2 or flips[-1] - flips[0] < opts.duration_s) \
                and time.monotonic() < t_cap:
            if opts.photodiode:
                screen.photodiode = pattern[k % 31]
            t = _flip_s(screen.draw(blank=True))
            now_us = gaze.now_us()
            mono = time.monotonic()
            flips.append(t)
            clock_x.append(mono)
            clock_y.append(now_us)
            if opts.photodiode:
                out.photodiode_rows.append(
                    (k, int(bool(screen.photodiode)), round(t, 6),
                     now_us - round((mono - t) * 1e6)))
            gaze.poll_events()  # status changes only: the checks read the samples
            take()
            k += 1
        screen.photodiode = None
        refresh_s = flips[-1] - flips[0] if len(flips) > 1 else 0.0
        measured_hz = C.refresh_rate_hz(flips)
        nominal_hz = float(screen.refresh_hz) if opts.dry_run else float(display.refresh_hz)
        out.checks.append(C.refresh_check(measured_hz, nominal_hz, refresh_s, display.name,
                                          virtual))
        refresh_stats = C.interval_stats(flips, nominal_hz)

        # 2. the renderer and a wheel step ----------------------------------------------
        image = images[trial.image]
        if image.path is None:
            raise FovexpError(f"image {trial.image}: no file (fovexp stimuli check)")
        frame = split_screen(load_stimulus(image.path, size, scale=image.scaled))
        w = frame.shape[1]
        screen.set_reference(frame[:, : w // 2])
        share = getattr(screen, "gl_share", None)
        renderer = TestRenderer(display, spec.preset, spec.geometry_model, opts.backend,
                                gl_share=share() if share is not None and opts.backend != "cpu"
                                else None)
        info = renderer.info()
        renderer.set_image(frame[:, w // 2:], (w, frame.shape[0]))
        adj = spec.adjust

        def cross_alone() -> None:
            screen.draw(blank=True)
            take()

        first_s, step_s = time_renders(
            renderer, [protocol.make_params(trial, v, seed) for v in step_values(
                trial.start_value, adj.step, adj.range[1])], cross_alone)
        out.checks.append(C.wheel_step_check(1e3 * step_s, spec.render.max_step_ms,
                                             str(info["backend"]), virtual))
        if opts.backend == "auto":
            auto = info
        else:
            probe = make_enhancer(display, preset=spec.preset, backend="auto")
            auto = {"backend": probe.backend, "fallback": getattr(probe, "fallback_reason",
                                                                  None)}
            close = getattr(probe, "close", None)
            if close is not None:
                close()
        out.checks.append(C.auto_backend_check(auto, virtual))

        # 3. the session's load, through the session's frame loop -------------------------
        say(f"fovexp rig check: the session's load: {opts.duration_s:g} s of frames")
        lo, hi = adj.range
        adjuster = ValueAdjuster(lo, hi, adj.step, adj.fine_step, trial.start_value)
        st = TrialState(adjuster, nominal_hz)
        rows: list[tuple[Any, ...]] = []
        timings: list[Any] = []
        ticks: dict[str, Any] = {"next": WHEEL_EVERY_S, "dir": 1}

        def participant(t: float, value: float, judgeable: bool) -> list[Any]:
            if t < ticks["next"]:
                return []
            ticks["next"] += WHEEL_EVERY_S
            if not lo <= adjuster.value + ticks["dir"] * adj.step <= hi:
                ticks["dir"] *= -1
            return [Wheel(ticks["dir"])]

        # a rig check has no participant: the halves are drawn whatever the gaze says
        monitor = NeverBlank(fixation, spec.fixation.radius_deg, spec.fixation.gaze_timeout_s)
        latch = LateLatch(1.0 / nominal_hz)  # as a session: the gaze read late in each frame
        loop = TrialLoop(screen=screen, gaze=gaze, renderer=renderer, monitor=monitor, state=st,
                         params_for=lambda v: protocol.make_params(trial, v, seed),
                         parameter=adj.parameter, trial_index=0, attempt=0,
                         participant=participant, timings=timings, latch=latch,
                         io=TrialIO(frame=rows.append, gaze=lambda i, a, got: keep(got),
                                    event=lambda kind, detail: None))
        loop.show_first()
        t0 = time.monotonic()
        with display_thread_first() as priority:
            outcome = loop.run(max_s=opts.duration_s)
        load_s = time.monotonic() - t0
        flip_times = [r[3] for r in rows]
        load_stats = C.interval_stats(flip_times, nominal_hz)
        out.checks.append(C.dropped_check(load_stats, virtual))
        uploads = [1e3 * t.upload_s for t in timings if t.upload_s is not None]
        handover_p99 = _pct(uploads, 99)
        out.checks.append(C.handover_check(handover_p99 if uploads else None, nominal_hz,
                                           str(info.get("output")), virtual))
        latency = [(r[10] - r[8]) / 1e3 for r in rows if r[8] is not None]

        # 4. GPU stages of the half the session renders -------------------------------------
        half = frame[:, w // 2:]
        gpu: dict[str, Any] = {}
        why_not = ""
        try:
            from fovexp import profile_stages

            say("fovexp rig check: GPU: per-stage time of the test half")
            prof = profile_stages(display, half, protocol.make_params(
                trial, trial.start_value, seed), repeats=3 if opts.dry_run else 11,
                warmup=1 if opts.dry_run else 2)
            gpu = prof.as_dict()
            frame_ms: float | None = float(prof.frame_ms)
        except Exception as exc:  # no GL 4.5 context here, or the driver's error
            frame_ms, why_not = None, f"not measured: {type(exc).__name__}: {exc}"
        out.checks.append(C.gpu_frame_check(frame_ms, nominal_hz, (half.shape[1],
                                                                   half.shape[0]),
                                            virtual, why_not))

        # -- the tracker -----------------------------------------------------------------------
        got_rate = meter.rate_hz
        simulated = gaze.name == "simulated"
        if found:
            out.checks.append(C.rate_check(None if got_rate is None else round(got_rate, 3),
                                           nominal_rate, simulated))
            span_us = (samples[-1].system_time_us - samples[0].system_time_us
                       if len(samples) > 1 else 0)
            expected = nominal_rate * span_us / 1e6 + 1 if span_us else 0
            loss = max(0.0, 1.0 - len(samples) / expected) if expected else None
            out.checks.append(C.loss_check(loss, simulated))
            out.checks.append(C.latency_check(_pct(latency, 95) if latency else None, virtual))
            fit = C.clock_fit(clock_x, clock_y)
            out.checks.append(C.clock_check(fit, virtual))
            out.checks.append(C.clock_jitter_check(fit, virtual))
        else:
            fit = C.clock_fit([], [])
            loss = None
        device_fit = C.clock_fit([s.device_time_us / 1e6 for s in samples],
                                 [s.system_time_us for s in samples])
        invalid = (sum(not s.valid for s in samples) / len(samples)) if samples else None

        out.sections = {
            "protocol": about,
            "display": {
                "profile": display.name, "profile_refresh_hz": display.refresh_hz,
                "profile_size": [display.width_px, display.height_px],
                "window_size": list(size), "screen": opts.screen,
                "framebuffer_size": list(screen.measure_display()[2]) if not opts.dry_run
                else list(size),
                "refresh": {"measured_hz": measured_hz, "compared_with_hz": nominal_hz,
                            "seconds": round(refresh_s, 3), **refresh_stats},
                "load": {"seconds": round(load_s, 3), "outcome": outcome,
                         "wheel_steps": adjuster.notches, "renders_shown": len(uploads),
                         **load_stats, "display_thread": priority,
                         "late_latch": latch.info()},
                "virtual": virtual,
            },
            "gpu": {"renderer": info, "auto": {k: auto.get(k) for k in ("backend", "fallback")},
                    "gl_version": _gl_version(), "wheel_step": {
                        "parameter": adj.parameter, "first_render_ms": round(1e3 * first_s, 2),
                        "step_ms": round(1e3 * step_s, 2),
                        "max_step_ms": spec.render.max_step_ms},
                    "handover_ms": {"p50": _pct(uploads, 50), "p99": handover_p99,
                                    "max": max(uploads) if uploads else math.nan,
                                    "n": len(uploads)},
                    "stages": gpu or {"not_measured": why_not}},
            "tracker": {
                "found": found, "kind": kind, "error": error or None,
                "info": gaze.info() if found else None,
                "nominal_rate_hz": nominal_rate,
                "rate": meter.to_dict(), "samples": len(samples), "missing_fraction": loss,
                "invalid_fraction": invalid,
                "gaze_to_flip_ms": {"p50": _pct(latency, 50), "p95": _pct(latency, 95),
                                    "max": max(latency) if latency else math.nan,
                                    "frames": len(latency),
                                    "definition": "flip_system_time_us - gaze_system_time_us "
                                                  "of the frame log"},
                "clock_vs_psychopy": {**fit, "reference": "PsychoPy's clock (time.monotonic: "
                                      "what flip times are on)", "clock": "the source's now_us"},
                "device_vs_system": device_fit,
            },
        }
        if opts.photodiode:
            out.sections["photodiode"] = {
                "patch": "bottom-left corner, white / black", "frames": len(
                    out.photodiode_rows),
                "pattern": "31-frame maximal-length sequence (x^5 + x^2 + 1), from frame 0",
            }
    finally:
        for step in (gaze.stop, getattr(renderer, "close", None), screen.close):
            if step is not None:
                try:
                    step()
                except Exception:  # closing after an error must not hide it
                    pass
    out.sections["machine"] = {"platform": platform.platform(), "node": platform.node(),
                               "python": platform.python_version()}
    return out


def _flip_s(flip: Any) -> float:
    """A flip's time (s, ``time.monotonic``): a screen's ``draw`` returns it, or a
    ``FlipTimes`` whose ``flip_s`` it is."""
    return float(getattr(flip, "flip_s", flip))


def _gl_version() -> dict[str, str | None]:
    """The window's GL_VERSION and GL_RENDERER (PsychoPy's context, current on this thread)."""
    try:
        import ctypes

        from pyglet import gl

        def s(name: Any) -> str | None:
            p = gl.glGetString(name)
            v = ctypes.cast(p, ctypes.c_char_p).value if p else None
            return None if v is None else v.decode()

        return {"version": s(gl.GL_VERSION), "renderer": s(gl.GL_RENDERER),
                "vendor": s(gl.GL_VENDOR)}
    except Exception:
        return {"version": None, "renderer": None, "vendor": None}


__all__ = ["Measured", "RigOptions", "load_rig_protocol", "run_measurements"]
