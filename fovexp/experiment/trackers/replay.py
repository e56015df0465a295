"""A recorded gaze, replayed (``fovexp run --dry-run --gaze-replay FILE``): the eye of a real
session, or of any recording, drives a dry run on the session's clock, with the simulated
tracker's delivery latency on top (:class:`~.simulated.ClockedGaze`).

Two formats, told apart by the header:

- a fovexp gaze log (``gaze-<session>.csv``, docs/LOGS.md): both eyes, their validity and the
  device times as recorded;
- a plain CSV with a time column (``time_s``, ``time_ms`` or ``time_us``), ``x``, ``y`` and
  optionally ``valid`` (1/0): positions in normalised screen coordinates (x right, y down), or,
  with ``units: deg`` (``--gaze-replay-units deg``), in degrees from the cross.

Sample ``i`` reaches the runner at its recorded time after the first sample's, counted from
the source's start, so that replaying the same file twice gives the same samples in the same
order. A replay shorter than the session starts again from its first sample (``loop``), or the
session stops with one line (``stop``).
"""

from __future__ import annotations

import csv
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

from fovexp import FovexpError

from .gaze import FixationGeometry, GazeSample, monotonic_us
from .simulated import ClockedGaze

END_CHOICES = ("loop", "stop")
_TIME_UNITS = {"time_s": 1e6, "time_ms": 1e3, "time_us": 1.0}


def _num(row: dict[str, str], key: str, path: Path, n: int) -> float:
    try:
        return float(row[key]) if row.get(key, "") != "" else math.nan
    except ValueError:
        raise FovexpError(f"{path}: row {n}: {key}={row[key]!r} is not a number") from None


def read_replay(path: Path, fixation: FixationGeometry, units: str = "norm"
                ) -> list[tuple[int, GazeSample]]:
    """The samples of ``path``, each with its time (us) after the first; raises
    :class:`FovexpError` naming the file and what is wrong."""
    try:
        with path.open(newline="") as f:
            rows = list(csv.DictReader(f))
            header = rows[0].keys() if rows else []
    except OSError as exc:
        raise FovexpError(f"--gaze-replay: cannot read {path}: {exc.strerror}") from None
    except (csv.Error, UnicodeDecodeError) as exc:
        raise FovexpError(f"--gaze-replay: {path} is not a CSV file ({exc})") from None
    if not rows:
        raise FovexpError(f"--gaze-replay: {path} has no samples")
    out: list[tuple[int, GazeSample]] = []
    if "system_time_us" in header and "left_x" in header:  # a fovexp gaze log
        t0 = None
        for n, r in enumerate(rows, 2):
            t = int(_num(r, "system_time_us", path, n))
            t0 = t if t0 is None else t0
            lv, rv = r.get("left_valid") in ("1", "True"), r.get("right_valid") in ("1", "True")
            s = GazeSample(int(_num(r, "device_time_us", path, n)), 0,
                           _num(r, "left_x", path, n), _num(r, "left_y", path, n), lv,
                           _num(r, "right_x", path, n), _num(r, "right_y", path, n), rv)
            out.append((t - t0, s))
        return out
    time_key = next((k for k in _TIME_UNITS if k in header), None)
    if time_key is None or "x" not in header or "y" not in header:
        raise FovexpError(f"--gaze-replay: {path}: neither a fovexp gaze log nor a CSV with "
                          f"a time column ({', '.join(_TIME_UNITS)}), x and y")
    if units not in ("norm", "deg"):
        raise FovexpError(f"--gaze-replay-units: {units!r} (norm or deg)")
    t0 = None
    for n, r in enumerate(rows, 2):
        t = round(_num(r, time_key, path, n) * _TIME_UNITS[time_key])
        t0 = t if t0 is None else t0
        x, y = _num(r, "x", path, n), _num(r, "y", path, n)
        if units == "deg" and math.isfinite(x) and math.isfinite(y):
            x, y = fixation.offset_to_norm(x, y)
        ok = (r.get("valid", "1") not in ("0", "False", "false")
              and math.isfinite(x) and math.isfinite(y))
        x, y = (x, y) if ok else (math.nan, math.nan)
        out.append((t - t0, GazeSample(t - t0, 0, x, y, ok, x, y, ok)))
    if any(b[0] < a[0] for a, b in zip(out, out[1:], strict=False)):
        raise FovexpError(f"--gaze-replay: {path}: the times go backwards")
    return out


class ReplayGaze(ClockedGaze):
    """The samples of :func:`read_replay`, delivered on the session's clock (module
    docstring); ``end``: ``loop`` or ``stop``."""

    name = "replay"
    #: a recording cannot look at calibration targets: the set-up is skipped, as the mouse's
    validated = False

    def __init__(self, path: Path, fixation: FixationGeometry, units: str = "norm",
                 end: str = "loop", latency_ms: float = 0.0, latency_jitter_ms: float = 0.0,
                 seed: int = 0, clock_us: Callable[[], int] = monotonic_us) -> None:
        if end not in END_CHOICES:
            raise FovexpError(f"--gaze-replay-end: {end!r} (loop or stop)")
        self.path, self.end = Path(path), end
        self.samples = read_replay(self.path, fixation, units)
        span = self.samples[-1][0]
        step = span / max(1, len(self.samples) - 1)
        #: one pass of the recording, and the gap before it starts again
        self.period_us = int(span + step)
        super().__init__(1e6 / step if step > 0 else 600.0, clock_us, latency_ms,
                         latency_jitter_ms, seed)

    def info(self) -> dict[str, Any]:
        return {"name": self.name, "file": str(self.path), "samples": len(self.samples),
                "end": self.end, "latency_ms": self.latency_ms,
                "latency_jitter_ms": self.latency_jitter_ms}

    def _measured_by(self, now: int) -> list[GazeSample]:
        assert self._t0 is not None
        out = []
        n = len(self.samples)
        while True:
            k, i = divmod(self._n, n)
            t = k * self.period_us + self.samples[i][0]
            if self._t0 + t > now:
                break
            if k > 0 and self.end == "stop":
                raise FovexpError(f"the gaze replay {self.path} ended after "
                                  f"{self.period_us / 1e6:.1f} s (--gaze-replay-end loop "
                                  "repeats it)")
            s = self.samples[i][1]
            out.append(s._replace(system_time_us=self._t0 + t))
            self._n += 1
        return out


__all__ = ["END_CHOICES", "ReplayGaze", "read_replay"]
