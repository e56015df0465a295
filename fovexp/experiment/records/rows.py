"""The rows a session writes for a trial, without a window: the trial log's row (the trial's
commit point), the gaze log's rows and the blanking log's episodes (docs/LOGS.md). The frame
log's rows are made by the frame loop itself (:class:`fovexp.experiment.tasks.frameloop.TrialLoop`).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from fovexp.results.format import now_iso

from ..protocol.spec import LoadedProtocol, Trial
from ..tasks.trial import Episode, TrialState
from ..trackers.gaze import FixationGeometry, GazeSample, sample_row
from .sessionfile import software_version

#: what the gaze log is given per sample: (trial index, attempt, sample); trial and attempt
#: are None between trials. Made into a row on the log's flusher thread (:func:`gaze_row`).
GazeItem = tuple[int | None, int | None, GazeSample]


def gaze_items(trial_index: int | None, samples: list[GazeSample],
               attempt: int | None = None) -> list[GazeItem]:
    """What the gaze log gets for ``samples``; ``attempt`` only within a trial."""
    a = attempt if trial_index is not None else None
    return [(trial_index, a, s) for s in samples]


def gaze_row(fixation: FixationGeometry, item: GazeItem) -> tuple[Any, ...]:
    """A gaze log row, with the sample's eccentricity from the cross."""
    trial_index, attempt, s = item
    return sample_row(trial_index, attempt, s, fixation.eccentricity(s.point))


def blanking_rows(trial_index: int, attempt: int,
                  episodes: Iterable[Episode]) -> list[tuple[Any, ...]]:
    """The blanking log's rows for an attempt's closed episodes (times from its first flip)."""
    return [(trial_index, attempt, round(e.start_s, 6), round(e.end_s, 6), e.frames, e.reason)
            for e in episodes if e.end_s is not None]


def trial_row(protocol: LoadedProtocol, trial: Trial, st: TrialState, *, participant: str,
              session_id: str, seed: int, tracker: str) -> dict[str, Any]:
    """The trial log's row of a confirmed trial. What is logged is what was on screen:
    ``final_value`` is the value of the stimulus on screen when Enter went down
    (:attr:`TrialState.final_value`), and the parameters are those it was rendered with;
    ``response_time_s`` runs from the first stimulus frame's flip to the press (to the
    microsecond, the flips' precision in the frame log)."""
    spec = protocol.spec
    final = st.final_value
    vals = protocol.parameter_values(trial, final)
    return {
        "participant": participant,
        "session": session_id,
        "experiment": spec.experiment,
        "protocol_sha256": protocol.sha256,
        "trial_index": trial.index,
        "practice": trial.practice,
        "repetition": trial.repetition,
        "image": trial.image,
        "blur_rate": vals["blur_rate"],
        "method": trial.method,
        "adjusted_parameter": spec.adjust.parameter,
        "f_e": vals["f_e"],
        "s_k": vals["s_k"],
        "s_f": vals["s_f"],
        "start_value": st.start_value,
        "final_value": final,
        "response_time_s": round(st.response_time_s, 6),
        "wheel_events": st.adjuster.notches,
        "blanked_fraction": round(st.blanking.fraction, 5),
        "dropped_frames": st.timer.dropped,
        "tracker": tracker,
        "seed": seed,
        "software_version": software_version(),
        "timestamp": now_iso(),
        **st.extra_columns(),  # a forced-choice trial's answer (tasks.forced_choice)
    }


__all__ = ["GazeItem", "blanking_rows", "gaze_items", "gaze_row", "trial_row"]
