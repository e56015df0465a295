"""What the participant sees and how fast: the PsychoPy window (:mod:`.window`, the only module
of the runner that imports PsychoPy), the X screen's size (:mod:`.xscreen`), the renderer's
thread (:mod:`.render`), the render budget (:mod:`.render_budget`), and the checks a session
runs on them before its first trial (:mod:`.checks`: the display's refresh rate and size, the
keyboard's time stamps, the wheel step's render time).

May import: ``fovexp`` (public API), :mod:`fovexp.results`, :mod:`fovexp.stimuli`,
:mod:`fovexp.experiment.interfaces`, and the rooms below it: ``protocol``, ``trackers`` (the
calibration screens' views) and ``tasks`` (the input events a window reports)
(tests/test_layers.py).
"""
