"""What ``fovexp monitor`` shows, read from a results folder on disk: the sessions under it
(running, stopped, finished) and, for one of them, the trial on screen judged against the
analysis' exclusion rules R11-R13 (:class:`fovexp.results.limits.TrialLimits`, the same
predicates ``fovexp analyze`` applies).

It reads only files the runner writes (docs/LOGS.md): ``live-<session>.json`` (the live status
file, :mod:`fovexp.results.live`), ``session-<session>.json`` and ``trials.csv``, each of them
written whole or row by row, and it never fails on what it reads: a file or a row it cannot
read is left out and named in the view's ``skipped`` list. Nothing here imports the runner,
PsychoPy or the web server.
"""

from __future__ import annotations

import json
import math
import os
import re
import socket
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fovexp import FovexpError
from fovexp.results.format import SIMULATED_TRACKER, is_participant_id, read_trials_file
from fovexp.results.limits import R11, R12, R13, TrialLimits
from fovexp.results.live import ENDINGS, FINAL_STATES, STALE_AFTER_S, LiveRead, read_live

#: a session file larger than this is not read (one is tens of kB)
MAX_SESSION_BYTES = 8 << 20
#: a trials.csv larger than this is not read by the monitor (a session's is a few kB)
MAX_TRIALS_BYTES = 16 << 20
#: how long a scan of the results folder is reused (s)
SCAN_TTL_S = 1.0
_NAME_RE = re.compile(r"\A[A-Za-z0-9][A-Za-z0-9_.-]{0,63}\Z")
_SESSION_RE = re.compile(r"\A[A-Za-z0-9_-]{1,40}\Z")
_FILE_RE = re.compile(r"\A(session|live)-([A-Za-z0-9_-]{1,40})\.json\Z")


@dataclass(frozen=True)
class SessionRef:
    """One session's place under the results folder."""

    experiment: str
    participant: str
    session: str
    folder: Path

    @property
    def key(self) -> str:
        return f"{self.experiment}/{self.participant}/{self.session}"


def parse_key(key: str) -> tuple[str, str, str] | None:
    """``experiment/participant/session`` split and checked (names only: no ``..``, no
    separators, no absolute paths); None when it is not one."""
    parts = key.split("/")
    if len(parts) != 3:
        return None
    exp, part, sess = parts
    if not (_NAME_RE.match(exp) and ".." not in exp and is_participant_id(part)
            and _SESSION_RE.match(sess)):
        return None
    return exp, part, sess


def _num(v: Any) -> float | None:
    """A finite number from JSON, else None."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return None
    return float(v) if math.isfinite(v) else None


def _int(v: Any) -> int | None:
    return v if isinstance(v, int) and not isinstance(v, bool) else None


def _str(v: Any, n: int = 200) -> str | None:
    return v[:n] if isinstance(v, str) else None


def _read_json(path: Path, max_bytes: int) -> tuple[dict[str, Any] | None, str | None]:
    try:
        size = path.stat().st_size
        if size > max_bytes:
            return None, f"{size} bytes: too large to read"
        data = json.loads(path.read_bytes().decode("utf-8"))
    except FileNotFoundError:
        return None, "missing"
    except OSError as exc:
        return None, f"cannot read: {exc.strerror}"
    except (UnicodeDecodeError, ValueError) as exc:
        return None, f"not JSON ({str(exc)[:80]})"
    if not isinstance(data, dict):
        return None, "not a JSON object"
    return data, None


def _ended_time(info: Mapping[str, Any]) -> float | None:
    """The session file's ``ended`` (an ISO time stamp) in s since the epoch, or None."""
    ended = _str(info.get("ended"))
    if not ended:
        return None
    from datetime import datetime

    try:
        return datetime.fromisoformat(ended).timestamp()
    except ValueError:
        return None


def _end(live: Mapping[str, Any], info: Mapping[str, Any]) -> dict[str, Any]:
    """How and when a finished session ended: the status file's last write (its final
    ``state``, and ``ended``, or ``since`` in a file written before ``ended`` was), else the
    session file's (``state``, ``ended``). ``how`` in words (:data:`fovexp.results.live
    .ENDINGS`), ``time`` in s since the epoch, ``at`` that time on this machine's clock face
    (None where neither file says)."""
    state = _str(live.get("state"))
    when: float | None = None
    if state in FINAL_STATES:
        when = _num(live.get("ended")) or _num(live.get("since"))
    else:
        state = "completed" if info.get("completed") is True else _str(info.get("state"))
    if when is None:
        when = _ended_time(info)
    at = (time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(when)) if when is not None
          else None)
    return {"state": state, "how": ENDINGS.get(state or "", state), "time": when, "at": at}


class ResultsView:
    """The sessions under ``root`` as ``fovexp monitor`` shows them.

    ``limits``: the thresholds of R11-R13 (``fovexp analyze``'s defaults unless given);
    ``report``: the folder of ``fovexp analyze``'s report, linked from finished sessions;
    ``stale_after_s``: a running session whose status file has not changed for this long (of
    the monitor's own clock) is shown as not responding; ``clock``: ``time.time``.
    """

    def __init__(self, root: str | Path, limits: TrialLimits | None = None,
                 report: str | Path | None = None, stale_after_s: float = STALE_AFTER_S,
                 clock: Callable[[], float] = time.time) -> None:
        self.root = Path(root).resolve()
        if not self.root.is_dir():
            raise FovexpError(f"{root}: no such results folder")
        self.limits = limits or TrialLimits()
        self.report = Path(report).resolve() if report is not None else None
        self.stale_after_s = stale_after_s
        self.clock = clock
        self._host = socket.gethostname()
        self._scan: tuple[float, dict[str, SessionRef]] | None = None
        # key -> (seq, monotonic time it last changed): a runner's silence, on our clock
        self._seen: dict[str, tuple[Any, float]] = {}
        self._cache: dict[Path, tuple[tuple[int, int, int], Any]] = {}

    # -- finding sessions ----------------------------------------------------------------------
    def refs(self) -> dict[str, SessionRef]:
        """Every session with a session or status file in ``<experiment>/<participant>/``."""
        now = time.monotonic()
        if self._scan is not None and now - self._scan[0] < SCAN_TTL_S:
            return self._scan[1]
        out: dict[str, SessionRef] = {}
        for pattern in ("*/*/session-*.json", "*/*/live-*.json"):
            for path in self.root.glob(pattern):
                m = _FILE_RE.match(path.name)
                if m is None:
                    continue
                exp, part = path.parent.parent.name, path.parent.name
                if parse_key(f"{exp}/{part}/{m.group(2)}") is None:
                    continue
                ref = SessionRef(exp, part, m.group(2), path.parent)
                out.setdefault(ref.key, ref)
        self._scan = (now, out)
        return out

    def resolve(self, key: str) -> SessionRef | None:
        """The session named by ``key`` when it is one of :meth:`refs` and its folder lies
        inside the results folder (a symbolic link out of it is refused); else None."""
        if parse_key(key) is None:
            return None
        ref = self.refs().get(key)
        if ref is None:
            return None
        try:
            ref.folder.resolve().relative_to(self.root)
        except (OSError, ValueError):
            return None
        return ref

    # -- reading files (cached on their size and modification time) ------------------------------
    def _cached(self, path: Path, read: Callable[[Path], Any]) -> Any:
        try:
            st = path.stat()
            stamp = (st.st_mtime_ns, st.st_size, st.st_ino)  # a rename gives a new inode
        except OSError:
            stamp = (-1, -1, -1)
        hit = self._cache.get(path)
        if hit is not None and hit[0] == stamp:
            return hit[1]
        value = read(path)
        self._cache[path] = (stamp, value)
        return value

    def _session_file(self, ref: SessionRef) -> tuple[dict[str, Any] | None, str | None]:
        return self._cached(ref.folder / f"session-{ref.session}.json",
                            lambda p: _read_json(p, MAX_SESSION_BYTES))

    def _live(self, ref: SessionRef) -> LiveRead:
        read: LiveRead = self._cached(ref.folder / f"live-{ref.session}.json", read_live)
        return read

    def _trials(self, ref: SessionRef) -> tuple[list[dict[str, Any]], list[str]]:
        """This session's rows of ``trials.csv``, and what was skipped (line and why)."""
        def read(path: Path) -> tuple[list[dict[str, Any]], list[str]]:
            try:
                if path.stat().st_size > MAX_TRIALS_BYTES:
                    return [], [f"{path.name}: too large to read here"]
                tf = read_trials_file(path, strict=False)
            except FileNotFoundError:
                return [], []
            except (OSError, FovexpError) as exc:
                return [], [f"{path.name}: {exc}"]
            skipped = [f"{path.name} line {line}: {why}" for line, why in tf.skipped]
            if tf.missing:
                skipped.append(f"{path.name}: header lacks {', '.join(tf.missing)}")
            return tf.rows, skipped
        rows, skipped = self._cached(ref.folder / "trials.csv", read)
        return [r for r in rows if r.get("session") == ref.session], skipped

    # -- judging -------------------------------------------------------------------------------
    def judge(self, blanked_fraction: float | None, dropped_fraction: float | None,
              latency_p95_ms: float | None) -> dict[str, dict[str, Any]]:
        """R11-R13 for one trial's figures: each rule's value, limit and whether the trial
        would be excluded (:meth:`TrialLimits.exceeded`; a missing figure breaks none)."""
        nan = math.nan
        hit = self.limits.exceeded(
            blanked_fraction=nan if blanked_fraction is None else blanked_fraction,
            dropped_fraction=nan if dropped_fraction is None else dropped_fraction,
            latency_p95_ms=nan if latency_p95_ms is None else latency_p95_ms)
        lim = self.limits
        return {
            R11: {"value": blanked_fraction, "limit": lim.max_blanked_fraction,
                  "unit": "fraction", "exceeded": hit[R11]},
            R12: {"value": dropped_fraction, "limit": lim.max_dropped_fraction,
                  "unit": "fraction", "exceeded": hit[R12]},
            R13: {"value": latency_p95_ms, "limit": lim.max_latency_p95_ms,
                  "unit": "ms", "exceeded": hit[R13]},
        }

    def _attempt(self, a: Any, skipped: list[str], where: str) -> dict[str, Any] | None:
        """One attempt of the status file, its fields checked and judged."""
        if not isinstance(a, Mapping):
            skipped.append(f"{where}: not an object")
            return None
        lat: Mapping[str, Any] = a["latency_ms"] if isinstance(a.get("latency_ms"), Mapping) \
            else {}
        out: dict[str, Any] = {
            "index": _int(a.get("index")), "attempt": _int(a.get("attempt")),
            "position": _int(a.get("position")), "total": _int(a.get("total")),
            "practice": bool(a.get("practice")), "method": _str(a.get("method")),
            "image": _str(a.get("image")), "parameter": _str(a.get("parameter")),
            "value": _num(a.get("value")), "start_value": _num(a.get("start_value")),
            "frames": _int(a.get("frames")), "dropped": _int(a.get("dropped")),
            "dropped_fraction": _num(a.get("dropped_fraction")),
            "blanked_fraction": _num(a.get("blanked_fraction")),
            "elapsed_s": _num(a.get("elapsed_s")), "blank": bool(a.get("blank")),
            "gaze_ecc_deg": _num(a.get("gaze_ecc_deg")), "outcome": _str(a.get("outcome")),
            "latency_ms": {k: _num(lat.get(k)) for k in ("median", "p95", "max")},
        }
        if out["index"] is None:
            skipped.append(f"{where}: no trial index")
            return None
        out["rules"] = self.judge(out["blanked_fraction"], out["dropped_fraction"],
                                  out["latency_ms"]["p95"])
        out["flagged"] = [r for r, v in out["rules"].items() if v["exceeded"]]
        return out

    def _gaze(self, g: Any, skipped: list[str]) -> dict[str, Any] | None:
        if g is None:
            return None
        if not isinstance(g, Mapping):
            skipped.append("live status: gaze is not an object")
            return None
        t, x, y = g.get("t"), g.get("x_deg"), g.get("y_deg")
        if not (isinstance(t, list) and isinstance(x, list) and isinstance(y, list)
                and len(t) == len(x) == len(y)):
            skipped.append("live status: gaze arrays missing or of different lengths")
            return None
        points = [(_num(a), _num(b), _num(c)) for a, b, c in zip(t, x, y, strict=True)]
        bad = sum(p[0] is None for p in points)
        if bad:
            skipped.append(f"live status: {bad} gaze sample(s) without a time")
        points = [p for p in points if p[0] is not None]
        return {"t": [p[0] for p in points], "x_deg": [p[1] for p in points],
                "y_deg": [p[2] for p in points], "window_s": _num(g.get("window_s")),
                "newest_age_s": _num(g.get("newest_age_s")),
                "samples_last_s": _int(g.get("samples_last_s"))}

    # -- one session ---------------------------------------------------------------------------
    def _runner_alive(self, live: Mapping[str, Any]) -> bool | None:
        """Whether the runner's process exists, when it runs on this machine (else None)."""
        pid = _int(live.get("pid"))
        if live.get("host") != self._host or pid is None or pid <= 0:
            return None
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        except OSError:  # another user's process: it exists
            return True
        return True

    def _status(self, ref: SessionRef, live: Mapping[str, Any] | None,
                info: Mapping[str, Any] | None,
                problem: str | None = None) -> tuple[str, str | None]:
        """``running``, ``stopped`` (a run that stopped without saying so: killed, crashed) or
        ``finished``; and why it is not running, when it says."""
        file_state = _str(info.get("state")) if info else None
        if info and info.get("completed") is True:
            file_state = "completed"
        if live is None:
            if file_state in FINAL_STATES:
                return "finished", None
            if problem not in (None, "no status file"):
                return "stopped", f"its live status file cannot be read ({problem})"
            return "stopped", ("no live status file: started by a fovexp without one, or it "
                               "stopped before its first write")
        state = _str(live.get("state"))
        if state in FINAL_STATES:
            return "finished", None
        seq = live.get("seq")
        now_mono = time.monotonic()
        seen = self._seen.get(ref.key)
        if seen is None or seen[0] != seq:
            # first sight: trust the writer's clock; afterwards our own
            updated = _num(live.get("updated"))
            age = (self.clock() - updated) if updated is not None else math.inf
            self._seen[ref.key] = (seq, now_mono - max(0.0, age) if seen is None else now_mono)
        silent_s = now_mono - self._seen[ref.key][1]
        if self._runner_alive(live) is False:
            return "stopped", "the runner's process is gone (killed or crashed)"
        if file_state in FINAL_STATES:
            return "finished", None
        if silent_s > self.stale_after_s:
            return "stopped", f"no update for {silent_s:.0f} s (runner killed, crashed or hung?)"
        return "running", None

    def session(self, key: str) -> dict[str, Any] | None:
        """One session's view (None when ``key`` names none)."""
        ref = self.resolve(key)
        if ref is None:
            return None
        skipped: list[str] = []
        info, problem = self._session_file(ref)
        if problem is not None and problem != "missing":
            skipped.append(f"session-{ref.session}.json: {problem}")
        lr = self._live(ref)
        live = lr.data
        if lr.problem is not None and lr.problem != "no status file":
            skipped.append(f"live-{ref.session}.json: {lr.problem}")
        status, why = self._status(ref, live, info, lr.problem)
        live = live or {}
        dry = bool(live.get("dry_run")) if "dry_run" in live else bool(
            info and any(r.get("dry_run") for r in info.get("runs", []) if isinstance(r, Mapping)))
        trial = self._attempt(live["trial"], skipped, "live status: trial") \
            if live.get("trial") is not None else None
        raw_attempts = live.get("attempts") or []
        if not isinstance(raw_attempts, list):
            skipped.append("live status: attempts is not a list")
            raw_attempts = []
        checked = (self._attempt(a, skipped, f"live status: attempt {i}")
                   for i, a in enumerate(raw_attempts))
        attempts = [a for a in checked if a is not None]
        rows, row_skips = self._trials(ref)
        skipped += row_skips
        last_attempt = {a["index"]: a for a in attempts if a["outcome"] == "done"}
        trials = []
        for r in rows:
            a = last_attempt.get(r["trial_index"])
            frames = a["frames"] if a else None
            dropped = r.get("dropped_frames")
            dfrac = (dropped / frames) if frames and dropped is not None else None
            lat = a["latency_ms"]["p95"] if a else None
            trials.append({
                "index": r["trial_index"], "practice": r["practice"], "method": r["method"],
                "image": r["image"], "final_value": r["final_value"],
                "response_time_s": r.get("response_time_s"),
                "blanked_fraction": r.get("blanked_fraction"), "dropped_frames": dropped,
                "frames": frames, "latency_p95_ms": lat,
                "rules": self.judge(r.get("blanked_fraction"), dfrac, lat),
            })
        for t in trials:
            t["flagged"] = [k for k, v in t["rules"].items() if v["exceeded"]]
        tracker: Mapping[str, Any] = live["tracker"] if isinstance(live.get("tracker"),
                                                                   Mapping) else {}
        info = info or {}
        tracker_info: Mapping[str, Any] = info["tracker"] if isinstance(info.get("tracker"),
                                                                        Mapping) else {}
        gaze = self._gaze(live.get("gaze"), skipped) if live else None
        if gaze is not None and status != "running":
            # rates of a stream that has stopped (the last write's, or a killed runner's):
            # not shown as if live
            gaze.update(samples_last_s=None, newest_age_s=None)
        out = {
            **self._overview(ref, live, info, status, why, trial),
            "protocol": _str(live.get("protocol_title")) or _str(info.get("protocol_path")),
            "protocol_sha256": _str(info.get("protocol_sha256") or live.get("protocol_sha256"),
                                    12),
            "radius_deg": _num(live.get("radius_deg")) or 1.25,
            "text": _str(live.get("text")),
            "trial": trial,
            "gaze": gaze,
            "attempts": attempts[-50:],
            "trials": trials,
            "totals": live.get("totals") if isinstance(live.get("totals"), Mapping) else {},
            "tracker": {"name": _str(live.get("tracker_name")) or _str(tracker_info.get("name")),
                        "connected": tracker.get("connected"),
                        "quality": tracker.get("quality"),
                        "events": tracker.get("events") if isinstance(tracker.get("events"),
                                                                      list) else []},
            "rules_apply": not dry and live.get("tracker_name") != SIMULATED_TRACKER,
            "limits": self.limits.as_dict(),
            "report": self._report(info),
            "skipped": skipped,
            "write_errors": _int(live.get("write_errors")),
        }
        return out

    def _overview(self, ref: SessionRef, live: Mapping[str, Any], info: Mapping[str, Any],
                  status: str, why: str | None, trial: Mapping[str, Any] | None,
                  ) -> dict[str, Any]:
        totals: Mapping[str, Any] = live["totals"] if isinstance(live.get("totals"),
                                                                 Mapping) else {}
        plan: Mapping[str, Any] = info["plan"] if isinstance(info.get("plan"), Mapping) else {}
        return {
            "key": ref.key, "experiment": ref.experiment, "participant": ref.participant,
            "session": ref.session, "status": status, "why": why,
            "state": _str(live.get("state")) or _str(info.get("state")),
            "dry_run": bool(live.get("dry_run")) if "dry_run" in live else None,
            "updated": _num(live.get("updated")),
            "since": _num(live.get("since")),
            "eta_s": _num(live.get("eta_s")) if status == "running" else None,
            "end": _end(live, info) if status == "finished" else None,
            "position": trial["position"] if trial else None,
            "total": trial["total"] if trial else None,
            "practice": trial["practice"] if trial else None,
            "flagged": trial["flagged"] if trial else [],
            "trials_done": _int(totals.get("trials_done")),
            "n_completed": _int(info.get("n_completed")),
            "n_trials": _int(plan.get("n_trials")),
            "started": _str(info.get("started")), "ended": _str(info.get("ended")),
            "file_state": _str(info.get("state")),
        }

    def _report(self, info: Mapping[str, Any]) -> dict[str, Any] | None:
        """The link to ``fovexp analyze``'s report, and whether it predates the session's end."""
        if self.report is None:
            return None
        html = self.report / "report.html"
        if not html.is_file():
            return {"url": None, "note": f"no report.html in {self.report} yet: run fovexp "
                                         f"analyze {self.root} --out {self.report}"}
        end_t = _ended_time(info)
        note = None
        if end_t is not None and html.stat().st_mtime < end_t:
            note = "the report is older than this session: run fovexp analyze again"
        return {"url": "/report/report.html", "note": note}

    # -- every session -------------------------------------------------------------------------
    def sessions(self) -> list[dict[str, Any]]:
        """Every session's overview: running ones first (newest update first), then those that
        stopped without saying so, then finished ones (latest end first)."""
        out = []
        for ref in self.refs().values():
            info, _ = self._session_file(ref)
            lr = self._live(ref)
            live = lr.data or {}
            status, why = self._status(ref, lr.data, info, lr.problem)
            trial = None
            if isinstance(live.get("trial"), Mapping):
                trial = self._attempt(live["trial"], [], "trial")
            out.append(self._overview(ref, live, info or {}, status, why, trial))
        def by(status: str) -> list[dict[str, Any]]:
            return [s for s in out if s["status"] == status]
        return [*sorted(by("running") + by("stopped"),
                        key=lambda s: (s["status"] != "running", -(s["updated"] or 0.0))),
                *sorted(by("finished"), key=lambda s: s["ended"] or "", reverse=True)]

    def snapshot(self, key: str | None) -> dict[str, Any]:
        """What the page gets each time: every session, and the one in view (by default the
        running session updated last)."""
        sessions = self.sessions()
        if key is None or self.resolve(key) is None:
            running = [s for s in sessions if s["status"] == "running"]
            key = running[0]["key"] if running else (sessions[0]["key"] if sessions else None)
        view = self.session(key) if key is not None else None
        return {"server_time": round(self.clock(), 3), "root": str(self.root),
                "sessions": sessions, "view": view,
                "report": "/report/report.html" if self.report is not None
                and (self.report / "report.html").is_file() else None}


__all__ = ["MAX_SESSION_BYTES", "ResultsView", "SessionRef", "parse_key"]
