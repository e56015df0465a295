"""The rig check's figures and verdicts, without a window: each measurement against its stated
threshold, and what to change when it fails (docs/EXPERIMENT.md, "The rig check").

Every check is a :class:`Check`: its value, the threshold as a sentence, pass (True), fail
(False) or not judged (None: not measured, or measured too briefly), and the advice a failed
one gives. Figures measured under a virtual display (Xvfb) carry a note saying so.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from fovexp.results.limits import TrialLimits

#: the measured refresh rate may differ from the profile's by this fraction
REFRESH_TOLERANCE = 0.005
#: the refresh rate is measured over at least this long (s) to be judged
MIN_REFRESH_S = 10.0
#: a frame whose interval exceeds this many refresh periods is dropped (as in the frame log)
DROPPED_PERIODS = 1.5
#: at most this fraction of the frames under the session's load may be dropped
MAX_DROPPED_FRACTION = 0.01
#: the tracker's measured rate within this fraction of its nominal one
RATE_TOLERANCE = 0.02
#: at most this fraction of the samples the nominal rate promises may be missing
MAX_SAMPLE_LOSS = 0.02
#: the texture hand-over (upload, or texture switch) within this fraction of a refresh period
MAX_HANDOVER_PERIODS = 0.25
#: the tracker's clock may drift against PsychoPy's by this much (parts per million)
MAX_CLOCK_DRIFT_PPM = 100.0
#: ... and the mapping between them jitter by this much around its line (ms)
MAX_CLOCK_JITTER_MS = 1.0
#: the 95th percentile of the gaze-to-flip latency: analysis rule R13's limit
MAX_LATENCY_P95_MS = TrialLimits().max_latency_p95_ms
#: the note on every figure measured under a virtual display
VIRTUAL = "measured under a virtual display (Xvfb, software GL): not this rig's"


@dataclass
class Check:
    """One check of the report."""

    id: str
    group: str
    title: str
    value: float | str | None
    unit: str
    threshold: str
    passed: bool | None
    advice: str = ""
    note: str = ""

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        if isinstance(self.value, float):
            d["value"] = None if math.isnan(self.value) else round(self.value, 4)
        return d


def _judge(passed: bool | None, advice: str) -> str:
    return advice if passed is False else ""


def _hz_band(nominal_hz: float, tolerance: float) -> str:
    """A rate's limit in the unit of the measured rate (Hz), the tolerance after it: a
    threshold reads against the value beside it without converting a percentage."""
    return (f"{nominal_hz * (1 - tolerance):.6g} to {nominal_hz * (1 + tolerance):.6g} Hz "
            f"({nominal_hz:g} Hz +/- {100 * tolerance:g} %)")


def source_name(kind: str, name: str) -> str:
    """The gaze source as the report names it: ``--tracker``'s kind, and the source's own
    name only where it says more (``iohub (mouse)``, not ``simulated: simulated``)."""
    return kind if name in ("", kind) else f"{kind} ({name})"


def interval_stats(flip_times_s: Sequence[float], refresh_hz: float) -> dict[str, Any]:
    """Frame intervals (ms: p50, p99, max) and the dropped frames (an interval longer than
    :data:`DROPPED_PERIODS` refresh periods, as the frame log counts them)."""
    t = np.asarray(flip_times_s, dtype=np.float64)
    dt = np.diff(t)
    if dt.size == 0:
        return {"frames": int(t.size), "p50_ms": math.nan, "p99_ms": math.nan,
                "max_ms": math.nan, "dropped": 0, "dropped_fraction": math.nan}
    ms = 1e3 * dt
    dropped = int((dt > DROPPED_PERIODS / refresh_hz).sum())
    return {"frames": int(t.size), "p50_ms": float(np.median(ms)),
            "p99_ms": float(np.percentile(ms, 99)), "max_ms": float(ms.max()),
            "dropped": dropped, "dropped_fraction": dropped / dt.size}


def refresh_rate_hz(flip_times_s: Sequence[float]) -> float | None:
    """The display's refresh rate from consecutive flips: refresh periods elapsed (each
    interval counted as a whole number of median intervals, so a dropped frame does not bias
    it) over the time they took."""
    t = np.asarray(flip_times_s, dtype=np.float64)
    if t.size < 3:
        return None
    dt = np.diff(t)
    period = float(np.median(dt))
    if period <= 0:
        return None
    periods = np.maximum(1, np.round(dt / period)).sum()
    return float(periods / (t[-1] - t[0]))


def clock_fit(x_s: Sequence[float], y_us: Sequence[float]) -> dict[str, float]:
    """A second clock ``y`` (us) against a reference ``x`` (s): the offset at the start (ms),
    the drift (ppm: the slope's excess over 1) and the largest distance from that line (ms)."""
    x = np.asarray(x_s, dtype=np.float64)
    y = np.asarray(y_us, dtype=np.float64) / 1e6
    if x.size < 3 or float(np.ptp(x)) <= 0:
        return {"offset_ms": math.nan, "drift_ppm": math.nan, "jitter_ms": math.nan,
                "span_s": 0.0, "pairs": int(x.size)}
    x0 = x - x[0]
    slope, icpt = np.polyfit(x0, y, 1)
    resid = y - (slope * x0 + icpt)
    return {"offset_ms": 1e3 * float(y[0] - x[0]), "drift_ppm": 1e6 * (float(slope) - 1.0),
            "jitter_ms": 1e3 * float(np.abs(resid).max()), "span_s": float(np.ptp(x)),
            "pairs": int(x.size)}


def photodiode_pattern(n: int) -> list[bool]:
    """The patch's states for ``n`` frames: a 31-frame maximal-length sequence (the 5-bit
    LFSR x^5 + x^3 + 1), repeated. Any 5 consecutive frames identify where in the sequence
    they are, so a photodiode trace aligns with the logged flips without ambiguity within 31
    frames; runs are at most 5 frames long, so the trace has edges throughout."""
    state = 0b00001
    seq = []
    for _ in range(31):
        seq.append(bool(state & 1))
        bit = (state ^ (state >> 2)) & 1
        state = (state >> 1) | (bit << 4)
    return [seq[i % 31] for i in range(n)]


# -- the verdicts ------------------------------------------------------------------------------

def refresh_check(measured_hz: float | None, nominal_hz: float, seconds: float,
                  profile: str, virtual: bool) -> Check:
    thr = (f"{_hz_band(nominal_hz, REFRESH_TOLERANCE)}, measured over at least "
           f"{MIN_REFRESH_S:g} s")
    if measured_hz is None:
        passed: bool | None = False
    elif seconds < MIN_REFRESH_S:
        passed = None
    else:
        passed = abs(measured_hz - nominal_hz) <= REFRESH_TOLERANCE * nominal_hz
    advice = (f"set the display to the profile {profile!r}'s mode ({nominal_hz:g} Hz), turn "
              "vsync on (driver settings: 'sync to vblank'), or correct refresh_hz in the "
              "profile")
    note = VIRTUAL + f"; {nominal_hz:g} Hz is the emulated vsync's rate" if virtual else ""
    if passed is None:
        note = (note + "; " if note else "") + f"measured over {seconds:.1f} s only: not judged"
    return Check("display.refresh", "display", "refresh rate", measured_hz, "Hz", thr, passed,
                 _judge(passed, advice), note)


def keyboard_check(backend: str | None, why_not: str | None, virtual: bool) -> Check:
    """Keys stamped when pressed (``why_not``: the session's own refusal,
    :func:`fovexp.experiment.display.checks.keys_at_poll`, None when they are)."""
    passed = why_not is None
    return Check("display.keyboard", "display", "key presses stamped when pressed",
                 backend or "unknown", "backend", "the keyboard gives each key its press time",
                 passed, _judge(passed, why_not or ""), VIRTUAL if virtual else "")


def dropped_check(stats: dict[str, Any], virtual: bool) -> Check:
    frac = stats["dropped_fraction"]
    passed = None if math.isnan(frac) else frac <= MAX_DROPPED_FRACTION
    advice = ("frames were dropped under the session's load: use the GPU backend (--backend "
              "gpu) on a hardware GPU, close other programs, check the compositor is off for "
              "the full-screen window (or 'unredirect fullscreen windows'), and that the "
              "render thread does not share the display thread's core")
    return Check("display.dropped", "display", "dropped frames under the session's load",
                 100 * frac, "%", f"at most {100 * MAX_DROPPED_FRACTION:g} % of the frames",
                 passed, _judge(passed, advice), VIRTUAL if virtual else "")


def wheel_step_check(step_ms: float | None, budget_ms: float, backend: str,
                     virtual: bool) -> Check:
    passed = None if step_ms is None else step_ms <= budget_ms
    advice = (f"a wheel step took longer than the protocol's render.max_step_ms on the "
              f"{backend} backend: use a hardware GPU (--backend gpu), fewer impulses, or a "
              "larger budget in the protocol")
    return Check("render.wheel_step", "gpu", "a wheel step rendered", step_ms, "ms",
                 f"within the protocol's render.max_step_ms, {budget_ms:g} ms", passed,
                 _judge(passed, advice), VIRTUAL if virtual else "")


def auto_backend_check(info: dict[str, Any], virtual: bool) -> Check:
    chosen = str(info.get("backend"))
    passed = chosen == "gpu"
    reason = info.get("fallback") or ""
    advice = ("--backend auto takes the CPU" + (f" ({reason})" if reason else "") + ": install "
              "the GPU's own OpenGL 4.5 driver (not Mesa's software renderer), or check that "
              "the X session runs on the GPU")
    return Check("gpu.auto", "gpu", "--backend auto picks the GPU", chosen, "backend",
                 "the GPU backend", passed, _judge(passed, advice),
                 VIRTUAL if virtual else "")


def gpu_frame_check(frame_ms: float | None, refresh_hz: float, size: tuple[int, int],
                    virtual: bool, why_not: str = "") -> Check:
    period = 1e3 / refresh_hz
    passed = None if frame_ms is None else frame_ms <= period
    advice = (f"the GPU's stages of a {size[0]}x{size[1]} frame take longer than a refresh "
              "period: a faster GPU, fewer impulses (12 instead of 64), or a frame already "
              "foveated by the renderer")
    note = VIRTUAL if virtual else ""
    if frame_ms is None and why_not:
        note = (note + "; " if note else "") + why_not
    return Check("gpu.stages", "gpu", f"GPU time of a {size[0]}x{size[1]} frame (profile_stages)",
                 frame_ms, "ms", f"within one refresh period, {period:.2f} ms", passed,
                 _judge(passed, advice), note)


def handover_check(p99_ms: float | None, refresh_hz: float, output: str,
                   virtual: bool) -> Check:
    limit = MAX_HANDOVER_PERIODS * 1e3 / refresh_hz
    passed = None if p99_ms is None or math.isnan(p99_ms) else p99_ms <= limit
    advice = ("handing the test half to the window takes too long: with the GPU backend it "
              "should be a texture switch (a GL context shared with the window's); an 8-bit "
              "upload needs a faster GPU or bus")
    return Check("gpu.handover", "gpu", f"texture hand-over ({output}), 99th percentile",
                 p99_ms, "ms", f"within {MAX_HANDOVER_PERIODS:g} of a refresh period, "
                 f"{limit:.2f} ms", passed, _judge(passed, advice), VIRTUAL if virtual else "")


def tracker_found_check(found: bool, name: str, error: str) -> Check:
    return Check("tracker.found", "tracker", "tracker found", name if found else None, "",
                 "the gaze source starts and sends samples", found,
                 "" if found else f"{error}: check the tracker's cable, power and address")


def rate_check(measured_hz: float | None, nominal_hz: float | None, simulated: bool) -> Check:
    passed = (None if measured_hz is None or not nominal_hz
              else abs(measured_hz - nominal_hz) <= RATE_TOLERANCE * nominal_hz)
    advice = (f"the tracker samples at {measured_hz} Hz, not {nominal_hz} Hz: set its "
              "sampling rate (its software, or the ioHub configuration's sampling_rate), or "
              "correct the protocol's tracker.sampling_hz")
    thr = (_hz_band(nominal_hz, RATE_TOLERANCE) if nominal_hz
           else f"within {100 * RATE_TOLERANCE:g} % of the nominal rate (not known)")
    return Check("tracker.rate", "tracker", "sampling rate (device clock)", measured_hz, "Hz",
                 thr, passed, _judge(passed, advice), "a simulated tracker" if simulated else "")


def loss_check(loss: float | None, simulated: bool) -> Check:
    passed = None if loss is None else loss <= MAX_SAMPLE_LOSS
    advice = ("samples the tracker should have sent never arrived: check its connection "
              "(a dedicated network port or USB 3 port), its host software's load, and the "
              "sampling rate it is set to")
    return Check("tracker.loss", "tracker", "samples missing (never delivered)",
                 None if loss is None else 100 * loss, "%",
                 f"at most {100 * MAX_SAMPLE_LOSS:g} % of the samples the nominal rate promises",
                 passed, _judge(passed, advice), "a simulated tracker" if simulated else "")


def latency_check(p95_ms: float | None, virtual: bool) -> Check:
    passed = None if p95_ms is None or math.isnan(p95_ms) else p95_ms <= MAX_LATENCY_P95_MS
    advice = ("the gaze-to-flip latency is too long for the analysis' rule R13: a faster "
              "tracker rate, the GPU backend, and no compositor in the display path")
    return Check("tracker.latency", "tracker", "gaze-to-flip latency, 95th percentile", p95_ms,
                 "ms", f"within analysis rule R13's {MAX_LATENCY_P95_MS:g} ms", passed,
                 _judge(passed, advice), VIRTUAL if virtual else "")


def clock_check(fit: dict[str, float], virtual: bool) -> Check:
    """The drift of the gaze source's clock against PsychoPy's (ppm); its jitter is
    :func:`clock_jitter_check`'s: each figure beside a limit in its own unit."""
    drift = fit["drift_ppm"]
    passed = None if math.isnan(drift) else abs(drift) <= MAX_CLOCK_DRIFT_PPM
    advice = ("the gaze source's clock and PsychoPy's drift apart: flips are put on the "
              "tracker's clock with it; check the tracker's time synchronisation (its host "
              "software, or the ioHub plugin's)")
    return Check("tracker.clock", "tracker", "tracker clock against PsychoPy's: drift",
                 drift, "ppm", f"within +/-{MAX_CLOCK_DRIFT_PPM:g} ppm", passed,
                 _judge(passed, advice), VIRTUAL if virtual else "")


def clock_jitter_check(fit: dict[str, float], virtual: bool) -> Check:
    """The largest distance of the gaze source's clock from its fitted line against
    PsychoPy's (ms): a jump the drift does not show."""
    jitter = fit["jitter_ms"]
    passed = None if math.isnan(jitter) else jitter <= MAX_CLOCK_JITTER_MS
    advice = ("the gaze source's clock jumps against PsychoPy's: flips are put on the "
              "tracker's clock with it; check the tracker's time synchronisation (its host "
              "software, or the ioHub plugin's) and the host's load")
    return Check("tracker.clock_jitter", "tracker",
                 "tracker clock against PsychoPy's: jitter (largest jump from the fit)",
                 jitter, "ms", f"at most {MAX_CLOCK_JITTER_MS:g} ms", passed,
                 _judge(passed, advice), VIRTUAL if virtual else "")


__all__ = ["Check", "DROPPED_PERIODS", "MAX_CLOCK_DRIFT_PPM", "MAX_CLOCK_JITTER_MS",
           "MAX_DROPPED_FRACTION", "MAX_HANDOVER_PERIODS", "MAX_LATENCY_P95_MS",
           "MAX_SAMPLE_LOSS", "MIN_REFRESH_S", "RATE_TOLERANCE", "REFRESH_TOLERANCE", "VIRTUAL",
           "auto_backend_check", "clock_check", "clock_fit", "clock_jitter_check",
           "dropped_check", "gpu_frame_check", "handover_check", "interval_stats",
           "latency_check", "loss_check", "photodiode_pattern", "rate_check", "refresh_check",
           "refresh_rate_hz", "source_name", "tracker_found_check", "wheel_step_check"]
