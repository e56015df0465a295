"""The experiment runner: the paper's calibration (section 5) and validation (section 6.1)
adjustment experiments with gaze-contingent blanking (docs/EXPERIMENT.md).

PsychoPy is imported only by :mod:`fovexp.experiment.window`, when a session opens a window.
"""

from .protocol import LoadedProtocol, Protocol, load_protocol
from .session import Session, SessionOptions

__all__ = ["LoadedProtocol", "Protocol", "Session", "SessionOptions", "load_protocol"]
