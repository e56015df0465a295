"""The stimulus manifest shipped with fovexp (see README.md in this folder).

Data only: this folder is installed as the package ``fovexp.stimuli.shipped``, inside the
stimulus code (``fovexp/stimuli/``; pyproject.toml maps it). See :mod:`fovexp.resources`.
"""
