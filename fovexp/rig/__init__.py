"""``fovexp rig check``: what a rig holds of what the study needs, measured before the first
participant (docs/EXPERIMENT.md, "The rig check").

- :mod:`.checks`: the figures and verdicts without a window (thresholds, what to change);
- :mod:`.measure`: the measurements, on the session's own window, renderer, gaze sources and
  frame loop (``fovexp.experiment``; one loop, the rig check only measures around it);
- :mod:`.report`: the JSON and Markdown report under the results root
  (``fovexp.results.rigcheck`` finds the newest, which ``fovexp run`` records);
- :mod:`.cli`: the command.
"""
