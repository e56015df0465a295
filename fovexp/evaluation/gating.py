"""``fovexp evaluate gating``: how late the gaze can be before the periphery is no longer tested
(issue 28; docs/EXPERIMENT.md, "Gaze truth").

Dry runs of one protocol, each with the simulated eye of one behaviour (``--sim-gaze``) and
one delivery latency (``--gaze-latency-ms``), run as a lab would (``fovexp run`` under Xvfb,
each its own process, the same seeds); then, from each session's logs alone
(:mod:`fovexp.results.gating`): the delivery latency, the stimulus frames the latency let
through, and, against the simulated eye's truth, the stimulus time on screen while the eye was
outside the 1.25 deg window, per trial and per excursion of the eye out of the window. The
table and the plot mark the two thresholds of the literature: 6 ms after a saccade's end
(McConkie and Loschky 2002) and 60 ms (Loschky and Wolverton 2007, for the blur they tested).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from fovexp import FovexpError
from fovexp.results.blanking import BlankingRule
from fovexp.results.frames import read_frame_log
from fovexp.results.gating import (
    BLUR_TOLERATED_AFTER_SACCADE_MS,
    UNNOTICED_AFTER_SACCADE_MS,
    excursion_exposure,
    read_gaze_log,
    session_gating,
    stimulus_outside,
)

LATENCIES_MS = (0.0, 4.0, 8.0, 16.0, 32.0, 48.0, 64.0)
BEHAVIOURS = ("steady", "wandering")


def _fovexp() -> list[str]:
    """This fovexp's command line (the same interpreter)."""
    return [sys.executable, "-m", "fovexp"]


def run_session(results: Path, participant: str, *, protocol: str, behaviour: str,
                latency_ms: float, trials: int, seed: int, sim_speed: float,
                stimuli: Path | None) -> None:
    """One dry run, in its own process, under Xvfb where there is no display."""
    cmd = [*_fovexp(), "run", protocol, "--participant", participant, "--dry-run",
           "--results", str(results), "--limit-trials", str(trials), "--practice", "0",
           "--sim-seed", str(seed), "--sim-speed", str(sim_speed), "--sim-gaze", behaviour,
           "--gaze-latency-ms", str(latency_ms)]
    if stimuli is not None:
        cmd += ["--stimuli", str(stimuli)]
    if not os.environ.get("DISPLAY"):
        if shutil.which("xvfb-run") is None:
            raise FovexpError("fovexp evaluate gating: no display and no xvfb-run (install "
                              "xvfb) for its dry runs")
        cmd = ["xvfb-run", "-a", "-s", "-screen 0 1280x720x24", *cmd]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        tail = (done.stderr.strip().splitlines() or ["(no output)"])[-1]
        raise FovexpError(f"fovexp evaluate gating: the dry run {participant} failed: {tail}")


def measure(folder: Path, rule: BlankingRule) -> tuple[dict[str, float], pd.DataFrame,
                                                       np.ndarray]:
    """A session folder's figures, per-trial exposure and per-excursion exposure."""
    sid = next(folder.glob("session-*.json")).stem.removeprefix("session-")
    frames = read_frame_log(folder / f"frames-{sid}.csv")
    gaze = read_gaze_log(folder / f"gaze-{sid}.csv")
    figures = session_gating(frames, gaze, rule)
    figures["blanked_fraction"] = float((frames["blanked"] == 1).mean()) if len(frames) else 0.0
    return figures, stimulus_outside(frames, gaze, rule), excursion_exposure(frames, gaze, rule)


def run(out: Path, *, protocol: str = "calibration-fe",
        latencies_ms: Sequence[float] = LATENCIES_MS,
        behaviours: Sequence[str] = BEHAVIOURS, trials: int = 3, seed: int = 5,
        sim_speed: float = 12.0, stimuli: Path | None = None,
        say=print) -> pd.DataFrame:  # noqa: ANN001
    """The study: a dry run per behaviour and latency into ``out/results``, then
    ``gating.csv`` (per session), ``gating-trials.csv``, ``gating-excursions.csv``,
    ``gating.png`` and ``gating.md`` in ``out``. The same seed for every run: the behaviours'
    eyes differ only by their settings, the latencies not at all."""
    out.mkdir(parents=True, exist_ok=True)
    results = out / "results"
    if results.exists():
        shutil.rmtree(results)
    rule = BlankingRule()
    rows, per_trial, per_excursion = [], [], []
    for i, b in enumerate(behaviours):
        for k, lat in enumerate(latencies_ms):
            pid = f"G{i:02d}{k:02d}"
            if lat >= 1e3 * rule.timeout_s:
                # every sample is older than the gaze timeout when it arrives: the rule never
                # shows the stimulus, and a trial could not end (nothing to judge)
                say(f"fovexp evaluate gating: {b}, {lat:g} ms: not run (at or above the gaze "
                    f"timeout, {1e3 * rule.timeout_s:g} ms: the stimulus is never shown)")
                rows.append({"behaviour": b, "latency_ms": lat, "never_shown": True})
                continue
            n_run = i * len(latencies_ms) + k + 1  # a line per dry run: each takes minutes
            say(f"fovexp evaluate gating: run {n_run}/{len(behaviours) * len(latencies_ms)}: "
                f"{b}, {lat:g} ms ({pid})")
            run_session(results, pid, protocol=protocol, behaviour=b, latency_ms=lat,
                        trials=trials, seed=seed, sim_speed=sim_speed, stimuli=stimuli)
            folder = next(results.glob(f"*/{pid}"))
            fig, trials_df, ex = measure(folder, rule)
            rows.append({"behaviour": b, "latency_ms": lat, "never_shown": False, **fig})
            per_trial.append(trials_df.assign(behaviour=b, latency_ms=lat))
            per_excursion += [{"behaviour": b, "latency_ms": lat, "exposure_ms": float(v)}
                              for v in ex]
    table = pd.DataFrame(rows)
    table.to_csv(out / "gating.csv", index=False)
    pd.concat(per_trial, ignore_index=True).to_csv(out / "gating-trials.csv", index=False)
    excursions = pd.DataFrame(per_excursion, columns=["behaviour", "latency_ms", "exposure_ms"])
    excursions.to_csv(out / "gating-excursions.csv", index=False)
    plot(table, excursions, out / "gating.png")
    (out / "gating.md").write_text(note(table, excursions, protocol, trials, seed))
    return table


def _summary(excursions: pd.DataFrame) -> pd.DataFrame:
    g = excursions.groupby(["behaviour", "latency_ms"])["exposure_ms"]
    return pd.DataFrame({"excursions": g.size(), "exposure_p50_ms": g.median(),
                         "exposure_p95_ms": g.quantile(0.95), "exposure_max_ms": g.max(),
                         "over_6ms": g.apply(lambda s: int((s > UNNOTICED_AFTER_SACCADE_MS)
                                                           .sum())),
                         "over_60ms": g.apply(lambda s: int((s > BLUR_TOLERATED_AFTER_SACCADE_MS)
                                                            .sum()))}).reset_index()


def plot(table: pd.DataFrame, excursions: pd.DataFrame, path: Path) -> None:
    """Left: the stimulus time outside the window per session (ms) against the latency; right:
    each excursion's exposure (median and maximum), with the two thresholds."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    summary = _summary(excursions) if len(excursions) else None
    for beh, grp in table[~table["never_shown"].astype(bool)].groupby("behaviour", sort=False):
        a.plot(grp["latency_ms"], grp["outside_ms"], "o-", label=beh)
        if summary is not None:
            s = summary[summary["behaviour"] == beh]
            b.plot(s["latency_ms"], s["exposure_max_ms"], "o-", label=f"{beh}: maximum")
            b.plot(s["latency_ms"], s["exposure_p50_ms"], "s--", label=f"{beh}: median")
    a.set_xlabel("injected delivery latency (ms)")
    a.set_ylabel("stimulus time outside the window (ms, per session)")
    a.legend()
    for y, text in ((UNNOTICED_AFTER_SACCADE_MS, "6 ms (McConkie & Loschky 2002)"),
                    (BLUR_TOLERATED_AFTER_SACCADE_MS, "60 ms (Loschky & Wolverton 2007)")):
        b.axhline(y, color="grey", lw=0.8, ls=":")
        b.text(0, y, text, va="bottom", fontsize=8, color="grey")
    b.set_xlabel("injected delivery latency (ms)")
    b.set_ylabel("stimulus on screen after the eye left (ms, per excursion)")
    b.legend(fontsize=8)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def note(table: pd.DataFrame, excursions: pd.DataFrame, protocol: str, trials: int,
         seed: int) -> str:
    """The study's Markdown: the per-session table and the excursions' summary."""
    cols = ["behaviour", "latency_ms", "never_shown", "blanked_fraction", "delivery_p50_ms",
            "delivery_max_ms", "tracker_cost_frames", "stamped_violations", "outside_ms",
            "outside_fraction", "excursion_max_ms"]

    def md(df: pd.DataFrame) -> str:
        head = "| " + " | ".join(df.columns) + " |\n|" + "---|" * len(df.columns) + "\n"
        body = "".join("| " + " | ".join(f"{v:.3g}" if isinstance(v, float) else str(v)
                                         for v in r) + " |\n"
                       for r in df.itertuples(index=False))
        return head + body

    text = (f"# Gating study: {protocol}, {trials} trials per dry run, seed {seed}\n\n"
            "Per dry run (one behaviour, one injected delivery latency; `never_shown`: a "
            "latency at or above the gaze timeout, where every sample arrives too old for the "
            "rule and the stimulus never appears, not run):\n\n"
            + md(table.reindex(columns=cols)))
    if len(excursions):
        text += ("\nPer excursion of the simulated eye out of the 1.25 deg window: the stimulus "
                 "time on screen after it left (ms), and how many exceed 6 ms (McConkie and "
                 "Loschky 2002) and 60 ms (Loschky and Wolverton 2007):\n\n"
                 + md(_summary(excursions)))
    return text


def parse_list(text: str, what: str) -> list[float]:
    try:
        out = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise FovexpError(f"--{what}: {text!r} is not a comma-separated list of numbers") from None
    if not out or any(not (0 <= v < 10_000) for v in out):
        raise FovexpError(f"--{what}: latencies in ms, 0 to 10000")
    return out


__all__ = ["BEHAVIOURS", "LATENCIES_MS", "measure", "note", "plot", "run", "run_session"]
