"""``python -m fovexp.analysis results/ --out report/``: the same as ``fovexp analyze``."""

import sys

from .cli import main

sys.exit(main())
