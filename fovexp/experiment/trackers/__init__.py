"""The eye tracker's side of a session: the gaze sources, one module per source, and the one
place that chooses among them (:func:`make_gaze_source`: ``fovexp run`` and ``fovexp rig check``
both call it); what the sources share and the blanking decision (:mod:`.gaze`); the tracker's
set-up in a session (:mod:`.setup`: display area, calibration, validation, drift checks), the
calibration screens' flow (:mod:`.calibration`) and the data quality they measure
(:mod:`.quality`).

- :mod:`.simulated`: the simulated eye tracker of dry runs and CI (:class:`SimulatedGaze`);
- :mod:`.mouse`: the mouse pointer as gaze, for pilot sessions (:class:`MouseGaze`);
- :mod:`.tobii`: Tobii Pro through tobii-research (``TobiiGaze``, 600 Hz, the paper's);
- :mod:`.families`: the eye-tracker families ioHub reaches (EyeLink, Tobii, GazePoint, Pupil
  Labs, EyeLogic, MouseGaze), the extra and plugin each needs, and the ioHub configuration a
  lab already has for PsychoPy Builder or ioHub (YAML), read without PsychoPy;
- :mod:`.iohub`: any ioHub eye tracker (its server process, samples on the frame log's clock,
  the lost-tracker path, the tracker's own calibration).

Each satisfies :class:`fovexp.experiment.interfaces.GazeSource`; what they share (samples,
events, the clock, the fixation geometry) is :mod:`fovexp.experiment.trackers.gaze`. Nothing here
imports PsychoPy or a tracker's SDK at import time.

May import: ``fovexp`` (public API), :mod:`fovexp.results`,
:mod:`fovexp.experiment.interfaces`, and the room below it, ``protocol`` (its defaults, a
trial's index); the session file only through :class:`~fovexp.experiment.interfaces.SessionRecord`
(tests/test_layers.py).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from fovexp import FovexpError
from fovexp.results.format import TRACKERS

if TYPE_CHECKING:
    from ..interfaces import GazeSource
    from .gaze import FixationGeometry
    from .simulated import SimGazeParams

def iohub_config_path(protocol: Any, tracker_config: str | Path | None) -> Path:
    """The ioHub configuration: ``--tracker-config``, else the protocol's
    ``tracker.iohub_config`` (relative to the protocol file); either may name a shipped
    example, ``example:FAMILY`` (:func:`.families.example_path`)."""
    from .families import EXAMPLE_PREFIX, example_path

    given = tracker_config if tracker_config is not None else protocol.spec.tracker.iohub_config
    if given is not None and str(given).startswith(EXAMPLE_PREFIX):
        return example_path(str(given)[len(EXAMPLE_PREFIX):])
    if tracker_config is not None:
        return Path(tracker_config)
    name = protocol.spec.tracker.iohub_config
    if name is None:
        raise FovexpError("--tracker iohub needs an ioHub configuration: --tracker-config "
                          "FILE (the YAML PsychoPy Builder or ioHub uses), or "
                          "tracker.iohub_config in the protocol")
    return Path(protocol.path).parent / name


def make_gaze_source(kind: str, *, protocol: Any, display: Any, fixation: FixationGeometry,
                     dry_run: bool = False, screen: int = 0,
                     tracker_address: str | None = None,
                     tracker_config: str | Path | None = None, sim_seed: int = 1,
                     sim_params: SimGazeParams | None = None,
                     replay: tuple[Path, str, str] | None = None) -> GazeSource:
    """The gaze source ``kind`` (``--tracker``) for ``protocol`` on ``display``: a Tobii at
    the protocol's rate (``tracker_address``: a given one, else the first found), the
    simulated eyes (``sim_seed``, ``sim_params``; default: the protocol's rate), the mouse, or
    the ioHub tracker of :func:`iohub_config_path` (a dry run's MouseGaze moves the pointer to
    the calibration targets itself). A Tobii or ioHub source whose SDK or plugin is missing
    fails here, before a window opens."""
    if kind == "tobii":
        from .tobii import TobiiGaze

        return TobiiGaze(protocol.spec.tracker.sampling_hz, tracker_address)
    if kind == "simulated" and replay is not None:  # a recorded gaze (--gaze-replay)
        from .replay import ReplayGaze
        from .simulated import SimGazeParams

        p = sim_params or SimGazeParams()
        return ReplayGaze(replay[0], fixation, units=replay[1], end=replay[2],
                          latency_ms=p.latency_ms, latency_jitter_ms=p.latency_jitter_ms,
                          seed=sim_seed)
    if kind == "simulated":
        from .simulated import SimGazeParams, SimulatedGaze

        params = sim_params or SimGazeParams(rate_hz=protocol.spec.tracker.sampling_hz)
        return SimulatedGaze(fixation, seed=sim_seed, params=params)
    if kind == "mouse":
        from .mouse import MouseGaze

        return MouseGaze()
    if kind == "iohub":
        from .families import load_iohub_config
        from .iohub import IoHubGaze

        return IoHubGaze(load_iohub_config(iohub_config_path(protocol, tracker_config)),
                         display, screen, pointer=dry_run)
    raise FovexpError(f"--tracker {kind!r}: choose {', '.join(TRACKERS)}")


__all__ = ["iohub_config_path", "make_gaze_source"]
