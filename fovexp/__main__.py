"""``python -m fovexp ...``: the same as the ``fovexp`` command."""

import sys

from .cli import main

sys.exit(main())
