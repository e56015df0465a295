"""Calibration results (paper section 5.3, Figure "calibration_results", Table 2).

Three experiments, each adjusting one parameter per foveation level (blur-rate, section 5.2):

* ``calibration-fe``: f_e alone -> mean f_e per blur-rate;
* ``calibration-sk``: s_k at fixed s_f (1, 1.9, 3.61, 6.81) -> mean s_k per (blur-rate, s_f) and
  the least-squares line s_k = slope * s_f + intercept per blur-rate, which the next experiment
  uses to set s_k from the adjusted s_f;
* ``calibration-sf``: s_f with s_k from that line -> the final s_f per blur-rate, and its s_k.

Averaging: each participant's trials at one condition (images, repetitions) are averaged first;
means and SEMs are then taken across participants (n = participants). The s_k line is fitted to
the per-s_f means, so every s_f level weighs the same whatever its trial count.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from pydantic import ValidationError

from fovexp import FovexpError, ParameterTable, validation_error

from .stats import Line, linear_fit, mean_sem

#: Decimal places that identify a condition level (blur-rate, s_f): float noise in logs is merged.
LEVEL_DECIMALS = 6


def _levels(values: pd.Series) -> pd.Series:
    return values.astype(float).round(LEVEL_DECIMALS)


def _require(trials: pd.DataFrame, parameter: str, what: str) -> pd.DataFrame:
    sel = trials[trials["adjusted_parameter"] == parameter]
    if sel.empty:
        raise FovexpError(f"{what}: no trials adjusting {parameter}")
    return sel


def summarize(trials: pd.DataFrame, by: list[str], value: str = "final_value") -> pd.DataFrame:
    """Mean +- SEM of ``value`` per group of ``by``: participant means first, then across them.

    Columns: ``by``..., mean, sem, n (participants), n_trials.
    """
    frame = trials.copy()
    for col in by:
        if col in ("blur_rate", "s_f", "s_k", "f_e"):
            frame[col] = _levels(frame[col])
    per_part = frame.groupby([*by, "participant"], sort=True)[value].agg(["mean", "size"])
    rows = []
    # A scalar level for one key keeps the group keys scalars (pandas deprecates 1-lists).
    for key, grp in per_part.groupby(level=by if len(by) > 1 else by[0], sort=True):
        mean, sem, n = mean_sem(grp["mean"].to_numpy())
        key = key if isinstance(key, tuple) else (key,)
        rows.append({**dict(zip(by, key, strict=True)), "mean": mean, "sem": sem, "n": n,
                     "n_trials": int(grp["size"].sum())})
    return pd.DataFrame(rows, columns=[*by, "mean", "sem", "n", "n_trials"])


def fe_summary(trials: pd.DataFrame) -> pd.DataFrame:
    """Per blur-rate mean +- SEM of the adjusted f_e (section 5.2, "Contrast enhancement")."""
    return summarize(_require(trials, "f_e", "calibration-fe"), ["blur_rate"])


def sk_summary(trials: pd.DataFrame) -> pd.DataFrame:
    """Per (blur-rate, s_f) mean +- SEM of the adjusted s_k (section 5.2, "Amplitude scaling")."""
    sel = _require(trials, "s_k", "calibration-sk")
    bad = sel[sel["s_f"].isna()]
    if len(bad):
        row = bad.iloc[0]
        raise FovexpError(f"{row['file']}: line {row['line']}: column s_f is empty in an s_k "
                          "trial (the fixed s_f is needed)")
    return summarize(sel, ["blur_rate", "s_f"])


def sk_lines(sk: pd.DataFrame) -> dict[float, Line]:
    """Least-squares s_k = slope * s_f + intercept per blur-rate, fitted to ``sk_summary`` means."""
    lines: dict[float, Line] = {}
    for br, grp in sk.groupby("blur_rate", sort=True):
        try:
            lines[float(br)] = linear_fit(grp["s_f"], grp["mean"])
        except FovexpError as exc:
            raise FovexpError(f"calibration-sk at blur-rate {br}: {exc}") from None
    return lines


def participant_sk_lines(trials: pd.DataFrame) -> dict[float, list[Line]]:
    """Per blur-rate, each participant's own s_k line (their per-s_f means; at least two s_f).

    Used for the uncertainty of the group line's prediction (see :func:`sf_summary`).
    """
    sel = trials[trials["adjusted_parameter"] == "s_k"].copy()
    sel["blur_rate"] = _levels(sel["blur_rate"])
    sel["s_f"] = _levels(sel["s_f"])
    means = sel.groupby(["blur_rate", "participant", "s_f"])["final_value"].mean().reset_index()
    out: dict[float, list[Line]] = {}
    for (br, _), grp in means.groupby(["blur_rate", "participant"], sort=True):
        if grp["s_f"].nunique() >= 2:
            out.setdefault(float(br), []).append(linear_fit(grp["s_f"], grp["final_value"]))
    return out


def sf_summary(trials: pd.DataFrame, lines: dict[float, Line],
               participant_lines: dict[float, list[Line]] | None = None) -> pd.DataFrame:
    """Final s_f per blur-rate (mean +- SEM) and its s_k from the s_k line (section 5.2,
    "Bandwidth scaling").

    The s_k SEM combines the two experiments' uncertainties: sqrt((slope * SEM(s_f))^2 +
    SEM_line^2), SEM_line being the SEM across participants of their own lines' s_k at the final
    s_f (left out when ``participant_lines`` is not given or has fewer than two lines).
    """
    sf = summarize(_require(trials, "s_f", "calibration-sf"), ["blur_rate"])
    missing = [br for br in sf["blur_rate"] if float(br) not in lines]
    if missing:
        raise FovexpError(f"calibration-sk has no s_k line at blur-rate(s) "
                          f"{', '.join(f'{m:g}' for m in missing)} used by calibration-sf")
    sf = sf.rename(columns={"mean": "s_f", "sem": "s_f_sem"})
    s_k, s_k_sem = [], []
    for br, s_f, s_f_sem in zip(sf["blur_rate"], sf["s_f"], sf["s_f_sem"], strict=True):
        line = lines[float(br)]
        s_k.append(float(line(s_f)))
        var = (line.slope * s_f_sem) ** 2 if np.isfinite(s_f_sem) else 0.0
        own = (participant_lines or {}).get(float(br), [])
        if len(own) >= 2:
            var += mean_sem([ln(s_f) for ln in own])[1] ** 2
        s_k_sem.append(float(np.sqrt(var)) if var > 0 else float("nan"))
    sf["s_k"] = s_k
    sf["s_k_sem"] = s_k_sem
    return sf[["blur_rate", "s_f", "s_f_sem", "s_k", "s_k_sem", "n", "n_trials"]]


@dataclass
class Calibration:
    """Everything of section 5.3: the three panels' data and Table 2."""

    fe: pd.DataFrame
    sk: pd.DataFrame
    lines: dict[float, Line]
    sf: pd.DataFrame
    table: pd.DataFrame  # blur_rate, f_e, f_e_sem, s_k, s_k_sem, s_f, s_f_sem

    def parameter_table(self, source: str = "fovexp analyze: lab calibration") -> ParameterTable:
        """Table 2 in the format the enhancer reads (:class:`fovexp.ParameterTable`)."""
        rows = [{k: float(r[k]) for k in ("blur_rate", "f_e", "s_k", "s_f")}
                for _, r in self.table.iterrows()]
        try:
            return ParameterTable(source=source, rows=rows)
        except ValidationError as exc:
            raise validation_error("calibrated Table 2 is outside the enhancer's ranges",
                                   exc) from None


def calibrate(fe_trials: pd.DataFrame, sk_trials: pd.DataFrame,
              sf_trials: pd.DataFrame) -> Calibration:
    """Table 2 (section 5.3) from the trials of the three calibration experiments.

    The table's blur-rates are those of calibration-sf; f_e and the s_k line must exist at each.
    """
    fe = fe_summary(fe_trials)
    sk = sk_summary(sk_trials)
    lines = sk_lines(sk)
    sf = sf_summary(sf_trials, lines, participant_sk_lines(sk_trials))
    fe_by = {float(r["blur_rate"]): r for _, r in fe.iterrows()}
    missing = [br for br in sf["blur_rate"] if float(br) not in fe_by]
    if missing:
        raise FovexpError(f"calibration-fe has no trials at blur-rate(s) "
                          f"{', '.join(f'{m:g}' for m in missing)} used by calibration-sf")
    table = pd.DataFrame({
        "blur_rate": sf["blur_rate"].astype(float),
        "f_e": [float(fe_by[float(b)]["mean"]) for b in sf["blur_rate"]],
        "f_e_sem": [float(fe_by[float(b)]["sem"]) for b in sf["blur_rate"]],
        "s_k": sf["s_k"], "s_k_sem": sf["s_k_sem"], "s_f": sf["s_f"], "s_f_sem": sf["s_f_sem"],
    }).reset_index(drop=True)
    return Calibration(fe=fe, sk=sk, lines=lines, sf=sf, table=table)
