"""ioHub as fovexp's gaze source (issue 22): what its server costs and how fast a lost one is
noticed, with the MouseGaze tracker under Xvfb (the pointer moved with xdotool).

    xvfb-run -a -s "-screen 0 1280x720x24" .venv/bin/python benchmarks/iohub.py

Measures: the server's start (``IoHubGaze``: launch, the tracker created, the first sample);
the reader thread's request round trip (``getEvents``) at its 1 ms pace; each sample's age when
the frame loop takes it (its ``system_time_us`` against ``now_us()`` at the poll, at 250 Hz);
the time from SIGKILL to ``connected`` False, and to samples again after the restart. Writes
benchmarks/IOHUB.md and benchmarks/iohub.json, with the machine and its load.
"""

from __future__ import annotations

import json
import os
import platform
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

CONFIG = """\
eyetracker.hw.mouse.EyeTracker:
  name: tracker
  runtime_settings: {sampling_rate: 250}
  device_timer: {interval: 0.004}
"""


def _pct(v: list[float]) -> dict[str, float]:
    a = np.asarray(v, dtype=float)
    return {"n": int(a.size), "p50": float(np.median(a)), "p99": float(np.percentile(a, 99)),
            "max": float(a.max())}


def main() -> None:
    from fovexp import load_display
    from fovexp.experiment.trackers.families import load_iohub_config
    from fovexp.experiment.trackers.iohub import IoHubGaze

    load = os.getloadavg()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "mousegaze.yaml"
        path.write_text(CONFIG)
        t0 = time.perf_counter()
        g = IoHubGaze(load_iohub_config(path), load_display("lg-oled55cx"))
        start_s = time.perf_counter() - t0
        g.start()
        subprocess.run(["xdotool", "mousemove", "640", "360"], check=True)
        # the round trip, timed the way the reader thread calls it (the reader is paused)
        with g._lock:
            rtt = []
            t_end = time.monotonic() + 2.0
            while time.monotonic() < t_end:
                a = time.perf_counter()
                evs = g.tracker.getEvents(asType="list")
                rtt.append(1e3 * (time.perf_counter() - a))
                for ev in evs or []:
                    g.buffer.append(ev)
                time.sleep(0.001)
        g.poll()
        ages = []
        t_end = time.monotonic() + 3.0
        while time.monotonic() < t_end:
            got = g.poll()
            now = g.now_us()
            ages += [(now - s.system_time_us) / 1e3 for s in got[-1:]]
            time.sleep(1 / 120)
        pid = g.server_pid
        t_kill = time.monotonic()
        os.kill(pid, signal.SIGKILL)
        while g.connected:
            g.poll_events()
            time.sleep(0.0005)
        noticed_ms = 1e3 * (time.monotonic() - t_kill)
        while not g.connected:
            g.poll_events()
            time.sleep(0.005)
        g.poll()
        while not g.poll():
            time.sleep(0.002)
        back_s = time.monotonic() - t_kill
        g.stop()
    out = {
        "machine": {"platform": platform.platform(), "cpus": os.cpu_count(),
                    "load_1_5_15": [round(x, 2) for x in load]},
        "server_start_s": round(start_s, 2), "roundtrip_ms": _pct(rtt),
        "sample_age_at_poll_ms": _pct(ages), "lost_noticed_ms": round(noticed_ms, 1),
        "samples_again_after_kill_s": round(back_s, 2),
    }
    (HERE / "iohub.json").write_text(json.dumps(out, indent=1) + "\n")
    r, a = out["roundtrip_ms"], out["sample_age_at_poll_ms"]
    rtt_s = f"{r['p50']:.3f} / {r['p99']:.3f} / {r['max']:.3f} ms"
    age_s = f"{a['p50']:.2f} / {a['p99']:.2f} / {a['max']:.2f} ms"
    md = f"""# ioHub as a gaze source (benchmarks/iohub.py)

MouseGaze at 250 Hz (server polling every 4 ms) under Xvfb, {out['machine']['platform']},
{out['machine']['cpus']} CPUs, load average {out['machine']['load_1_5_15']} (1, 5, 15 min) when
it started: the machine is shared with other engineers' runs.

| figure | value |
|---|---|
| server start (launch, tracker created, first sample) | {start_s:.2f} s |
| getEvents round trip, p50 / p99 / max ({r['n']} requests) | {rtt_s} |
| newest sample's age when the frame loop polls, p50 / p99 / max | {age_s} |
| SIGKILL to `connected` False | {noticed_ms:.1f} ms |
| SIGKILL to samples again (server started again) | {back_s:.2f} s |

The sample's age includes MouseGaze's own pacing (a sample every 4 ms, made in bursts when the
server polls): a tracker whose plugin stamps samples on arrival shows less.
"""
    (HERE / "IOHUB.md").write_text(md)
    print(md)


if __name__ == "__main__":
    main()
