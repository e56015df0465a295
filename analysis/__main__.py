"""``python -m analysis results/ --out report/`` until ``fovexp analyze`` is wired in."""

import sys

from .cli import main

sys.exit(main())
