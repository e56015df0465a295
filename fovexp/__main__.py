"""``python -m fovexp ...``: the same as the ``fovexp`` command."""

from .cli import entry

entry()
