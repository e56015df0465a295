"""The experiment runner: the paper's calibration (section 5) and validation (section 6.1)
adjustment experiments with gaze-contingent blanking (docs/EXPERIMENT.md).

:mod:`.session` keeps the order of a session's steps; each step lives in a room, lowest first:
``protocol`` (the protocol file and the study folder), ``trackers`` (gaze sources, the
tracker's set-up, calibration, data quality), ``tasks`` (the participant's task and the
screens around trials), ``display`` (the window, the renderer, their checks) and ``records``
(what a session writes and reads back). A room imports only rooms below it and
:mod:`.interfaces`; none imports the session (tests/test_layers.py).

PsychoPy is imported only by :mod:`fovexp.experiment.display.window`, when a session opens a
window.
"""

from .options import SessionOptions
from .protocol.spec import LoadedProtocol, Protocol, load_protocol
from .session import Session

__all__ = ["LoadedProtocol", "Protocol", "Session", "SessionOptions", "load_protocol"]
