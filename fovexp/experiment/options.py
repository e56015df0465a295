"""What ``fovexp run`` decides for a session (docs/EXPERIMENT.md lists the flags), in one
place: :class:`SessionOptions`, read by :class:`fovexp.experiment.session.Session`."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .tasks.simulated_participant import SimTruth
from .trackers.calibration import CalibrationTiming
from .trackers.simulated import SimGazeParams


@dataclass
class SessionOptions:
    """Everything the CLI decides (docs/EXPERIMENT.md lists the flags)."""

    participant: str
    results_root: Path = Path("results")
    tracker: str = "tobii"  # tobii / simulated / mouse
    dry_run: bool = False
    resume: bool = False
    new_session: bool = False
    limit_trials: int | None = None
    practice_trials: int | None = None
    window_size: tuple[int, int] | None = None
    fullscreen: bool = True
    skip_display_check: bool = False
    tracker_address: str | None = None
    #: ``--tracker iohub``: the ioHub configuration (default: the protocol's
    #: ``tracker.iohub_config``)
    tracker_config: Path | None = None
    #: enhancer backend: auto (a hardware GPU if there is one), cpu or gpu
    backend: str = "auto"
    #: the monitor of a multi-monitor rig (PsychoPy's ``screen``)
    screen: int = 0
    #: the participant form (age, sex, vision correction; each may be None), or None when it
    #: was not asked (dry runs, no terminal, --no-form); recorded at the first start
    participant_info: dict[str, Any] | None = None
    #: why the form was not asked, recorded instead of it
    participant_info_note: str | None = None
    #: where the per-trial console line and warnings go (default: stderr)
    console: Callable[[str], None] | None = None
    sim_truth: SimTruth = field(default_factory=SimTruth)
    sim_speed: float = 4.0
    sim_noise_scale: float = 1.0
    sim_seed: int | None = None
    sim_gaze: SimGazeParams | None = None
    #: seconds of each instruction/break screen in a dry run (no key presses there)
    dry_message_s: float = 0.2
    #: a dry run's gaze replayed from a recording: (file, units "norm"/"deg", end "loop"/"stop")
    gaze_replay: tuple[Path, str, str] | None = None
    #: run a real session although its keys are stamped when polled (``--accept-poll-keys``)
    accept_poll_keys: bool = False
    #: the calibration screens' durations (default Titta's; a dry run's are shorter)
    calibration_timing: CalibrationTiming | None = None
