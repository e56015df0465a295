"""The eye tracker's set-up around the trials, without a window of its own: the display area
its coordinates refer to, calibration and validation at the start (and when the operator or a
drift check asks), and the drift checks between trials.

The screens and their logic are :mod:`fovexp.experiment.trackers.calibration`'s; this module drives
them with a session's gaze source and screen, records every calibration and validation in the
session file's ``tracker_quality`` and the drift checks as events, and decides when a check is
due. The gaze stream keeps going into the gaze log meanwhile (between trials). Paper section
5.1 (Experiment Setup): a Tobii Pro Spectrum at 600 Hz, gaze kept within 1.25 deg of the cross.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

from fovexp import FovexpError
from fovexp.results.format import now_iso

from ..interfaces import GazeSource, Screen, SessionRecord
from ..protocol.spec import Trial
from .calibration import (
    CalibrationFlow,
    CalibrationTiming,
    DriftCheck,
    SimulatedCalibration,
)
from .gaze import DisplayArea, FixationGeometry, GazeSample, check_display_area
from .quality import target_points


class Aborted(Exception):
    """The operator quit (Escape, then Q to confirm); progress is saved."""


def display_area(gaze: GazeSource, display: Any,
                 display_name: str) -> tuple[DisplayArea, dict[str, Any]]:
    """The display area the gaze source's normalised coordinates refer to: a Tobii's own
    (refused when its size is more than a few mm off the display profile's), else the
    profile's nominal one. Returns it and what goes into the session file."""
    get = getattr(gaze, "display_area", None)
    area = get() if get is not None else DisplayArea.nominal(display)
    if area.source != "tracker":
        return area, {"source": area.source, "display_area": area.to_dict()}
    try:
        info = check_display_area(area, display)
    except FovexpError as exc:
        raise FovexpError(f"{exc} ({display_name})") from None
    return area, {"source": "tracker", **info}


def window_ppd(fixation: FixationGeometry, display: Any, window_width_px: int) -> float:
    """Window pixels per degree at the screen centre (a window smaller than the display, a dry
    run's, shows the same degrees in fewer pixels)."""
    return fixation.ppd_centre * window_width_px / display.width_px


def calibration_timing(given: CalibrationTiming | None, dry_run: bool) -> CalibrationTiming:
    """The calibration screens' durations: those given, else Titta's (a dry run's shorter)."""
    if given is not None:
        return given
    return CalibrationTiming.dry_run() if dry_run else CalibrationTiming()


class TrackerSetup:
    """Calibration, validation and drift checks of one run (module docstring).

    ``protocol_spec`` is the protocol's (its ``tracker``, ``fixation``, ``quality_limits``,
    ``drift_limit_deg``); ``seed`` seeds the simulated calibration's noise; ``gaze_sink`` takes
    the samples that arrive meanwhile (the gaze log, between trials); ``auto``: the screens
    answer themselves (dry runs)."""

    def __init__(self, *, gaze: GazeSource, screen: Screen, protocol_spec: Any,
                 area: DisplayArea, distance_mm: float, ppd_px: float,
                 timing: CalibrationTiming, auto: bool, seed: int, file: SessionRecord,
                 gaze_sink: Callable[[list[GazeSample]], None]) -> None:
        self.gaze, self.screen, self.spec = gaze, screen, protocol_spec
        self.area, self.distance_mm, self.ppd_px = area, distance_mm, ppd_px
        # a source that states its delivery latency (the simulated tracker's --gaze-latency-ms)
        # gets it, and four of its jitter's sd, on top of the wait for a window's late samples
        late_s = timing.late_s + 1e-3 * (getattr(gaze, "latency_ms", 0.0)
                                         + 4 * getattr(gaze, "latency_jitter_ms", 0.0))
        timing = dataclasses.replace(timing, late_s=late_s)
        self.timing, self.auto, self.seed = timing, auto, seed
        self.file, self.gaze_sink = file, gaze_sink
        #: main trials since the last drift check or calibration
        self.since_drift = 0

    @property
    def rate_hz(self) -> float:
        """The gaze source's nominal sampling rate (an ioHub tracker's configured one), else
        the protocol's: the validation's expected samples."""
        return float(getattr(self.gaze, "rate_hz", None) or self.spec.tracker.sampling_hz)

    @property
    def eyes(self) -> tuple[str, ...]:
        """The eyes the source records (both, unless a monocular tracker)."""
        return tuple(getattr(self.gaze, "eyes", ("left", "right")))

    @property
    def calibrated(self) -> bool:
        """Whether the source is calibrated at all (not the mouse, nor a test's script)."""
        return bool(getattr(self.gaze, "validated", True))

    def setup(self, reason: str = "start") -> None:
        """Calibrate and validate on the calibration screen
        (``fovexp.experiment.trackers.calibration``: head position, animated targets, per-point
        results with accept / redo). Every calibration and validation goes into the session
        file's ``tracker_quality`` (with ``reason``: ``start``, ``operator`` (C between trials)
        or ``drift``); only a validation within the protocol's limits can be accepted. A failed
        set-up at the start raises :class:`FovexpError` with the reason; the operator's Q
        (confirmed) raises :class:`Aborted` (progress saved)."""
        spec, info = self.spec, self.file.info
        if not self.calibrated:
            info["tracker_quality"].append({"time": now_iso(), "skipped": self.gaze.name})
            self.file.write()
            return
        if hasattr(self.gaze, "calibration"):  # a real tracker
            backend = self.gaze.calibration()
        else:
            backend = SimulatedCalibration(self.gaze)

        def record(rec: dict[str, Any], new: bool) -> None:
            if new:
                rec["reason"] = reason
                info["tracker_quality"].append(rec)  # the same dict: updates rewrite it
            self.file.write()

        flow = CalibrationFlow(
            backend, target_points(spec.tracker.calibration_points),
            target_points(spec.tracker.validation_points), spec.quality_limits, self.area,
            self.distance_mm, self.rate_hz, self.screen.size,
            self.ppd_px, spec.fixation.radius_deg, timing=self.timing,
            look_at=getattr(self.gaze, "look_at", None), on_record=record,
            auto=self.auto, seed=self.seed + len(info["tracker_quality"]),
            now_iso=now_iso, eyes=self.eyes)
        self.run_flow(flow)
        if flow.outcome == "accepted":
            self.since_drift = 0
            return
        if flow.outcome == "failed" or (reason == "start" and flow.failure):
            self.file.event("tracker_setup_failed", reason=flow.failure, stage=reason)
            raise FovexpError(flow.failure or "eye-tracker set-up failed")
        self.file.event("aborted", during=f"eye-tracker calibration ({reason})")
        raise Aborted()

    def run_flow(self, flow: CalibrationFlow | DriftCheck) -> None:
        """Drive a calibration screen or a drift check: draw its view, read the keys, feed it
        the gaze (which goes to the gaze log, between trials) until it has an outcome."""
        flow.start(self.gaze.now_us())
        try:
            while not flow.finished:
                keys = self.screen.calibration_frame(flow.view())
                for ev in self.gaze.poll_events():
                    self.file.event(ev.kind, **ev.detail)
                samples = self.gaze.poll()
                self.gaze_sink(samples)
                flow.feed(samples)
                flow.step(keys, self.gaze.now_us())
        finally:
            flow.close()

    def between_trials(self, trial: Trial, more_trials: bool) -> None:
        """After ``trial``: the operator's C (pressed during the trial or after it)
        recalibrates; D, or ``tracker.drift_check_every`` main trials since the last check or
        calibration, runs a drift check (:meth:`drift_check`). Nothing after the run's last
        trial (``more_trials`` False), nor with a source that is not calibrated (the mouse)."""
        keys = self.screen.take_operator_keys()
        if not self.calibrated or not more_trials:
            return
        self.since_drift += not trial.practice
        every = self.spec.tracker.drift_check_every
        if "c" in keys:
            self.file.event("recalibration", reason="operator", after_trial=trial.index)
            self.setup("operator")
        elif "d" in keys or (every and self.since_drift >= every):
            self.drift_check(trial, "operator" if "d" in keys else "scheduled")

    def drift_check(self, trial: Trial, why: str) -> None:
        """The central target; the offset of the mean gaze per eye against the protocol's
        drift limit (``tracker.max_drift_deg``, by default the central accuracy limit); logged
        as a ``drift_check`` event; a recalibration when the operator (or a dry run) asks."""
        spec = self.spec
        check = DriftCheck(self.area, self.distance_mm, self.rate_hz,
                           self.screen.size, self.ppd_px, spec.drift_limit_deg,
                           spec.tracker.max_data_loss, timing=self.timing,
                           look_at=getattr(self.gaze, "look_at", None), auto=self.auto,
                           eyes=self.eyes)
        self.run_flow(check)
        self.since_drift = 0
        self.file.event("drift_check", why=why, after_trial=trial.index, outcome=check.outcome,
                        checks=[r.to_dict() for r in check.results])
        if check.outcome == "recalibrate":
            self.file.event("recalibration", reason="drift", after_trial=trial.index)
            self.setup("drift")
        elif check.outcome == "quit":
            self.file.event("aborted", during="drift check", after_trial=trial.index)
            raise Aborted()


__all__ = ["Aborted", "TrackerSetup", "calibration_timing", "display_area", "window_ppd"]
