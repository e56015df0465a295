"""Tobii Pro eye trackers through tobii-research (paper section 5.1: Tobii Pro Spectrum, 600 Hz).

The gaze callback runs on the SDK's thread and only appends the SDK's sample dictionary to a
:class:`~fovexp.experiment.trackers.gaze.SampleBuffer`; conversion, the blanking decision and disk
writes happen in the frame loop and the log writer. Samples keep the tracker's own device and system
timestamps (microseconds). Connection loss/restoration and gaze output frequency changes arrive
as notifications; a stall of the sample stream and a measured rate off the nominal one are
noticed too.

tobii-research ships Linux wheels for Python 3.10 only; without it, or without a tracker,
``--tracker tobii`` stops with a clear message before any window opens.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from fovexp import FovexpError

from ..protocol.defaults import TRACKER_RATE_HZ
from .calibration import CalibrationOutcome, PointSamples
from .gaze import (
    GAZE_BUFFER_S,
    DisplayArea,
    GazeSample,
    SampleBuffer,
    SourceEvent,
    Vec3,
    monotonic_us,
)


def import_tobii() -> Any:
    """The ``tobii_research`` module, or a FovexpError saying how to get it."""
    try:
        import tobii_research
    except ImportError as exc:
        raise FovexpError(
            "--tracker tobii needs the tobii-research package (pip install "
            "'fovexp[tracker]'; Linux wheels exist for Python 3.10 only): " + str(exc)
        ) from None
    return tobii_research


def _num(v: Any) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        return math.nan
    return f


def _origin(d: dict[str, Any], eye: str) -> Vec3 | None:
    """The eye's gaze origin (user coordinate system, mm), or None when not valid."""
    o = d.get(f"{eye}_gaze_origin_in_user_coordinate_system")
    if not d.get(f"{eye}_gaze_origin_validity") or o is None:
        return None
    x, y, z = (_num(v) for v in tuple(o)[:3])
    return (x, y, z) if all(math.isfinite(v) for v in (x, y, z)) else None


def sample_from_sdk(d: dict[str, Any]) -> GazeSample:
    """A gaze sample from the SDK's dictionary (``subscribe_to(..., as_dictionary=True)``).

    ``*_gaze_point_on_display_area`` is already normalised with origin top-left, the runner's
    convention; validity is per eye (``*_gaze_point_validity``: 1 valid, 0 invalid). The gaze
    origins (``*_gaze_origin_in_user_coordinate_system``, mm) are kept where valid: the
    validation measures its angles from them.
    """
    lx, ly = (d.get("left_gaze_point_on_display_area") or (math.nan, math.nan))[:2]
    rx, ry = (d.get("right_gaze_point_on_display_area") or (math.nan, math.nan))[:2]
    lv = bool(d.get("left_gaze_point_validity")) and math.isfinite(_num(lx))
    rv = bool(d.get("right_gaze_point_validity")) and math.isfinite(_num(rx))
    return GazeSample(int(d["device_time_stamp"]), int(d["system_time_stamp"]),
                      _num(lx), _num(ly), lv, _num(rx), _num(ry), rv,
                      _origin(d, "left"), _origin(d, "right"))


class TobiiGaze:
    """A Tobii Pro tracker as a gaze source.

    ``tracker`` may be given (an object with the ``tobii_research.EyeTracker`` interface; tests
    pass a stand-in for the absent hardware); otherwise the first tracker found (or the one whose
    address or serial number is ``address``) is used. Besides the gaze it streams the user
    position guide (for the calibration's head-position box), reports its display area
    (:meth:`display_area`) and calibrates through the SDK (:meth:`calibration`).
    """

    name = "tobii"

    def __init__(self, frequency_hz: float = TRACKER_RATE_HZ, address: str | None = None,
                 tracker: Any = None, stall_s: float = 0.5, rate_tolerance: float = 0.1,
                 calibration_factory: Any = None) -> None:
        self.tr = import_tobii()
        if tracker is None:
            try:
                found = list(self.tr.find_all_eyetrackers())
            except Exception as exc:  # the SDK raises its own types; any failure means no tracker
                raise FovexpError(f"searching for Tobii eye trackers failed: {exc}") from None
            if address:
                found = [t for t in found if address in (t.address, t.serial_number)]
            if not found:
                where = f" matching {address!r}" if address else ""
                raise FovexpError(
                    f"no Tobii eye tracker found{where}: check that it is connected and powered, "
                    "and that Tobii Pro Eye Tracker Manager sees it (or run with --tracker "
                    "simulated / mouse for a pilot)"
                )
            tracker = found[0]
        self.tracker = tracker
        self.frequency_hz = float(frequency_hz)
        self.buffer = SampleBuffer(maxlen=int(self.frequency_hz * GAZE_BUFFER_S))
        self._notes = SampleBuffer(maxlen=1000)
        self._connected = True
        self._subscribed = False
        self._last_sample_us: int | None = None
        self._stalled = False
        self._stall_us = int(stall_s * 1e6)
        self._rate_tol = rate_tolerance
        self._recent_dev: list[int] = []
        self._rate_flagged = False
        self._position: Any = None
        #: makes the SDK's calibration object (default ``ScreenBasedCalibration``: see
        #: :class:`TobiiCalibration`)
        self.calibration_factory = calibration_factory

    # -- SDK callbacks: append only ------------------------------------------------------------
    def _on_gaze(self, data: dict[str, Any]) -> None:
        # with when it reached the runner, on the SDK's system clock (the delivery latency)
        self.buffer.append((data, int(self.tr.get_system_time_stamp())))

    def _on_lost(self, data: Any) -> None:
        self._notes.append(("connection_lost", data))

    def _on_restored(self, data: Any) -> None:
        self._notes.append(("connection_restored", data))

    def _on_frequency(self, data: Any) -> None:
        self._notes.append(("frequency_changed", data))

    def _on_position(self, data: Any) -> None:
        self._position = data  # only the latest matters (one assignment: atomic)

    # -- lifecycle -----------------------------------------------------------------------------
    def start(self) -> None:
        tr = self.tr
        try:
            freqs = [float(f) for f in self.tracker.get_all_gaze_output_frequencies()]
            if not any(abs(f - self.frequency_hz) < 0.5 for f in freqs):
                raise FovexpError(
                    f"the Tobii tracker {self.tracker.model} offers {freqs} Hz, not the "
                    f"protocol's {self.frequency_hz:g} Hz"
                )
            self.tracker.set_gaze_output_frequency(self.frequency_hz)
            self.tracker.subscribe_to(tr.EYETRACKER_GAZE_DATA, self._on_gaze, as_dictionary=True)
            self.tracker.subscribe_to(tr.EYETRACKER_NOTIFICATION_CONNECTION_LOST, self._on_lost,
                                      as_dictionary=True)
            self.tracker.subscribe_to(tr.EYETRACKER_NOTIFICATION_CONNECTION_RESTORED,
                                      self._on_restored, as_dictionary=True)
            self.tracker.subscribe_to(tr.EYETRACKER_NOTIFICATION_GAZE_OUTPUT_FREQUENCY_CHANGED,
                                      self._on_frequency, as_dictionary=True)
        except FovexpError:
            raise
        except Exception as exc:
            raise FovexpError(f"starting the Tobii gaze stream failed: {exc}") from None
        try:  # where the eyes are in the track box: the calibration's head-position screen
            self.tracker.subscribe_to(tr.EYETRACKER_USER_POSITION_GUIDE, self._on_position,
                                      as_dictionary=True)
        except Exception:  # a model without the guide: the screen uses the gaze origins
            pass
        self._subscribed = True
        self._last_sample_us = self.now_us()

    def stop(self) -> None:
        if not self._subscribed:
            return
        for kind, cb in ((self.tr.EYETRACKER_GAZE_DATA, self._on_gaze),
                         (self.tr.EYETRACKER_NOTIFICATION_CONNECTION_LOST, self._on_lost),
                         (self.tr.EYETRACKER_NOTIFICATION_CONNECTION_RESTORED, self._on_restored),
                         (self.tr.EYETRACKER_NOTIFICATION_GAZE_OUTPUT_FREQUENCY_CHANGED,
                          self._on_frequency),
                         (self.tr.EYETRACKER_USER_POSITION_GUIDE, self._on_position)):
            try:
                self.tracker.unsubscribe_from(kind, cb)
            except Exception:  # shutting down: a failed unsubscribe must not hide the real error
                pass
        self._subscribed = False

    def now_us(self) -> int:
        """The SDK's system clock, the one its ``system_time_stamp`` uses."""
        try:
            return int(self.tr.get_system_time_stamp())
        except Exception:
            return monotonic_us()

    @property
    def connected(self) -> bool:
        return self._connected and not self._stalled

    def info(self) -> dict[str, Any]:
        t = self.tracker
        out: dict[str, Any] = {"name": "tobii", "frequency_hz": self.frequency_hz}
        for k in ("model", "serial_number", "address", "device_name", "firmware_version",
                  "runtime_version"):
            try:
                out[k] = str(getattr(t, k))
            except Exception:
                out[k] = None
        try:
            out["sdk_version"] = str(self.tr.__version__)
        except AttributeError:
            pass
        return out

    # -- frame loop side -----------------------------------------------------------------------
    def poll(self) -> list[GazeSample]:
        raw = self.buffer.drain()
        out = []
        for d, received_us in raw:
            try:
                out.append(sample_from_sdk(d)._replace(received_system_time_us=received_us))
            except (KeyError, TypeError, ValueError):
                continue  # a malformed sample counts as lost
        if out:
            self._last_sample_us = out[-1].system_time_us
            self._recent_dev.extend(s.device_time_us for s in out)
            self._recent_dev = self._recent_dev[-int(self.frequency_hz):]
        return out

    def poll_events(self) -> list[SourceEvent]:
        events = []
        for kind, data in self._notes.drain():
            detail = dict(data) if isinstance(data, dict) else {"data": repr(data)}
            ts = int(detail.get("system_time_stamp", self.now_us()))
            if kind in ("connection_lost", "connection_restored"):
                self._connected = kind == "connection_restored"
                self._recent_dev.clear()  # the rate is measured again from after the gap
            events.append(SourceEvent(kind, ts, detail))
        now = self.now_us()
        stalled = (self._last_sample_us is not None and self._subscribed
                   and now - self._last_sample_us > self._stall_us)
        if stalled != self._stalled:
            self._stalled = stalled
            self._recent_dev.clear()
            events.append(SourceEvent("stream_stalled" if stalled else "stream_resumed", now, {}))
        rate = self.measured_rate_hz()
        if rate is not None:
            off = abs(rate - self.frequency_hz) > self._rate_tol * self.frequency_hz
            if off != self._rate_flagged:
                self._rate_flagged = off
                events.append(SourceEvent("rate_deviation" if off else "rate_ok", now,
                                          {"measured_hz": rate, "nominal_hz": self.frequency_hz}))
        return events

    def measured_rate_hz(self) -> float | None:
        """Sampling rate from the last second of device timestamps (None: too few samples)."""
        ts = self._recent_dev
        if len(ts) < max(10, int(0.25 * self.frequency_hz)):
            return None
        span = (ts[-1] - ts[0]) / 1e6
        return (len(ts) - 1) / span if span > 0 else None

    # -- geometry and calibration -------------------------------------------------------------
    def display_area(self) -> DisplayArea:
        """The display area the tracker's normalised gaze refers to (``get_display_area``, set
        up in Tobii Pro Eye Tracker Manager), in its user coordinate system (mm)."""
        try:
            return DisplayArea.from_sdk(self.tracker.get_display_area())
        except Exception as exc:  # the SDK's own error types
            raise FovexpError(
                f"reading the Tobii tracker's display area failed ({type(exc).__name__}: {exc}): "
                "set it up in Tobii Pro Eye Tracker Manager (Display setup)") from None

    def user_position(self) -> tuple[Vec3 | None, Vec3 | None]:
        """Each eye's position in the track box from the user position guide (normalised, 0.5
        the middle; z 0 nearest the tracker), or None where the eye is not found."""
        d = self._position
        if not isinstance(d, dict):
            return None, None
        out: list[Vec3 | None] = []
        for eye in ("left", "right"):
            pos = d.get(f"{eye}_user_position")
            if not d.get(f"{eye}_user_position_validity") or pos is None:
                out.append(None)
                continue
            x, y, z = (_num(v) for v in tuple(pos)[:3])
            out.append((x, y, z) if all(math.isfinite(v) for v in (x, y, z)) else None)
        return out[0], out[1]

    def calibration(self) -> TobiiCalibration:
        """The SDK's screen-based calibration as a :class:`fovexp.experiment.trackers.calibration`
        backend."""
        return TobiiCalibration(self, self.calibration_factory)


class TobiiCalibration:
    """``tobii_research.ScreenBasedCalibration`` behind the calibration flow's backend interface
    (:class:`fovexp.experiment.trackers.calibration.CalibrationBackend`). Its calls block
    (collecting a point takes the SDK about a second), so the flow runs them on a worker thread.

    ``factory`` makes the calibration object from the tracker (default the SDK's class, which
    accepts only a connected ``tobii_research.EyeTracker``; tests without a tracker pass a
    stand-in for it).
    """

    def __init__(self, gaze: TobiiGaze, factory: Any = None) -> None:
        self.gaze = gaze
        self.tr = gaze.tr
        self.factory = factory or gaze.tr.ScreenBasedCalibration
        self.cal: Any = None

    def begin(self) -> None:
        self.cal = self.factory(self.gaze.tracker)
        self.cal.enter_calibration_mode()

    def collect(self, x: float, y: float) -> bool:
        ok = self.cal.collect_data(x, y) == self.tr.CALIBRATION_STATUS_SUCCESS
        if not ok:  # the SDK's advice: try a point once more before giving up on it
            ok = self.cal.collect_data(x, y) == self.tr.CALIBRATION_STATUS_SUCCESS
        return ok

    def discard(self, x: float, y: float) -> None:
        self.cal.discard_data(x, y)

    def compute(self) -> CalibrationOutcome:
        tr = self.tr
        result = self.cal.compute_and_apply()
        points: dict[tuple[float, float], PointSamples] = {}
        for cp in result.calibration_points:
            x, y = (float(v) for v in cp.position_on_display_area)
            ps = PointSamples()
            for smp in cp.calibration_samples:
                for eye, out in ((smp.left_eye, ps.left), (smp.right_eye, ps.right)):
                    px, py = (float(v) for v in eye.position_on_display_area)
                    out.append((px, py, eye.validity == tr.VALIDITY_VALID_AND_USED))
            points[(x, y)] = ps
        failed = result.status == tr.CALIBRATION_STATUS_FAILURE
        return CalibrationOutcome(
            failed=failed, status=str(result.status), points=points,
            reason="the tracker could not compute a calibration from these points"
            if failed else "")

    def end(self) -> None:
        if self.cal is not None:
            try:
                self.cal.leave_calibration_mode()
            except Exception:  # leaving after an error must not hide the error
                pass
            self.cal = None

    def user_position(self) -> tuple[Vec3 | None, Vec3 | None]:
        return self.gaze.user_position()


def rate_of(samples: Sequence[GazeSample]) -> float:
    """Mean sampling rate (Hz) from device timestamps."""
    if len(samples) < 2:
        return math.nan
    t = np.array([s.device_time_us for s in samples], dtype=np.float64)
    return float((len(t) - 1) / ((t[-1] - t[0]) / 1e6))
