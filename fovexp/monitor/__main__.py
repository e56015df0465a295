"""``python -m fovexp.monitor``: the same as ``fovexp monitor``."""

from .cli import main

raise SystemExit(main())
