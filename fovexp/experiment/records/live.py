"""The live state a running session publishes for ``fovexp monitor`` (docs/LOGS.md, "The live
status file"; the format and its reader: :mod:`fovexp.results.live`).

The display thread's only part is to hand over what it already makes: each frame's log row
(:meth:`LivePublisher.frames`) and each batch of gaze samples (:meth:`LivePublisher.gaze`), the
same objects it gives the frame and gaze logs (their ``tap``), appended to a queue without a
lock (``deque.extend`` is atomic in CPython) and without copying. The session tells
it, between frames, what it is showing (:meth:`set_state`, :meth:`begin_attempt`,
:meth:`trial_done`, ...). Everything else happens on the publisher's own thread, at a lower
priority, :data:`~fovexp.results.live.LIVE_PERIOD_S` apart: it drains the queues, sums up the
attempt on screen (frames, dropped frames, the blanked share with the trial log's own
definition, the gaze-to-flip latency), keeps the last seconds of gaze as angles from the cross,
and rewrites ``live-<session>.json`` whole. A failed write (a full disk) is counted and retried
at the next period; nothing here can stop a session.
"""

from __future__ import annotations

import collections
import math
import os
import socket
import threading
import time
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from fovexp.results.format import FRAME_COLUMNS
from fovexp.results.live import (
    GAZE_MAX_RATE_HZ,
    GAZE_WINDOW_S,
    LIVE_FORMAT,
    LIVE_PERIOD_S,
    live_path,
    write_live,
)

from ..display.render import _lower_priority
from ..tasks.trial import BlankingLog
from ..trackers.gaze import FixationGeometry, GazeSample

_TRIAL, _ATTEMPT, _FLIP, _DROPPED, _BLANKED, _VALUE, _GAZE_US, _ECC, _FLIP_US = (
    FRAME_COLUMNS.index(c) for c in (
        "trial_index", "attempt", "flip_time_s", "dropped", "blanked", "value",
        "gaze_system_time_us", "gaze_ecc_deg", "flip_system_time_us"))
#: a queue holds at most this many items (a minute of frames at 120 Hz, of samples at
#: 600 Hz, many times what one period brings): a stalled publisher costs bounded memory
_QUEUE_MAX = 1 << 16
#: finished attempts the file lists (the newest)
_MAX_ATTEMPTS = 400
#: the run's gaze-to-flip latencies as a histogram of this bin (ms) up to _LATENCY_MAX_MS
_LATENCY_BIN_MS, _LATENCY_MAX_MS = 0.25, 1000.0


def _num(v: float | None, digits: int = 4) -> float | None:
    """A JSON number: rounded, None for NaN and infinities."""
    if v is None or not math.isfinite(v):
        return None
    return round(float(v), digits)


def _latency(lat_ms: np.ndarray) -> dict[str, Any]:
    if not lat_ms.size:
        return {"n": 0, "median": None, "p95": None, "max": None}
    return {"n": int(lat_ms.size), "median": _num(float(np.median(lat_ms)), 2),
            "p95": _num(float(np.percentile(lat_ms, 95)), 2), "max": _num(float(lat_ms.max()), 2)}


class _Attempt:
    """One attempt's frames as the frame log has them, summed up as the analysis reads them
    (:func:`fovexp.results.frames.trial_quality`, ``blanked_fraction`` of the trial log)."""

    def __init__(self, trial_index: int, attempt: int, meta: Mapping[str, Any]) -> None:
        self.trial_index, self.attempt, self.meta = trial_index, attempt, dict(meta)
        self.frames = 0
        self.dropped = 0
        self.blanking = BlankingLog()
        self.t0: float | None = None
        self.latency_ms: list[float] = []
        self.value: float | None = None
        self.blank = False
        self.ecc: float | None = None
        self.outcome: str | None = None

    def add(self, row: tuple[Any, ...]) -> None:
        t = float(row[_FLIP])
        if self.t0 is None:
            self.t0 = t
        self.frames += 1
        self.dropped += bool(row[_DROPPED])
        self.blank = bool(row[_BLANKED])
        self.blanking.frame(t - self.t0, self.blank, "")
        self.value = row[_VALUE]
        self.ecc = row[_ECC]
        if row[_GAZE_US] is not None and row[_FLIP_US] is not None:
            self.latency_ms.append((row[_FLIP_US] - row[_GAZE_US]) / 1e3)

    def summary(self) -> dict[str, Any]:
        lat = np.asarray(self.latency_ms, dtype=float)
        return {
            **self.meta, "index": self.trial_index, "attempt": self.attempt,
            "value": _num(self.value, 6), "frames": self.frames, "dropped": self.dropped,
            "dropped_fraction": _num(self.dropped / self.frames if self.frames else math.nan, 5),
            "blanked_fraction": _num(self.blanking.fraction, 5),
            "elapsed_s": _num(self.blanking.shown_s, 3),
            "blank": self.blank, "gaze_ecc_deg": _num(self.ecc, 3),
            "latency_ms": _latency(lat), "outcome": self.outcome,
        }


class LivePublisher:
    """Publishes a running session's state (module docstring) into ``live-<session>.json`` of
    ``folder``. ``header`` holds what stays for the run (participant, experiment, protocol,
    session, plan, ...); ``fixation`` converts gaze to angles from the cross."""

    @classmethod
    def for_session(cls, folder: Path, session: str, protocol: Any, participant: str,
                    dry_run: bool, n_trials: int, fixation: FixationGeometry) -> LivePublisher:
        """A session's publisher, its header from the protocol (a ``LoadedProtocol``)."""
        spec = protocol.spec
        return cls(folder, session, {
            "participant": participant, "experiment": protocol.experiment,
            "protocol_path": str(protocol.path), "protocol_title": spec.title,
            "protocol_sha256": protocol.sha256, "dry_run": dry_run,
            "radius_deg": spec.fixation.radius_deg,
            "gaze_timeout_s": spec.fixation.gaze_timeout_s, "break_every": spec.break_every,
            "n_trials": n_trials}, fixation)

    def __init__(self, folder: Path, session: str, header: Mapping[str, Any],
                 fixation: FixationGeometry, period_s: float = LIVE_PERIOD_S) -> None:
        self.path = live_path(folder, session)
        self.fixation = fixation
        self.period_s = period_s
        self.header = {"format": LIVE_FORMAT, "session": session, "pid": os.getpid(),
                       "host": socket.gethostname(), "period_s": period_s, **header}
        # filled by the display thread, drained by the publisher thread (no lock)
        self._frames_in: collections.deque[tuple[Any, ...]] = collections.deque(
            maxlen=_QUEUE_MAX)
        self._gaze_in: collections.deque[Any] = collections.deque(maxlen=_QUEUE_MAX)
        # set by the session thread, read by the publisher thread (under the lock)
        self._lock = threading.Lock()
        self._status: dict[str, Any] = {"state": "starting", "text": None,
                                        "since": time.time()}
        self._meta: dict[tuple[int, int], dict[str, Any]] = {}
        self._current: tuple[int, int] | None = None
        self._eta: tuple[float, float] | None = None  # (eta_s, time.time() when said)
        self._tracker: dict[str, Any] = {"connected": True, "events": [], "quality": None}
        self._counts = {"pauses": 0, "breaks": 0, "disconnections": 0, "trials_done": 0}
        # the publisher thread's own
        self._attempt: _Attempt | None = None
        self._finished: collections.deque[dict[str, Any]] = collections.deque(
            maxlen=_MAX_ATTEMPTS)
        self._latency_hist = np.zeros(int(_LATENCY_MAX_MS / _LATENCY_BIN_MS) + 1, np.int64)
        self._frames_total = 0
        self._dropped_total = 0
        self._gaze: collections.deque[tuple[int, float | None, float | None]] = \
            collections.deque(maxlen=int(GAZE_WINDOW_S * GAZE_MAX_RATE_HZ * 2))
        self._gaze_kept_us: int | None = None
        self._gaze_last_valid = False
        self._gaze_arrived: float | None = None  # time.monotonic() of the newest batch
        self._gaze_count: collections.deque[tuple[float, int]] = collections.deque(maxlen=64)
        self.writes = 0
        #: the publisher thread's CPU time per write (s), the newest 1000 (benchmarks)
        self.publish_cpu_s: collections.deque[float] = collections.deque(maxlen=1000)
        self.write_errors = 0
        self.last_error: str | None = None
        #: when the run ended (s since the epoch; :meth:`stop`), None while it runs
        self._ended: float | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="fovexp-live", daemon=True)

    # -- the display thread: hand over, nothing more ---------------------------------------------
    def frames(self, rows: Iterable[tuple[Any, ...]]) -> None:
        """Frame log rows (:data:`fovexp.results.format.FRAME_COLUMNS`), as shown."""
        self._frames_in.extend(rows)

    def gaze(self, items: Iterable[Any]) -> None:
        """Gaze log items: ``(trial_index, attempt, GazeSample)`` (:mod:`.rows`)."""
        self._gaze_in.extend(items)

    # -- the session thread, between frames -------------------------------------------------------
    def set_state(self, state: str, text: str | None = None) -> None:
        """What the session shows now: ``calibrating``, ``message``, ``trial``, ``between
        trials``, ``break``, ``paused``, ``disconnected`` (:data:`fovexp.results.live
        .RUN_STATES`); ``text`` the screen's first line."""
        with self._lock:
            if state == "paused" and self._status["state"] != "paused":
                self._counts["pauses"] += 1
            if state == "break" and self._status["state"] != "break":
                self._counts["breaks"] += 1
            if state == "disconnected" and self._status["state"] != "disconnected":
                self._counts["disconnections"] += 1
                self._tracker["connected"] = False
            elif self._status["state"] == "disconnected":
                self._tracker["connected"] = True
            first = (text or "").strip().splitlines()
            self._status = {"state": state, "text": first[0][:200] if first else None,
                            "since": time.time()}

    def begin_attempt(self, trial_index: int, attempt: int, **meta: Any) -> None:
        """An attempt at a trial starts (its frames follow); ``meta``: position, total,
        practice, method, image, parameter, blur_rate, start_value."""
        with self._lock:
            self._meta[(trial_index, attempt)] = {k: v for k, v in meta.items()}
            self._current = (trial_index, attempt)
            self._status = {"state": "trial", "text": None, "since": time.time()}

    def end_attempt(self, outcome: str) -> None:
        """The attempt on screen ended: ``done``, ``pause`` or ``disconnected``."""
        with self._lock:
            if self._current is not None:
                self._meta[self._current]["outcome"] = outcome
            if outcome == "done":
                self._counts["trials_done"] += 1
            self._status = {"state": "between trials", "text": None, "since": time.time()}

    def set_eta(self, eta_s: float) -> None:
        """The time the rest of the run takes, as the console line says it."""
        with self._lock:
            self._eta = (eta_s, time.time())

    def event(self, kind: str, detail: Mapping[str, Any] | None = None) -> None:
        """A tracker status event (the frame loop's, or the session's)."""
        with self._lock:
            events = self._tracker["events"]
            events.append({"kind": kind, "time": time.time(),
                           **{k: v for k, v in (detail or {}).items()
                              if isinstance(v, (str, int, float, bool)) or v is None}})
            del events[:-8]
            if kind in ("connection_lost", "tracker_disconnected"):
                self._tracker["connected"] = False
            elif kind in ("connection_restored", "tracker_reconnected"):
                self._tracker["connected"] = True

    def tracker_quality(self, entries: list[Mapping[str, Any]] | None) -> None:
        """The session file's ``tracker_quality``: the last validation's summary is published
        (the accepted one where there is one)."""
        val = [e for e in entries or [] if isinstance(e.get("validation"), Mapping)]
        if not val and entries:
            skipped = [e for e in entries if e.get("skipped")]
            if skipped:
                with self._lock:
                    self._tracker["quality"] = {"skipped": str(skipped[-1]["skipped"])}
            return
        if not val:
            return
        e = ([v for v in val if v.get("accepted")] or val)[-1]
        v = e["validation"]
        with self._lock:
            self._tracker["quality"] = {
                "time": e.get("time"), "reason": e.get("reason"),
                "accepted": bool(e.get("accepted")), "passed": v.get("passed"),
                "accuracy_deg": _num(v.get("accuracy_deg")),
                "central_accuracy_deg": _num(v.get("central_accuracy_deg")),
                "data_loss": _num(v.get("data_loss")),
                "limits": dict(v.get("limits") or {}),
            }

    # -- start, stop ---------------------------------------------------------------------------
    def start(self) -> LivePublisher:
        self._publish()  # the file exists before the first trial
        self._thread.start()
        return self

    def stop(self, state: str) -> None:
        """The run ended with ``state`` (the session file's: :data:`fovexp.results.live
        .ENDINGS`): the last write, which says when (``ended``) and carries no rates (no
        samples per second, no ETA): a reader of the kept file sees a finished run, not a
        frozen live one."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=5)
        self._take_frames()
        self._close_attempt()  # the last attempt joins the list
        now = time.time()
        with self._lock:
            self._status = {"state": state, "text": None, "since": now}
            self._ended = now
        self._publish()

    # -- the publisher thread ------------------------------------------------------------------
    def _run(self) -> None:
        _lower_priority()
        while not self._stop.wait(self.period_s):
            self._publish()

    def _publish(self) -> None:
        c0 = time.thread_time()
        try:
            write_live(self.path, self.snapshot())
            self.writes += 1
        except Exception as exc:  # a full disk, a bug: the session goes on, the file waits
            self.write_errors += 1
            self.last_error = f"{type(exc).__name__}: {exc}"
        self.publish_cpu_s.append(time.thread_time() - c0)

    def _take_frames(self) -> None:
        q = self._frames_in
        for _ in range(len(q)):
            row = q.popleft()
            key = (int(row[_TRIAL]), int(row[_ATTEMPT]))
            a = self._attempt
            if a is None or (a.trial_index, a.attempt) != key:
                self._close_attempt()
                with self._lock:
                    meta = self._meta.get(key, {})
                a = self._attempt = _Attempt(*key, meta)
            a.add(row)
            self._frames_total += 1
            self._dropped_total += bool(row[_DROPPED])
            if a.latency_ms and row[_GAZE_US] is not None and row[_FLIP_US] is not None:
                b = int(min(a.latency_ms[-1], _LATENCY_MAX_MS) / _LATENCY_BIN_MS)
                self._latency_hist[max(b, 0)] += 1

    def _close_attempt(self) -> None:
        a = self._attempt
        if a is not None:
            with self._lock:
                a.outcome = self._meta.get((a.trial_index, a.attempt), {}).get("outcome")
            self._finished.append(a.summary())
        self._attempt = None

    def _take_gaze(self) -> None:
        q = self._gaze_in
        n = len(q)
        if n:
            now = time.monotonic()
            self._gaze_arrived = now
            self._gaze_count.append((now, n))
        min_dt_us = int(1e6 / GAZE_MAX_RATE_HZ)
        kept: list[tuple[int, tuple[float, float] | None]] = []
        last_valid = self._gaze_last_valid
        for _ in range(n):
            s: GazeSample = q.popleft()[2]
            t = int(s.system_time_us)
            valid = s.valid
            # at most GAZE_MAX_RATE_HZ, but every change between a valid sample and none
            if (self._gaze_kept_us is not None and t - self._gaze_kept_us < min_dt_us
                    and valid == last_valid):
                continue
            self._gaze_kept_us, last_valid = t, valid
            kept.append((t, s.point))
        self._gaze_last_valid = last_valid
        for (t, _), (x, y) in zip(kept, self._offsets_deg([p for _, p in kept]), strict=True):
            # rounded once, here (the file shows each sample for 3 s, 12 writes)
            self._gaze.append((t, None if x is None else round(x, 3),
                               None if y is None else round(y, 3)))

    def _offsets_deg(self, points: list[tuple[float, float] | None],
                     ) -> list[tuple[float | None, float | None]]:
        """Gaze points as (x, y) degrees from the cross (x right, y down): the exact angle
        (the blanking rule's, as :meth:`FixationGeometry.eccentricity` measures it, for all at
        once) along the on-screen direction; None off the screen or without a point."""
        on = [i for i, p in enumerate(points)
              if p is not None and 0.0 <= p[0] <= 1.0 and 0.0 <= p[1] <= 1.0]
        out: list[tuple[float | None, float | None]] = [(None, None)] * len(points)
        if not on:
            return out
        fix = self.fixation
        px = np.array([fix.to_px(*points[i]) for i in on])  # type: ignore[misc]
        ecc = fix.geometry.eccentricity_deg(px[:, 0], px[:, 1], fix.cross_px)
        d = px - np.asarray(fix.cross_px)
        r = np.hypot(d[:, 0], d[:, 1])
        unit = d / np.where(r > 0, r, 1.0)[:, None]
        for k, i in enumerate(on):
            out[i] = (float(ecc[k] * unit[k, 0]), float(ecc[k] * unit[k, 1]))
        return out

    def _gaze_view(self, ended: bool = False) -> dict[str, Any]:
        """The last seconds of gaze; after the end (``ended``) without the arrival figures,
        which describe a running stream."""
        g = list(self._gaze)
        t_us = np.array([s[0] for s in g], dtype=np.int64)
        first = int(np.searchsorted(t_us, t_us[-1] - GAZE_WINDOW_S * 1e6)) if g else 0
        keep = g[first:]
        now = time.monotonic()
        recent = sum(n for t, n in self._gaze_count if now - t <= 1.0)
        return {
            "window_s": GAZE_WINDOW_S,
            "t": np.round((t_us[first:] - t_us[-1]) / 1e6, 3).tolist() if g else [],
            "x_deg": [s[1] for s in keep], "y_deg": [s[2] for s in keep],
            "newest_age_s": (_num(now - self._gaze_arrived, 3)
                             if self._gaze_arrived is not None and not ended else None),
            "samples_last_s": None if ended else recent,
        }

    def snapshot(self) -> dict[str, Any]:
        """The status file's content now (the publisher thread; also callable in tests)."""
        self._take_frames()
        self._take_gaze()
        with self._lock:
            status = dict(self._status)
            current = self._current
            counts = dict(self._counts)
            tracker = {**self._tracker, "events": list(self._tracker["events"])}
            eta = self._eta
            ended = self._ended
            meta_now = dict(self._meta.get(current, {})) if current is not None else None
        a = self._attempt
        trial = None
        if status["state"] == "trial" and current is not None:
            if a is not None and (a.trial_index, a.attempt) == current:
                trial = a.summary()
            else:  # started, no frame yet (the first render)
                trial = {**(meta_now or {}), "index": current[0], "attempt": current[1],
                         "frames": 0}
        elif a is not None:  # the last attempt, until the next one shows a frame
            with self._lock:
                a.outcome = self._meta.get((a.trial_index, a.attempt), {}).get("outcome")
            trial = a.summary()
        hist = self._latency_hist
        n_lat = int(hist.sum())
        total_lat: dict[str, Any] = {"n": n_lat}
        if n_lat:
            cdf = np.cumsum(hist) / n_lat
            total_lat.update({f"p{q}": _num(float(np.searchsorted(cdf, q / 100) + 0.5)
                                            * _LATENCY_BIN_MS, 2) for q in (50, 95)})
        now = time.time()
        return {
            **self.header, "updated": round(now, 3), "seq": self.writes + 1,
            "state": status["state"], "text": status["text"], "since": round(status["since"], 3),
            "ended": None if ended is None else round(ended, 3),
            "trial": trial,
            "attempts": list(self._finished),
            "gaze": self._gaze_view(ended is not None),
            "totals": {"frames": self._frames_total, "dropped": self._dropped_total,
                       "latency_ms": total_lat, **counts},
            "tracker": tracker,
            "eta_s": (None if eta is None or ended is not None
                      else _num(max(0.0, eta[0] - (now - eta[1])), 1)),
            "write_errors": self.write_errors,
        }


__all__ = ["LivePublisher"]
