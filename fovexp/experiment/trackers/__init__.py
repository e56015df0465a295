"""Gaze sources beyond the built-in ones, one module per source.

- :mod:`.families`: the eye-tracker families ioHub reaches (EyeLink, Tobii, GazePoint, Pupil
  Labs, EyeLogic, MouseGaze), the extra and plugin each needs, and the ioHub configuration a
  lab already has for PsychoPy Builder or ioHub (YAML), read without PsychoPy;
- :mod:`.iohub`: any ioHub eye tracker as a :class:`~fovexp.experiment.interfaces.GazeSource`
  (its server process, samples on the frame log's clock, the lost-tracker path, the tracker's
  own calibration).

The simulated, mouse and Tobii (tobii-research) sources are ``fovexp.experiment.gaze`` and
``fovexp.experiment.tobii``. Nothing here imports PsychoPy at import time.
"""
