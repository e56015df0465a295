"""Results folders as ``fovexp monitor`` finds them, written by hand: session files, live status
files and trial logs, well-formed or damaged (tests/monitor/)."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from fovexp.results.format import TRIAL_COLUMNS, format_line
from fovexp.results.live import LIVE_FORMAT, write_live

REPO = Path(__file__).resolve().parent.parent


def session_file(folder: Path, sid: str, state: str = "running", n_trials: int = 10,
                 dry_run: bool = True, ended: str | None = None, **extra: Any) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"session-{sid}.json"
    path.write_text(json.dumps({
        "session": sid, "participant": folder.name, "experiment": folder.parent.name,
        "state": state, "completed": state == "completed", "plan": {"n_trials": n_trials},
        "started": "2026-11-24T10:00:00+00:00", "ended": ended, "n_completed": 0,
        "runs": [{"dry_run": dry_run}], "protocol_sha256": "ab" * 32, **extra}))
    return path


def live(sid: str, *, state: str = "trial", position: int = 3, total: int = 10,
         blanked: float = 0.1, dropped: int = 1, frames: int = 300, p95: float = 12.0,
         dry_run: bool = True, updated: float | None = None, pid: int | None = None,
         host: str | None = None, seq: int = 1, **extra: Any) -> dict[str, Any]:
    """A live status file's content, as the runner writes it (fovexp.experiment.records.live)."""
    trial = {"index": position + 1, "attempt": 0, "position": position, "total": total,
             "practice": False, "method": "ours", "image": "scene-02", "parameter": "s_k",
             "value": 21.5, "start_value": 10.0, "frames": frames, "dropped": dropped,
             "dropped_fraction": dropped / frames, "blanked_fraction": blanked,
             "elapsed_s": frames / 120, "blank": False, "gaze_ecc_deg": 0.4,
             "latency_ms": {"n": frames, "median": p95 / 2, "p95": p95, "max": p95 * 1.5},
             "outcome": None}
    data = {
        "format": LIVE_FORMAT, "session": sid, "pid": pid if pid is not None else os.getpid(),
        "host": host if host is not None else os.uname().nodename, "period_s": 0.25,
        "participant": "P01", "experiment": "calibration-sk", "dry_run": dry_run,
        "tracker_name": "simulated" if dry_run else "tobii", "radius_deg": 1.25,
        "protocol_title": "Calibration 2", "updated": time.time() if updated is None else updated,
        "seq": seq, "state": state, "text": None, "since": time.time(), "trial": trial,
        "attempts": [dict(trial, index=position, position=position - 1, outcome="done")],
        "gaze": {"window_s": 3.0, "t": [-0.02, -0.01, 0.0], "x_deg": [0.1, None, 0.3],
                 "y_deg": [-0.1, None, 0.2], "newest_age_s": 0.01, "samples_last_s": 600},
        "totals": {"frames": 3000, "dropped": 4, "latency_ms": {"n": 3000, "p50": 9.0,
                                                                "p95": 12.0},
                   "pauses": 1, "breaks": 0, "disconnections": 0, "trials_done": 2},
        "tracker": {"connected": True, "events": [],
                    "quality": {"accuracy_deg": 0.4, "central_accuracy_deg": 0.3,
                                "data_loss": 0.02, "passed": True, "accepted": True}},
        "eta_s": 95.0, "write_errors": 0,
    }
    data.update(extra)
    return data


def write_live_file(folder: Path, data: dict[str, Any]) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"live-{data['session']}.json"
    write_live(path, data)
    return path


def trial_row(sid: str, index: int, **kw: Any) -> dict[str, Any]:
    row = {"participant": "P01", "session": sid, "experiment": "calibration-sk",
           "protocol_sha256": "ab" * 32, "trial_index": index, "practice": 0, "repetition": 0,
           "image": "scene-01", "blur_rate": 0.34, "method": "ours",
           "adjusted_parameter": "s_k", "f_e": 0.2, "s_k": 20.0, "s_f": 2.2,
           "start_value": 10.0, "final_value": 20.0, "response_time_s": 3.2, "wheel_events": 5,
           "blanked_fraction": 0.01, "dropped_frames": 0, "tracker": "simulated", "seed": 1,
           "software_version": "0.1", "timestamp": "2026-11-24T10:00:00+00:00"}
    row.update(kw)
    return row


def trials_text(rows: list[dict[str, Any]]) -> str:
    return format_line(TRIAL_COLUMNS) + "".join(
        format_line([r.get(c) for c in TRIAL_COLUMNS]) for r in rows)


class MonitorProcess:
    """``python -m fovexp monitor ARGS`` in a subprocess; :attr:`url` is the address it
    printed (with its token, when it has one)."""

    def __init__(self, args: list[str], cwd: Path | None = None, timeout_s: float = 30) -> None:
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join([str(REPO), env.get("PYTHONPATH", "")]).rstrip(
            os.pathsep)
        self.proc = subprocess.Popen([sys.executable, "-m", "fovexp", "monitor", *args],
                                     cwd=cwd, env=env, stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True)
        assert self.proc.stderr is not None
        deadline = time.monotonic() + timeout_s
        self.first_line = ""
        while time.monotonic() < deadline:
            line = self.proc.stderr.readline()
            if not line:
                break
            self.first_line = line.strip()
            m = re.search(r"(http://\S+)", line)
            if m:
                self.url = m.group(1)
                self.base = self.url.split("?")[0].rstrip("/")
                self.token = m.group(1).partition("?token=")[2] or None
                return
        self.stop()
        raise RuntimeError(f"fovexp monitor did not start: {self.first_line}")

    def stop(self) -> int:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        return self.proc.returncode
