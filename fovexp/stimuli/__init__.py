"""The images a session shows and the evaluation and the bench read: the fifteen generated
scenes (:mod:`.scenes`, drawn natively at any resolution), a lab's stimulus folder with its
frames, checks and manifest (:mod:`.folder`), and the ``fovexp stimuli`` command (:mod:`.cli`).

The shipped scene pins (``scenes.yaml``) are data, installed as ``fovexp.stimuli.shipped`` from
the project's top-level ``stimuli/`` folder (pyproject.toml).

May import: the enhancer's public API (``fovexp``) and its own modules; only the command line's
``check`` reads a protocol (:mod:`fovexp.experiment.protocol.spec`). Nothing here imports
PsychoPy (tests/test_layers.py).
"""
